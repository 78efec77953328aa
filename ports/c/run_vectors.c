/* Replays one golden-vector file through the C port and reports how far it is from it.
 *
 *   run_vectors CONFIG.cfg VECTORS.csv
 *
 * Prints one line of key=value figures (max absolute error and max reference magnitude per
 * compared quantity, status and flag mismatches) and exits 0; exits 2 on unreadable input.
 * The comparison thresholds live in the test that runs it (tests/test_c_port.py). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrs_calib.h"
#include "mrs_controller.h"

#define LINE_MAX_LEN 4096
#define N_COLS (5 + 2 + MRS_MAX_MODEL_DELAY + 5)

static int fail(const char *what, const char *arg)
{
    fprintf(stderr, "run_vectors: %s: %s\n", what, arg);
    return 2;
}

/* The coefficient lines of the .cfg, to compare with mrs_configure(). */
static void keep_coeff(void *ctx, const char *key, double value)
{
    static const char *const names[7] = {"a", "g_w0", "g_w1", "g_r0", "g_r1", "k_us", "inv_one_minus_g_w0"};
    double *ref = ctx;
    int i;
    for (i = 0; i < 7; ++i) {
        if (strcmp(key, names[i]) == 0) {
            ref[i] = value;
        }
    }
}

static void track(double got, double ref, double *err, double *mag)
{
    const double e = fabs(got - ref);
    if (e > *err) {
        *err = e;
    }
    if (fabs(ref) > *mag) {
        *mag = fabs(ref);
    }
}

int main(int argc, char **argv)
{
    mrs_config_t g;
    mrs_coeffs_t c;
    mrs_state_t s;
    double coeff_ref[7] = {0, 0, 0, 0, 0, 0, 0};
    double coeff_err = 0.0;
    double u_err = 0.0, u_mag = 0.0, z_err = 0.0, z_mag = 0.0, h_err = 0.0, h_mag = 0.0;
    long steps = 0, status_mismatch = 0, flags_mismatch = 0, idx_mismatch = 0, init_mismatch = 0;
    char line[LINE_MAX_LEN];
    char why[512];
    FILE *f;
    int i;

    if (argc != 3) {
        return fail("usage", "run_vectors CONFIG.cfg VECTORS.csv");
    }
    if (mrs_calib_read(argv[1], &g, keep_coeff, coeff_ref, why, sizeof why) != 0) {
        return fail("calibration", why);
    }
    if (mrs_configure(&g, &c) != 0) {
        return fail("invalid calibration in", argv[1]);
    }
    {
        const double got[7] = {c.a, c.g_w0, c.g_w1, c.g_r0, c.g_r1, c.k_us, c.inv_one_minus_g_w0};
        for (i = 0; i < 7; ++i) {
            const double e = fabs(got[i] - coeff_ref[i]) / (fabs(coeff_ref[i]) > 0.0 ? fabs(coeff_ref[i]) : 1.0);
            if (e > coeff_err) {
                coeff_err = e;
            }
        }
    }
    mrs_init_state(&s);
    f = fopen(argv[2], "r");
    if (f == NULL) {
        return fail("cannot read", argv[2]);
    }
    if (fgets(line, sizeof line, f) == NULL) { /* header */
        fclose(f);
        return fail("empty file", argv[2]);
    }
    while (fgets(line, sizeof line, f) != NULL) {
        double v[N_COLS];
        char *p = line;
        int n = 0;
        mrs_real_t u;
        while (n < N_COLS) {
            char *end;
            v[n++] = strtod(p, &end);
            if (*end != ',') {
                break;
            }
            p = end + 1;
        }
        if (n != N_COLS) {
            fclose(f);
            return fail("malformed row in", argv[2]);
        }
        /* k, delta_driver, yaw_rate, speed, u, z, u_prev, u_hist0..7, hist_idx, needs_init,
           recovering, status, fault_flags */
        u = mrs_step(&c, &s, (mrs_real_t)v[1], (mrs_real_t)v[2], (mrs_real_t)v[3]);
        track((double)u, v[4], &u_err, &u_mag);
        track((double)s.u_prev, v[6], &u_err, &u_mag);
        track((double)s.z, v[5], &z_err, &z_mag);
        for (i = 0; i < MRS_MAX_MODEL_DELAY; ++i) {
            track((double)s.u_hist[i], v[7 + i], &h_err, &h_mag);
        }
        idx_mismatch += (s.hist_idx != (uint8_t)v[15]);
        init_mismatch += (s.needs_init != (uint8_t)v[16]) || (s.recovering != (uint8_t)v[17]);
        status_mismatch += (s.status != (uint8_t)v[18]);
        flags_mismatch += (s.fault_flags != (uint8_t)v[19]);
        ++steps;
    }
    fclose(f);
    printf("steps=%ld real_bytes=%u coeff_rel_err=%.3e u_err=%.3e u_mag=%.3e z_err=%.3e z_mag=%.3e "
           "hist_err=%.3e hist_mag=%.3e status_mismatch=%ld flags_mismatch=%ld idx_mismatch=%ld "
           "init_mismatch=%ld\n",
           steps, (unsigned)sizeof(mrs_real_t), coeff_err, u_err, u_mag, z_err, z_mag, h_err, h_mag,
           status_mismatch, flags_mismatch, idx_mismatch, init_mismatch);
    return 0;
}
