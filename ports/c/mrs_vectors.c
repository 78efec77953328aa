/* The golden-vector replay (mrs_vectors.h): parsing, stepping and comparison, shared by the host
 * runner (run_vectors.c) and the bare-metal target (pil/pil_main.c). */
#include "mrs_vectors.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrs_config.h"

#define LINE_MAX_LEN 4096
/* k, delta_driver, yaw_rate, speed, u, z, u_prev, u_hist0..7, hist_idx, p_n, f_s1, f_s2,
   needs_init, recovering, status, fault_flags */
#define N_COLS (5 + 2 + MRS_MAX_MODEL_DELAY + 1 + 3 + 4)
#define COL_HIST 7
#define COL_IDX (COL_HIST + MRS_MAX_MODEL_DELAY)

static int fail(const char *what, const char *arg)
{
    fprintf(stderr, "run_vectors: %s: %s\n", what, arg);
    return 2;
}

typedef struct {
    const char *name;
    const mrs_real_t *value;
    int count;
} coeff_t;

/* Largest relative difference between the file's `c.NAME = x[, y...]` lines and mrs_configure()'s
 * coefficients of that name; -1 if a line names no known coefficient or has the wrong length. */
static double coefficient_error(const char *path, const mrs_coeffs_t *c)
{
    const coeff_t known[] = {
        {"c.sched_v", c->sched_v, c->n_sched}, {"c.sched_inv_dv", c->sched_inv_dv, c->n_sched - 1},
        {"c.sched_a", c->sched_a, c->n_sched}, {"c.sched_g_w0", c->sched_g_w0, c->n_sched},
        {"c.sched_g_w1", c->sched_g_w1, c->n_sched}, {"c.sched_g_r0", c->sched_g_r0, c->n_sched},
        {"c.sched_g_r1", c->sched_g_r1, c->n_sched}, {"c.sched_q0", c->sched_q0, c->n_sched},
        {"c.inv_one_minus_g_w0", &c->inv_one_minus_g_w0, 1}, {"c.act_a", &c->act_a, 1},
        {"c.act_b", &c->act_b, 1}, {"c.flt_b0", &c->flt_b0, 1}, {"c.flt_b1", &c->flt_b1, 1},
        {"c.flt_b2", &c->flt_b2, 1}, {"c.flt_a1", &c->flt_a1, 1}, {"c.flt_a2", &c->flt_a2, 1},
        {"c.wheelbase", &c->wheelbase, 1}, {"c.k_us", &c->k_us, 1}, {"c.u_max", &c->u_max, 1},
        {"c.fade_step", &c->fade_step, 1}};
    char line[LINE_MAX_LEN];
    double worst = 0.0;
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        return -1.0;
    }
    while (fgets(line, sizeof line, f) != NULL) {
        char *eq = strchr(line, '=');
        unsigned i;
        if (strncmp(line, "c.", 2u) != 0 || eq == NULL) {
            continue;
        }
        for (i = 0u; i < sizeof known / sizeof known[0]; ++i) {
            const size_t n = strlen(known[i].name);
            if (strncmp(line, known[i].name, n) == 0 && (line[n] == ' ' || line[n] == '=')) {
                char *p = eq + 1;
                int j;
                for (j = 0; j < known[i].count; ++j) {
                    char *end;
                    const double ref = strtod(p, &end);
                    const double e = fabs((double)known[i].value[j] - ref) / (fabs(ref) > 0.0 ? fabs(ref) : 1.0);
                    if (end == p) {
                        fclose(f);
                        return -1.0;
                    }
                    worst = (e > worst) ? e : worst;
                    p = (*end == ',') ? end + 1 : end;
                }
                break;
            }
        }
    }
    fclose(f);
    return worst;
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

int mrs_vectors_main(int argc, char **argv, const mrs_vectors_probe_t *probe)
{
    mrs_config_t g;
    mrs_coeffs_t c;
    mrs_state_t s;
    double coeff_err;
    double u_err = 0.0, u_mag = 0.0, z_err = 0.0, z_mag = 0.0, h_err = 0.0, h_mag = 0.0;
    double n_err = 0.0, n_mag = 0.0;
    long steps = 0, status_mismatch = 0, flags_mismatch = 0, idx_mismatch = 0, init_mismatch = 0;
    char line[LINE_MAX_LEN], err[256];
    FILE *f;
    int i;

    if (argc != 3) {
        return fail("usage", "run_vectors CONFIG.cfg VECTORS.csv");
    }
    if (mrs_config_load(argv[1], &g, err, sizeof err) != 0) {
        return fail("calibration", err);
    }
    if (mrs_configure(&g, &c) != 0) {
        return fail("invalid calibration in", argv[1]);
    }
    coeff_err = coefficient_error(argv[1], &c);
    if (coeff_err < 0.0) {
        return fail("bad coefficient line in", argv[1]);
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
        if (probe != NULL) {
            u = probe->step(probe->ctx, &c, &s, (mrs_real_t)v[1], (mrs_real_t)v[2], (mrs_real_t)v[3]);
        } else {
            u = mrs_step(&c, &s, (mrs_real_t)v[1], (mrs_real_t)v[2], (mrs_real_t)v[3], 0u);
        }
        track((double)u, v[4], &u_err, &u_mag);
        track((double)s.u_prev, v[6], &u_err, &u_mag);
        track((double)s.z, v[5], &z_err, &z_mag);
        for (i = 0; i < MRS_MAX_MODEL_DELAY; ++i) {
            track((double)s.u_hist[i], v[COL_HIST + i], &h_err, &h_mag);
        }
        track((double)s.p_n, v[COL_IDX + 1], &n_err, &n_mag);
        track((double)s.f_s1, v[COL_IDX + 2], &n_err, &n_mag);
        track((double)s.f_s2, v[COL_IDX + 3], &n_err, &n_mag);
        idx_mismatch += (s.hist_idx != (uint8_t)v[COL_IDX]);
        init_mismatch += (s.needs_init != (uint8_t)v[COL_IDX + 4]) || (s.recovering != (uint8_t)v[COL_IDX + 5]);
        status_mismatch += (s.status != (uint8_t)v[COL_IDX + 6]);
        flags_mismatch += (s.fault_flags != (uint8_t)v[COL_IDX + 7]);
        ++steps;
    }
    fclose(f);
    printf("steps=%ld real_bytes=%u coeff_rel_err=%.3e u_err=%.3e u_mag=%.3e z_err=%.3e z_mag=%.3e "
           "hist_err=%.3e hist_mag=%.3e model_err=%.3e model_mag=%.3e status_mismatch=%ld "
           "flags_mismatch=%ld idx_mismatch=%ld init_mismatch=%ld\n",
           steps, (unsigned)sizeof(mrs_real_t), coeff_err, u_err, u_mag, z_err, z_mag, h_err, h_mag, n_err,
           n_mag, status_mismatch, flags_mismatch, idx_mismatch, init_mismatch);
    return 0;
}
