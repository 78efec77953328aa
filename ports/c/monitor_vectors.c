/* Replays input vectors through the C plausibility monitor and authority limiter.
 *
 *   monitor_vectors < INPUT
 *
 * INPUT: a line "monitor" + the 43 mrs_monitor_config_t numbers in struct order, a line
 * "authority" + the 8 mrs_authority_config_t numbers, then one line per control period:
 * "delta_driver delta_driver_redundant yaw_rate lat_accel speed aux_cmd_applied u_request
 * yaw_rate_redundant speed_redundant" (nan for a missing input).  OUTPUT: a line "coeffs" + the
 * monitor's and the authority's coefficients, then per period "bits flags kin_err pair_err
 * model_err u auth_flags yaw_pair_err turn_err turn_n turn_settled yaw_hold_n yaw_clear_n
 * speed_pair_err speed_pair_count speed2_seen steer_hold_n speed_lag" (the limiter cut by the flags'
 * MRS_CUT_CHECKS and faded by their MRS_FADE_CHECKS), every real as %.17g so that a double reads
 * back exactly.  "defaults" alone prints the default configurations instead.  Exit 2 on
 * unreadable input, 3 on an invalid calibration.
 * tests/test_c_monitor.py drives it against firmware_py/plausibility.py. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrs_monitor.h"

#define LINE_MAX_LEN 2048

static int read_numbers(char *line, double *out, int n)
{
    char *p = line, *end;
    int i;
    for (i = 0; i < n; ++i) {
        out[i] = strtod(p, &end);
        if (end == p) {
            return -1;
        }
        p = end;
    }
    return 0;
}

static void print_defaults(void)
{
    mrs_monitor_config_t m;
    mrs_authority_config_t a;
    mrs_monitor_default_config(&m);
    mrs_authority_default_config(&a);
    printf("monitor %.17g %.17g %.17g %.17g %d %.17g %.17g %d %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g "
           "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g "
           "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n",
           m.ts, m.speed_min, m.yaw_bound, m.yaw_rel, m.yaw_count, m.yaw_raw_fraction, m.steer_bound, m.steer_count, m.model_margin, m.model_rel,
           m.model_tau, m.model_time, m.frozen_time, m.frozen_move_yaw, m.frozen_move_steer, m.nominal_l_f,
           m.nominal_l_r, m.nominal_mass, m.nominal_c_f, m.nominal_c_r, m.kin_gap, m.mu_min, m.actuator_tau,
           m.yaw_pair_bound, m.sensor_tau, m.side_accel, m.speed_step, m.turn_yaw_min, m.turn_yaw_tol, m.turn_lat_tol,
           m.turn_lat_rel, m.turn_speed_rel, m.turn_yaw_bias, m.turn_lat_bias, m.yaw_pair_hold, m.speed_pair_bound,
           m.speed_pair_rel, m.speed_pair_time, m.steer_jump, m.mu_min_paired, m.speed_brake_decel, m.speed_brake_tau,
           m.speed_slip_rel);
    printf("authority %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", a.ts, a.u_max, a.rate_max, a.fade_rate,
           a.fault_fade_rate, a.panic_window, a.engage, a.rearm_time);
}

/* The 43 numbers of the "monitor" line into the configuration, in struct order. */
static void monitor_config_of(const double *v, mrs_monitor_config_t *mg)
{
    mg->ts = v[0];
    mg->speed_min = v[1];
    mg->yaw_bound = v[2];
    mg->yaw_rel = v[3];
    mg->yaw_count = (int)v[4];
    mg->yaw_raw_fraction = v[5];
    mg->steer_bound = v[6];
    mg->steer_count = (int)v[7];
    mg->model_margin = v[8];
    mg->model_rel = v[9];
    mg->model_tau = v[10];
    mg->model_time = v[11];
    mg->frozen_time = v[12];
    mg->frozen_move_yaw = v[13];
    mg->frozen_move_steer = v[14];
    mg->nominal_l_f = v[15];
    mg->nominal_l_r = v[16];
    mg->nominal_mass = v[17];
    mg->nominal_c_f = v[18];
    mg->nominal_c_r = v[19];
    mg->kin_gap = v[20];
    mg->mu_min = v[21];
    mg->actuator_tau = v[22];
    mg->yaw_pair_bound = v[23];
    mg->sensor_tau = v[24];
    mg->side_accel = v[25];
    mg->speed_step = v[26];
    mg->turn_yaw_min = v[27];
    mg->turn_yaw_tol = v[28];
    mg->turn_lat_tol = v[29];
    mg->turn_lat_rel = v[30];
    mg->turn_speed_rel = v[31];
    mg->turn_yaw_bias = v[32];
    mg->turn_lat_bias = v[33];
    mg->yaw_pair_hold = v[34];
    mg->speed_pair_bound = v[35];
    mg->speed_pair_rel = v[36];
    mg->speed_pair_time = v[37];
    mg->steer_jump = v[38];
    mg->mu_min_paired = v[39];
    mg->speed_brake_decel = v[40];
    mg->speed_brake_tau = v[41];
    mg->speed_slip_rel = v[42];
}

