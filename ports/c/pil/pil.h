/* The processor-in-the-loop target's own pieces (startup.c, measure.c); not the controller's. */
#ifndef PIL_H
#define PIL_H

#include <stdint.h>

/* Arm semihosting call (op in r0, arg in r1, bkpt 0xab); its result. */
int pil_semihost(int op, void *arg);

/* Flush stdio and leave QEMU with this exit status (SYS_EXIT_EXTENDED). */
void pil_exit(int status);

/* The markers the instruction-counting plugin (pil/insn_count.c) watches: it counts the
 * instructions executed from the return of a *_begin to the call of its *_end. */
void pil_law_begin(void);
void pil_law_end(void);
void pil_cycle_begin(void);
void pil_cycle_end(void);

/* Stack painting: pil_paint() fills PIL_PAINT_BYTES below the caller's stack pointer with a
 * pattern; pil_painted_depth(), called at the same stack pointer, says how many bytes below it
 * were written since (PIL_PAINT_BYTES: all of them, the window was too small). */
#define PIL_PAINT_BYTES 4096u
void pil_paint(void);
uint32_t pil_painted_depth(void);

#endif
