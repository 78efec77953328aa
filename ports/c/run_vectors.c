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

#include "mrs_controller.h"

#define LINE_MAX_LEN 4096
#define N_COLS (5 + 2 + MRS_MAX_MODEL_DELAY + 5)

static int fail(const char *what, const char *arg)
{
    fprintf(stderr, "run_vectors: %s: %s\n", what, arg);
    return 2;
}

static void trim(char *s)
{
    size_t n = strlen(s);
    while (n > 0u && (s[n - 1u] == '\n' || s[n - 1u] == '\r' || s[n - 1u] == ' ')) {
        s[--n] = '\0';
    }
}

/* Reads the calibration lines; also keeps the coefficient lines to compare with mrs_configure(). */
static int read_config(const char *path, mrs_config_t *g, double coeff_ref[7])
{
    char line[LINE_MAX_LEN];
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        return -1;
    }
    mrs_default_config(g);
    while (fgets(line, sizeof line, f) != NULL) {
        char *eq = strchr(line, '=');
        char *key = line, *val;
        double x;
        if (line[0] == '#' || eq == NULL) {
            continue;
        }
        *eq = '\0';
        val = eq + 1;
        trim(key);
        while (*val == ' ') {
            ++val;
        }
        trim(val);
        x = strtod(val, NULL);
        if (strcmp(key, "q_form") == 0) {
            g->q_form = (strcmp(val, "standard") == 0) ? MRS_Q_STANDARD : MRS_Q_LIMITED;
        } else if (strcmp(key, "method") == 0) {
            g->method = (strcmp(val, "zoh") == 0) ? MRS_ZOH : MRS_TUSTIN;
        } else if (strcmp(key, "k") == 0) {
            g->k = x;
        } else if (strcmp(key, "tau") == 0) {
            g->tau = x;
        } else if (strcmp(key, "tau_n") == 0) {
            g->tau_n = x;
        } else if (strcmp(key, "ts") == 0) {
            g->ts = x;
        } else if (strcmp(key, "aux_limit") == 0) {
            g->aux_limit = x;
        } else if (strcmp(key, "rate_limit") == 0) {
            g->rate_limit = x;
        } else if (strcmp(key, "model_delay_steps") == 0) {
            g->model_delay_steps = (int)x;
        } else if (strcmp(key, "fade_rate") == 0) {
            g->fade_rate = x;
        } else if (strcmp(key, "speed_active_min") == 0) {
            g->speed_active_min = x;
        } else if (strcmp(key, "speed_max") == 0) {
            g->speed_max = x;
        } else if (strcmp(key, "driver_angle_max") == 0) {
            g->driver_angle_max = x;
        } else if (strcmp(key, "yaw_rate_max") == 0) {
            g->yaw_rate_max = x;
        } else if (strcmp(key, "nominal_l_f") == 0) {
            g->nominal_l_f = x;
        } else if (strcmp(key, "nominal_l_r") == 0) {
            g->nominal_l_r = x;
        } else if (strcmp(key, "nominal_mass") == 0) {
            g->nominal_mass = x;
        } else if (strcmp(key, "nominal_c_f") == 0) {
            g->nominal_c_f = x;
        } else if (strcmp(key, "nominal_c_r") == 0) {
            g->nominal_c_r = x;
        } else if (strcmp(key, "c.a") == 0) {
            coeff_ref[0] = x;
        } else if (strcmp(key, "c.g_w0") == 0) {
            coeff_ref[1] = x;
        } else if (strcmp(key, "c.g_w1") == 0) {
            coeff_ref[2] = x;
        } else if (strcmp(key, "c.g_r0") == 0) {
            coeff_ref[3] = x;
        } else if (strcmp(key, "c.g_r1") == 0) {
            coeff_ref[4] = x;
        } else if (strcmp(key, "c.k_us") == 0) {
            coeff_ref[5] = x;
        } else if (strcmp(key, "c.inv_one_minus_g_w0") == 0) {
            coeff_ref[6] = x;
        }
    }
    fclose(f);
    return 0;
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
    FILE *f;
    int i;

    if (argc != 3) {
        return fail("usage", "run_vectors CONFIG.cfg VECTORS.csv");
    }
    if (read_config(argv[1], &g, coeff_ref) != 0) {
        return fail("cannot read", argv[1]);
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
