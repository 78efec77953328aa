/* Markers for the instruction counter and the painted stack (pil.h). */
#include "pil.h"

#define PAINT 0xC5A1C5A1u

/* Each a lone `bx lr` (the plugin subtracts it); built with -fno-ipa-icf so that they keep four
 * addresses. */
__attribute__((noinline, used)) void pil_law_begin(void)
{
    __asm__ volatile("" ::: "memory");
}
__attribute__((noinline, used)) void pil_law_end(void)
{
    __asm__ volatile("" ::: "memory");
}
__attribute__((noinline, used)) void pil_cycle_begin(void)
{
    __asm__ volatile("" ::: "memory");
}
__attribute__((noinline, used)) void pil_cycle_end(void)
{
    __asm__ volatile("" ::: "memory");
}

/* Leaf functions that push nothing: their sp is the caller's at the call. */
__attribute__((noinline)) void pil_paint(void)
{
    uint32_t *p;
    __asm__ volatile("mov %0, sp" : "=r"(p));
    for (uint32_t i = 1u; i <= PIL_PAINT_BYTES / 4u; ++i) {
        p[-(int32_t)i] = PAINT;
    }
}

__attribute__((noinline)) uint32_t pil_painted_depth(void)
{
    uint32_t *p;
    uint32_t i = PIL_PAINT_BYTES / 4u;
    __asm__ volatile("mov %0, sp" : "=r"(p));
    while (i > 0u && p[-(int32_t)i] == PAINT) {
        --i;
    }
    return 4u * i;
}