/* The 8 numbers of the "authority" line into the configuration. */
static void authority_config_of(const double *v, mrs_authority_config_t *ag)
{
    ag->ts = v[0];
    ag->u_max = v[1];
    ag->rate_max = v[2];
    ag->fade_rate = v[3];
    ag->fault_fade_rate = v[4];
    ag->panic_window = v[5];
    ag->engage = v[6];
    ag->rearm_time = v[7];
}

static void print_coeffs(const mrs_monitor_coeffs_t *m, const mrs_authority_coeffs_t *a)
{
    printf("coeffs %.17g %.17g %d %d %d %.17g %.17g %.17g %.17g %.17g %.17g %.17g %d %d %d %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g "
           "%.17g %.17g %d %.17g %.17g %.17g %.17g %.17g\n",
           m->model_alpha, m->k_us, (int)m->model_steps, (int)m->frozen_steps, (int)m->yaw_count, m->inv_cs_m,
           m->moment_m, m->cf_m, a->du_max, a->fade_step, a->fault_fade_step, a->engage, (int)a->window_steps,
           (int)a->rearm_steps, (int)m->kin_gap_steps, m->lat_span, m->aux_alpha, m->inv_yaw_pair_bound, m->delta_alpha, m->side_accel, m->speed_step,
           m->turn_yaw_min, m->turn_yaw_tol, m->turn_lat_tol, m->turn_lat_rel, m->turn_speed_rel, m->turn_yaw_bias,
           m->turn_lat_bias, m->yaw_pair_hold, m->speed_pair_bound, m->speed_pair_rel, (int)m->speed_pair_steps,
           m->steer_jump, m->lat_span_paired, m->speed_brake_alpha, m->speed_brake_lag, m->speed_slip_rel);
}

/* One output line per input line from a reset monitor and limiter: 0, or 2 on an unreadable line. */
static int replay(const mrs_monitor_coeffs_t *mc, const mrs_authority_coeffs_t *ac)
{
    char line[LINE_MAX_LEN];
    double v[9];
    mrs_monitor_state_t ms;
    mrs_authority_state_t as;
    mrs_monitor_reset(&ms);
    mrs_authority_reset(&as);
    while (fgets(line, sizeof line, stdin) != NULL) {
        uint8_t bits;
        double u;
        if (read_numbers(line, v, 9) != 0) {
            return 2;
        }
        bits = mrs_monitor_step(mc, &ms, v[0], v[1], v[2], v[3], v[4], v[5], v[7], v[8]);
        u = mrs_authority_step(ac, &as, v[6], bits, (uint8_t)((ms.flags & MRS_CUT_CHECKS) != 0u),
                               (uint8_t)((ms.flags & MRS_FADE_CHECKS) != 0u));
        printf("%u %u %.17g %.17g %.17g %.17g %u %.17g %.17g %d %u %d %d %.17g %d %u %d %.17g\n", (unsigned)bits,
               (unsigned)ms.flags, ms.kin_err, ms.pair_err, ms.model_err, u, (unsigned)as.flags, ms.yaw_pair_err,
               ms.turn_err, (int)ms.turn_n, (unsigned)ms.turn_settled, (int)ms.yaw_hold_n, (int)ms.yaw_clear_n,
               ms.speed_pair_err, (int)ms.speed_pair_count, (unsigned)ms.speed2_seen, (int)ms.steer_hold_n,
               ms.speed_lag);
    }
    return 0;
}

int main(void)
{
    char line[LINE_MAX_LEN];
    double v[43];
    mrs_monitor_config_t mg;
    mrs_authority_config_t ag;
    mrs_monitor_coeffs_t mc;
    mrs_authority_coeffs_t ac;

    if (fgets(line, sizeof line, stdin) == NULL) {
        return 2;
    }
    if (strncmp(line, "defaults", 8) == 0) {
        print_defaults();
        return 0;
    }
    if (strncmp(line, "monitor", 7) != 0 || read_numbers(line + 7, v, 43) != 0) {
        return 2;
    }
    monitor_config_of(v, &mg);
    if (fgets(line, sizeof line, stdin) == NULL || strncmp(line, "authority", 9) != 0 ||
        read_numbers(line + 9, v, 8) != 0) {
        return 2;
    }
    authority_config_of(v, &ag);
    if (mrs_monitor_configure(&mg, &mc) != 0 || mrs_authority_configure(&ag, &ac) != 0) {
        return 3;
    }
    print_coeffs(&mc, &ac);
    return replay(&mc, &ac);
}
