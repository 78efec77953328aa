/* Replays one golden-vector file through the C port and reports how far it is from it: the one
 * owner of the vector format and its comparison, for the host runner (run_vectors.c) and the
 * bare-metal processor-in-the-loop target (pil/pil_main.c, which reads the files by semihosting).
 *
 *   run_vectors CONFIG.cfg VECTORS.csv
 *
 * Prints one line of key=value figures (max absolute error and max reference magnitude per
 * compared quantity, status and flag mismatches) and returns 0; returns 2 with one line on
 * stderr on unreadable input. The comparison thresholds live in the tests that run it
 * (tests/test_c_port.py, tests/test_pil.py). */
#ifndef MRS_VECTORS_H
#define MRS_VECTORS_H

#include "mrs_controller.h"

/* A probe's step() replaces each row's mrs_step(c, s, delta_driver, yaw_rate, speed, 0) and must
 * call it: the target measures the call (instructions, stack) and steps the whole cycle on the
 * row's inputs. */
typedef struct {
    mrs_real_t (*step)(void *ctx, const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver,
                       mrs_real_t yaw_rate, mrs_real_t speed);
    void *ctx;
} mrs_vectors_probe_t;

/* The runner's whole job for argv = {name, CONFIG.cfg, VECTORS.csv}; probe may be NULL. */
int mrs_vectors_main(int argc, char **argv, const mrs_vectors_probe_t *probe);

#endif
