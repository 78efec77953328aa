/* The processor-in-the-loop target's program: one golden-vector file through the C port on the
 * Cortex-M, by the host runner's own replay (mrs_vectors_main), with each row's mrs_step()
 * measured, and the whole control cycle stepped on the same inputs and measured too.
 *
 *   pil CONFIG.cfg VECTORS.csv     (argv through semihosting)
 *
 * Prints mrs_vectors_main()'s line, then `pil: law_stack=N cycle_stack=N coeffs_bytes=N state_bytes=N`
 * (the deepest painted stack of one mrs_step() and of one whole cycle; the cycle's coefficient and
 * state structs, which the caller allocates). The instruction counts come from the
 * emulator (pil/insn_count.c), between the markers of pil.h. */
#include <math.h>
#include <stdio.h>

#include "mrs_config.h"
#include "mrs_cycle.h"
#include "mrs_e2e.h"
#include "mrs_vectors.h"
#include "pil.h"

/* The E2E work of one period: the command frame (AuxSteerCmd: 8 bytes, CRC in byte 0) protected,
 * and one received frame's counter checked; the data ID is AuxSteerCmd's (dbc/mrsteer.dbc, E2E_DataID). */
#define CMD_DATA_ID 4096u
#define CMD_BYTES 8u
#define RX_MAX_DELTA 3u

typedef struct {
    mrs_cycle_coeffs_t c;
    mrs_cycle_state_t s;
    mrs_e2e_receiver_t rx;
    uint8_t counter;
    uint8_t frame[CMD_BYTES];
    uint32_t law_stack, cycle_stack;
} pil_t;

/* One period as the node runs it: the cycle, then the command frame's counter and CRC, and the
 * check of a received frame's counter. */
static __attribute__((noinline)) void cycle(pil_t *p, const mrs_cycle_inputs_t *in)
{
    const double u = mrs_cycle_step(&p->c, &p->s, in);
    const int32_t raw = (int32_t)(u * 1e6);
    p->counter = mrs_e2e_next_counter(p->counter);
    p->frame[1] = (uint8_t)((p->frame[1] & 0xF0u) | p->counter);
    p->frame[2] = (uint8_t)((uint32_t)raw & 0xFFu);
    p->frame[3] = (uint8_t)(((uint32_t)raw >> 8) & 0xFFu);
    p->frame[4] = (uint8_t)(((uint32_t)raw >> 16) & 0xFFu);
    p->frame[0] = mrs_e2e_crc(CMD_DATA_ID, p->frame, CMD_BYTES, 0u);
    (void)mrs_e2e_check_counter(&p->rx, p->counter);
}

static mrs_real_t step(void *ctx, const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver,
                       mrs_real_t yaw_rate, mrs_real_t speed)
{
    pil_t *p = ctx;
    mrs_real_t u;
    uint32_t depth;
    mrs_cycle_inputs_t in;
    pil_paint();
    pil_law_begin();
    u = mrs_step(c, s, delta_driver, yaw_rate, speed, 0u);
    pil_law_end();
    depth = pil_painted_depth();
    p->law_stack = (depth > p->law_stack) ? depth : p->law_stack;

    in.delta_driver = (double)delta_driver;
    in.yaw_rate = (double)yaw_rate;
    in.speed = (double)speed;
    in.lat_accel = in.yaw_rate * in.speed; /* the redundant sensors agree: every check runs */
    in.delta_driver_redundant = in.delta_driver;
    in.yaw_rate_redundant = in.yaw_rate;
    in.speed_redundant = in.speed;
    in.monitor_steps = 1;
    in.monitor_driver = in.delta_driver;
    in.starting = 0;
    pil_paint();
    pil_cycle_begin();
    cycle(p, &in);
    pil_cycle_end();
    depth = pil_painted_depth();
    p->cycle_stack = (depth > p->cycle_stack) ? depth : p->cycle_stack;
    return u;
}

int main(int argc, char **argv)
{
    static pil_t p;
    mrs_vectors_probe_t probe = {step, &p};
    mrs_config_t law;
    mrs_monitor_config_t monitor;
    mrs_authority_config_t authority;
    char err[256];
    int rc;
    /* the markers with nothing between: the counter's zero */
    pil_law_begin();
    pil_law_end();
    pil_cycle_begin();
    pil_cycle_end();
    if (argc == 3 && mrs_config_load(argv[1], &law, err, sizeof err) == 0) {
        mrs_monitor_default_config(&monitor);
        mrs_authority_default_config(&authority);
        if (mrs_cycle_configure(&law, &monitor, &authority, &p.c) != 0) {
            fprintf(stderr, "pil: the cycle refuses the calibration in %s\n", argv[1]);
            return 2;
        }
        mrs_cycle_reset(&p.s);
        mrs_e2e_receiver_init(&p.rx, RX_MAX_DELTA);
    }
    rc = mrs_vectors_main(argc, argv, &probe); /* every error of the arguments or files: its one line */
    if (rc == 0) {
        printf("pil: law_stack=%lu cycle_stack=%lu coeffs_bytes=%lu state_bytes=%lu\n", (unsigned long)p.law_stack,
               (unsigned long)p.cycle_stack, (unsigned long)sizeof p.c, (unsigned long)sizeof p.s);
    }
    return rc;
}
