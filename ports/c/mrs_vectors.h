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

/* Called around each row's mrs_step(): the target counts the instructions between them and
 * steps the whole cycle on the row's inputs (delta_driver, yaw_rate, speed) in after(). */
typedef struct {
    void (*before)(void *ctx);
    void (*after)(void *ctx, double delta_driver, double yaw_rate, double speed);
    void *ctx;
} mrs_vectors_probe_t;

/* The runner's whole job for argv = {name, CONFIG.cfg, VECTORS.csv}; probe may be NULL. */
int mrs_vectors_main(int argc, char **argv, const mrs_vectors_probe_t *probe);

#endif
