/* Bare-metal start-up of the processor-in-the-loop target (Cortex-M4F and Cortex-M7 on QEMU's
 * MPS2 boards): vector table, reset (FPU on, .data copied from flash, .bss zeroed), the command
 * line and the exit status through Arm semihosting, then main(). newlib's librdimon does the
 * file and console I/O over semihosting; nothing here is part of the controller. */
#include <stdint.h>
#include <stdio.h>

#include "pil.h"

#define SYS_GET_CMDLINE 0x15
#define SYS_EXIT_EXTENDED 0x20
#define ADP_STOPPED_APPLICATION_EXIT 0x20026
#define CMDLINE_MAX 1024
#define ARGV_MAX 8

extern uint32_t __data_start, __data_end, __data_load, __bss_start__, __bss_end__, __stack_top;
extern void initialise_monitor_handles(void);
extern int main(int argc, char **argv);
void Reset_Handler(void);
void pil_start(void);

static void fault(void)
{
    pil_exit(3);
}

/* The initial stack pointer, then reset, NMI, the faults, SVCall, PendSV, SysTick. */
__attribute__((section(".vectors"), used)) static const struct {
    uint32_t *initial_sp;
    void (*handler[15])(void);
} vectors = {&__stack_top,
             {Reset_Handler, fault, fault, fault, fault, fault, 0, 0, 0, 0, fault, fault, 0, fault, fault}};

/* Before any C: the FPU's coprocessors (CPACR CP10, CP11) on, or the first FP instruction faults. */
__attribute__((naked)) void Reset_Handler(void)
{
    __asm__ volatile("ldr r0, =0xE000ED88\n"
                     "ldr r1, [r0]\n"
                     "orr r1, r1, #(0xF << 20)\n"
                     "str r1, [r0]\n"
                     "dsb\n"
                     "isb\n"
                     "ldr r0, =__stack_top\n"
                     "mov sp, r0\n"
                     "b pil_start\n");
}

int pil_semihost(int op, void *arg)
{
    register int r0 __asm__("r0") = op;
    register void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void pil_exit(int status)
{
    uint32_t block[2] = {ADP_STOPPED_APPLICATION_EXIT, (uint32_t)status};
    fflush(stdout);
    fflush(stderr);
    for (;;) {
        (void)pil_semihost(SYS_EXIT_EXTENDED, block);
    }
}

/* The words of QEMU's -semihosting-config arg=... list, split at spaces. */
static int command_line(char **argv)
{
    static char line[CMDLINE_MAX];
    struct {
        char *buf;
        int len;
    } block = {line, CMDLINE_MAX - 1};
    int argc = 0;
    char *p = line;
    if (pil_semihost(SYS_GET_CMDLINE, &block) != 0) {
        return 0;
    }
    line[block.len] = '\0';
    while (*p != '\0' && argc < ARGV_MAX) {
        while (*p == ' ') {
            *p++ = '\0';
        }
        if (*p != '\0') {
            argv[argc++] = p;
        }
        while (*p != '\0' && *p != ' ') {
            ++p;
        }
    }
    return argc;
}

void pil_start(void)
{
    static char *argv[ARGV_MAX + 1];
    uint32_t *src = &__data_load;
    uint32_t *dst;
    for (dst = &__data_start; dst < &__data_end; ++dst) {
        *dst = *src++;
    }
    for (dst = &__bss_start__; dst < &__bss_end__; ++dst) {
        *dst = 0u;
    }
    initialise_monitor_handles();
    pil_exit(main(command_line(argv), argv));
}
