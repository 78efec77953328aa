/* C99 port of firmware_py/plausibility.py: see mrs_monitor.h.  Each statement follows the
 * Python module's, in the same order and association, so that double results are identical. */
#include "mrs_monitor.h"

#include <math.h> /* exp() and floor() in the configure functions only; isfinite is a macro */
#include <stddef.h>

#include "mrs_defaults.h"

void mrs_monitor_default_config(mrs_monitor_config_t *cfg)
{
    /* firmware_py/plausibility.py's PlausibilityConfig(), from mrs_defaults.h (generated from it) */
    cfg->ts = MRS_MONITOR_DEFAULT_TS;
    cfg->speed_min = MRS_MONITOR_DEFAULT_SPEED_MIN;
    cfg->yaw_bound = MRS_MONITOR_DEFAULT_YAW_BOUND;
    cfg->yaw_rel = MRS_MONITOR_DEFAULT_YAW_REL;
    cfg->yaw_count = MRS_MONITOR_DEFAULT_YAW_COUNT;
    cfg->yaw_raw_fraction = MRS_MONITOR_DEFAULT_YAW_RAW_FRACTION;
    cfg->steer_bound = MRS_MONITOR_DEFAULT_STEER_BOUND;
    cfg->steer_count = MRS_MONITOR_DEFAULT_STEER_COUNT;
    cfg->model_margin = MRS_MONITOR_DEFAULT_MODEL_MARGIN;
    cfg->model_rel = MRS_MONITOR_DEFAULT_MODEL_REL;
    cfg->model_tau = MRS_MONITOR_DEFAULT_MODEL_TAU;
    cfg->model_time = MRS_MONITOR_DEFAULT_MODEL_TIME;
    cfg->frozen_time = MRS_MONITOR_DEFAULT_FROZEN_TIME;
    cfg->frozen_move_yaw = MRS_MONITOR_DEFAULT_FROZEN_MOVE_YAW;
    cfg->frozen_move_steer = MRS_MONITOR_DEFAULT_FROZEN_MOVE_STEER;
    cfg->nominal_l_f = MRS_MONITOR_DEFAULT_NOMINAL_L_F;
    cfg->nominal_l_r = MRS_MONITOR_DEFAULT_NOMINAL_L_R;
    cfg->nominal_mass = MRS_MONITOR_DEFAULT_NOMINAL_MASS;
    cfg->nominal_c_f = MRS_MONITOR_DEFAULT_NOMINAL_C_F;
    cfg->nominal_c_r = MRS_MONITOR_DEFAULT_NOMINAL_C_R;
    cfg->kin_gap = MRS_MONITOR_DEFAULT_KIN_GAP;
    cfg->mu_min = MRS_MONITOR_DEFAULT_MU_MIN;
    cfg->actuator_tau = MRS_MONITOR_DEFAULT_ACTUATOR_TAU;
    cfg->yaw_pair_bound = MRS_MONITOR_DEFAULT_YAW_PAIR_BOUND;
    cfg->sensor_tau = MRS_MONITOR_DEFAULT_SENSOR_TAU;
    cfg->side_accel = MRS_MONITOR_DEFAULT_SIDE_ACCEL;
    cfg->speed_step = MRS_MONITOR_DEFAULT_SPEED_STEP;
    cfg->turn_yaw_min = MRS_MONITOR_DEFAULT_TURN_YAW_MIN;
    cfg->turn_yaw_tol = MRS_MONITOR_DEFAULT_TURN_YAW_TOL;
    cfg->turn_lat_tol = MRS_MONITOR_DEFAULT_TURN_LAT_TOL;
    cfg->turn_lat_rel = MRS_MONITOR_DEFAULT_TURN_LAT_REL;
    cfg->turn_speed_rel = MRS_MONITOR_DEFAULT_TURN_SPEED_REL;
    cfg->turn_yaw_bias = MRS_MONITOR_DEFAULT_TURN_YAW_BIAS;
    cfg->turn_lat_bias = MRS_MONITOR_DEFAULT_TURN_LAT_BIAS;
    cfg->yaw_pair_hold = MRS_MONITOR_DEFAULT_YAW_PAIR_HOLD;
    cfg->speed_pair_bound = MRS_MONITOR_DEFAULT_SPEED_PAIR_BOUND;
    cfg->speed_pair_rel = MRS_MONITOR_DEFAULT_SPEED_PAIR_REL;
    cfg->speed_pair_time = MRS_MONITOR_DEFAULT_SPEED_PAIR_TIME;
    cfg->steer_jump = MRS_MONITOR_DEFAULT_STEER_JUMP;
    cfg->mu_min_paired = MRS_MONITOR_DEFAULT_MU_MIN_PAIRED;
    cfg->speed_brake_decel = MRS_MONITOR_DEFAULT_SPEED_BRAKE_DECEL;
    cfg->speed_brake_tau = MRS_MONITOR_DEFAULT_SPEED_BRAKE_TAU;
    cfg->speed_slip_rel = MRS_MONITOR_DEFAULT_SPEED_SLIP_REL;
}

static int positive(double x)
{
    return isfinite(x) && x > 0.0;
}

/* A time in periods, rounded half up, at least 1, at most INT32_MAX (plausibility.steps_of). */
static int32_t steps_of(double t, double ts)
{
    double n = floor(t / ts + 0.5);
    return n < 1.0 ? 1 : (n > 2147483647.0 ? INT32_MAX : (int32_t)n);
}

/* in [0, 1000): the relative bounds (plausibility.configure's second loop) */
static int ratio_ok(double x)
{
    return x >= 0.0 && x < 1e3;
}

/* a friction of the kinematic family: in [0.05, 1] */
static int mu_ok(double x)
{
    return x >= 0.05 && x <= 1.0;
}

/* a sample count: an integer in [1, 100] */
static int count_ok(int n)
{
    return n >= 1 && n <= 100;
}

/* plausibility.configure's checks: 1 if the calibration is valid */
static int monitor_config_valid(const mrs_monitor_config_t *g)
{
    const double p[] = {g->ts, g->speed_min, g->yaw_bound, g->yaw_raw_fraction, g->steer_bound, g->model_margin, g->model_tau,
                        g->model_time, g->frozen_time, g->frozen_move_yaw, g->frozen_move_steer, g->nominal_l_f,
                        g->nominal_l_r, g->nominal_mass, g->nominal_c_f, g->nominal_c_r, g->kin_gap, g->actuator_tau,
                        g->yaw_pair_bound, g->sensor_tau, g->speed_step, g->turn_yaw_min, g->turn_yaw_tol,
                        g->turn_lat_tol, g->turn_speed_rel, g->yaw_pair_hold, g->speed_pair_bound,
                        g->speed_pair_time, g->steer_jump, g->speed_brake_decel, g->speed_brake_tau};
    const double r[] = {g->model_rel, g->yaw_rel, g->side_accel, g->turn_lat_rel, g->turn_yaw_bias, g->turn_lat_bias,
                        g->speed_pair_rel, g->speed_slip_rel};
    size_t i;
    for (i = 0u; i < sizeof p / sizeof p[0]; ++i) {
        if (!positive(p[i])) {
            return 0;
        }
    }
    for (i = 0u; i < sizeof r / sizeof r[0]; ++i) {
        if (!ratio_ok(r[i])) {
            return 0;
        }
    }
    return count_ok(g->yaw_count) && count_ok(g->steer_count) && mu_ok(g->mu_min) && mu_ok(g->mu_min_paired) &&
           g->speed_brake_tau <= 10.0 && g->turn_yaw_tol < 2.0 * g->turn_yaw_min &&
           g->yaw_pair_hold <= g->yaw_pair_bound;
}

int mrs_monitor_configure(const mrs_monitor_config_t *g, mrs_monitor_coeffs_t *c)
{
    double wheelbase;
    if (!monitor_config_valid(g)) {
        return -1;
    }
    wheelbase = g->nominal_l_f + g->nominal_l_r;
    c->speed_min = g->speed_min;
    c->yaw_bound = g->yaw_bound;
    c->yaw_rel = g->yaw_rel;
    c->inv_yaw_raw_fraction = 1.0 / g->yaw_raw_fraction;
    c->yaw_count = g->yaw_count;
    c->steer_bound = g->steer_bound;
    c->inv_steer_bound = 1.0 / g->steer_bound;
    c->steer_count = g->steer_count;
    c->model_margin = g->model_margin;
    c->model_rel = g->model_rel;
    c->model_alpha = 1.0 - exp(-g->ts / g->model_tau);
    c->model_steps = steps_of(g->model_time, g->ts);
    c->frozen_steps = steps_of(g->frozen_time, g->ts);
    c->kin_gap_steps = steps_of(g->kin_gap, g->ts);
    c->frozen_move_yaw = g->frozen_move_yaw;
    c->frozen_move_steer = g->frozen_move_steer;
    c->wheelbase = wheelbase;
    c->k_us = (g->nominal_c_r * g->nominal_l_r - g->nominal_c_f * g->nominal_l_f) * g->nominal_mass /
              (g->nominal_c_f * g->nominal_c_r * wheelbase);
    c->ts = g->ts;
    c->inv_cs_m = g->nominal_mass / (g->nominal_c_f + g->nominal_c_r);
    c->moment_m = (g->nominal_c_r * g->nominal_l_r - g->nominal_c_f * g->nominal_l_f) / g->nominal_mass;
    c->cf_m = g->nominal_c_f / g->nominal_mass;
    c->lat_span = 1.0 / g->mu_min - 1.0;
    c->aux_alpha = 1.0 - exp(-g->ts / g->actuator_tau);
    c->yaw_pair_bound = g->yaw_pair_bound;
    c->inv_yaw_pair_bound = 1.0 / g->yaw_pair_bound;
    c->delta_alpha = 1.0 - exp(-g->ts / g->sensor_tau);
    c->side_accel = g->side_accel;
    c->speed_step = g->speed_step;
    c->turn_yaw_min = g->turn_yaw_min;
    c->turn_yaw_tol = g->turn_yaw_tol;
    c->turn_lat_tol = g->turn_lat_tol;
    c->turn_lat_rel = g->turn_lat_rel;
    c->turn_speed_rel = g->turn_speed_rel;
    c->turn_yaw_bias = g->turn_yaw_bias;
    c->turn_lat_bias = g->turn_lat_bias;
    c->yaw_pair_hold = g->yaw_pair_hold;
    c->speed_pair_bound = g->speed_pair_bound;
    c->speed_pair_rel = g->speed_pair_rel;
    c->speed_pair_steps = steps_of(g->speed_pair_time, g->ts);
    c->steer_jump = g->steer_jump;
    c->lat_span_paired = 1.0 / g->mu_min_paired - 1.0;
    /* a first-order lag follows a ramp falling at a per period (1 - alpha) a / alpha above it */
    c->speed_brake_alpha = 1.0 - exp(-g->ts / g->speed_brake_tau);
    c->speed_brake_lag = (1.0 - c->speed_brake_alpha) * g->speed_brake_decel * g->ts / c->speed_brake_alpha;
    c->speed_slip_rel = g->speed_slip_rel;
    return 0;
}

void mrs_monitor_reset(mrs_monitor_state_t *s)
{
    int i;
    s->started = 0u;
    s->lat_prev = 0.0;
    s->steer2_prev = 0.0;
    s->kin_count = 0;
    s->pair_count = 0;
    s->model_count = 0;
    s->r_model = 0.0;
    s->yaw_last = s->lat_last = s->st_last = s->st2_last = 0.0;
    s->yaw_same = s->lat_same = s->st_same = s->st2_same = 0;
    s->yaw_ref = s->lat_ref = s->st_ref = s->st2_ref = 0.0;
    s->yaw_ref_ok = s->st_ref_ok = 0u;
    s->latched = 0u;
    s->flags = 0u;
    s->bits = 0u;
    s->kin_err = s->pair_err = s->model_err = 0.0;
    s->since = 0;
    s->have_sample = 0u;
    s->raw_prev = 0.0;
    s->beta_prev = 0.0;
    s->lat_beta_prev = 0.0;
    s->aux_lag = 0.0;
    s->delta_lag = 0.0;
    s->lag_beta_prev = 0.0;
    for (i = 0; i < MRS_KIN_WINDOW; ++i) {
        s->kin_raw[i] = 0.0;
        s->kin_comp[i] = 0.0;
        s->kin_lat[i] = 0.0;
        s->kin_sensor[i] = 0.0;
    }
    s->kin_idx = 0;
    s->kin_n = 0;
    for (i = 0; i < MRS_YAW_PAIR_WINDOW; ++i) {
        s->yaw_pair[i] = 0.0;
    }
    s->yaw_pair_idx = 0;
    s->yaw_pair_n = 0;
    s->yaw_pair_err = 0.0;
    s->yaw_hold_n = 0;
    s->yaw_clear_n = 0;
    s->yaw2_seen = 0u;
    s->speed_last = 0.0;
    s->speed_lag = 0.0;
    s->speed_seen = 0u;
    s->turn_n = 0;
    s->turn_settled = 0u;
    s->turn_r0 = s->turn_a0 = 0.0;
    s->turn_res = s->turn_r = 0.0;
    s->turn_err = 0.0;
    s->speed2_seen = 0u;
    s->speed_pair_count = 0;
    s->speed_pair_err = 0.0;
    s->jump_prev = 0.0;
    s->jump_ok = 0u;
    s->steer_hold_n = 0;
}

/* |x| without a call (x is a side-effect-free expression everywhere below). */
#define MRS_MAG(x) ((x) < 0.0 ? -(x) : (x))

/* Up/down counter: +1 over the bound (saturating at n, then the check latches), -1 within. */
#define MRS_COUNT(cnt, over, n, bit)       \
    do {                                   \
        if (over) {                        \
            (cnt) += 1;                    \
            if ((cnt) >= (n)) {            \
                (cnt) = (n);               \
                s->latched |= (bit);       \
            }                              \
        } else if ((cnt) > 0) {            \
            (cnt) -= 1;                    \
        }                                  \
    } while (0)

/*
 * One control period is the units below in this order, with the names of firmware_py/
 * plausibility.py's: one per check family, each reading the coefficients and the state fields
 * its comment there names, latching its fault into s->latched and returning what the period's
 * other units read (a suspicion flag, a vote).  plausibility_bits is the combiner.
 */

/* The combiner's table (PLAUS_TABLE): a detailed flag in the mask sets the bus bit. */
static const struct {
    uint16_t mask;
    uint8_t bit;
} plaus_table[3] = {
    {MRS_YAW_CHECKS, MRS_PLAUS_YAW},
    {MRS_STEER_CHECKS, MRS_PLAUS_STEER},
    {MRS_DEGRADED_CHECKS, MRS_PLAUS_DEGRADED},
};

static uint8_t plausibility_bits(uint16_t flags)
{
    uint8_t bits = 0u;
    int k;
    for (k = 0; k < 3; k++) {
        if ((flags & plaus_table[k].mask) != 0u) {
            bits = (uint8_t)(bits | plaus_table[k].bit);
        }
    }
    return bits;
}

/* 6. speed step: a jump no car makes; before the pause below speed_min (K_n(v) follows it) */
static void speed_step_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double speed)
{
    if (speed >= 0.0 && speed < 1e3) {
        if (s->speed_seen && speed != s->speed_last) {
            const double e = MRS_MAG(speed - s->speed_last);
            if (e > c->speed_step) {
                s->latched |= MRS_CHECK_SPEED;
            }
        }
        if (s->speed_seen) {
            s->speed_lag += c->speed_brake_alpha * (speed - s->speed_lag);
        } else {
            s->speed_lag = speed;
        }
        s->speed_last = speed;
        s->speed_seen = 1u;
    } else {
        s->speed_seen = 0u;
    }
}

/* 8. speed pair: before the pause too (a drifting speed carries the reading under speed_min);
 * returns the vote: the second speed there and agreeing (it out-votes check 7) */
static int speed_pair_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double speed,
                            double speed_redundant)
{
    double e, x, bound;
    int within;
    if (!(speed_redundant >= 0.0 && speed_redundant < 1e3)) {
        s->speed_pair_count = 0;
        return 0;
    }
    s->speed2_seen = 1u;
    if (!(speed >= 0.0 && speed < 1e3)) {
        s->speed_pair_count = 0;
        return 0;
    }
    e = MRS_MAG(speed - speed_redundant);
    x = speed < speed_redundant ? speed : speed_redundant; /* min(v, v_2) */
    bound = c->speed_pair_bound + c->speed_pair_rel * x;
    within = e <= bound; /* it vouches (out-votes check 7) only within the plain bound */
    if (speed_redundant < speed && s->speed_lag - speed > c->speed_brake_lag) {
        bound += c->speed_slip_rel * x; /* braking: the wheels the second speed is read from slip */
    }
    s->speed_pair_err = e / bound;
    MRS_COUNT(s->speed_pair_count, e > bound, c->speed_pair_steps, MRS_CHECK_SPEED_PAIR);
    return s->speed_pair_count == 0 && within;
}

/* MISSING when a redundant input the car has is gone: the second speed or the yaw rate's second
 * element (once received, while the first is valid: the pair pauses), a_y or the second channel */
static uint16_t input_flags(mrs_monitor_state_t *s, double yaw_rate, double yaw_rate_redundant, double speed,
                            double speed_redundant, int lat_ok, int st2_ok)
{
    uint16_t flags = 0u;
    if (s->speed2_seen && !(speed_redundant >= 0.0 && speed_redundant < 1e3) && speed >= 0.0 && speed < 1e3) {
        flags |= MRS_MISSING;
    }
    if (yaw_rate_redundant > -1e3 && yaw_rate_redundant < 1e3) {
        s->yaw2_seen = 1u;
    } else if (s->yaw2_seen && yaw_rate > -1e3 && yaw_rate < 1e3) {
        flags |= MRS_MISSING;
    }
    if (!(lat_ok && st2_ok)) {
        flags |= MRS_MISSING;
    }
    return flags;
}

/* the redundant frame missing: the steady-turn check starts afresh when it is back, and after a
 * long gap the kinematic window too (a shorter one is bridged as a lost frame is) */
static void redundant_frame_lost(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s)
{
    s->turn_n = 0;
    s->turn_settled = 0u;
    if (s->since >= c->kin_gap_steps) {
        s->have_sample = 0u;
        s->kin_n = 0;
    }
}

/* paused (too slow, or mrs_step faults on the input): restart the windows, keep the latch */
static void monitor_pause(mrs_monitor_state_t *s)
{
    s->kin_count = s->pair_count = s->model_count = 0;
    s->yaw_pair_n = 0;
    s->yaw_same = s->lat_same = s->st_same = s->st2_same = 0;
    s->jump_ok = 0u;
    s->steer_hold_n = 0;
    s->kin_n = 0;
    s->turn_n = 0;
    s->turn_settled = 0u;
    s->started = 0u;
}

/* the first period after a pause: the lags and the previous samples start at this one */
static void monitor_start(mrs_monitor_state_t *s, double delta_driver, double delta_driver_redundant,
                          double yaw_rate, double lat_accel, double r_kin, double r_ss, double delta)
{
    s->r_model = r_ss;
    s->kin_n = 0;
    s->kin_idx = 0;
    s->since = 0;
    s->have_sample = 0u;
    s->lat_prev = lat_accel;
    s->steer2_prev = delta_driver_redundant;
    s->yaw_last = yaw_rate;
    s->lat_last = lat_accel;
    s->st_last = delta_driver;
    s->st2_last = delta_driver_redundant;
    s->yaw_ref = r_kin;
    s->lat_ref = yaw_rate;
    s->st_ref = delta_driver_redundant;
    s->st2_ref = delta_driver;
    s->yaw_ref_ok = s->st_ref_ok = 0u;
    s->delta_lag = delta;
    s->turn_n = 0;
    s->turn_settled = 0u;
    s->started = 1u;
}

/* the yaw rate confirmed by its second element: valid, the window full, its last samples within the hold */
static int yaw_confirmed(const mrs_monitor_state_t *s, double yaw_rate_redundant)
{
    return yaw_rate_redundant > -1e3 && yaw_rate_redundant < 1e3 && s->yaw_pair_n >= MRS_YAW_PAIR_WINDOW &&
           s->yaw_clear_n >= MRS_YAW_PAIR_WINDOW;
}

/* 2. model: the nominal car's steady-state yaw rate, lagged, against the yaw rate; out-voted
 * while the yaw rate is confirmed by its second element and by a_y / v */
static void model_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate, double r_ss,
                        int lat_ok, double yaw_rate_redundant)
{
    double e, rm, bound;
    int confirmed, vouched;
    s->r_model += c->model_alpha * (r_ss - s->r_model);
    e = MRS_MAG(yaw_rate - s->r_model);
    rm = MRS_MAG(s->r_model);
    bound = c->model_margin + c->model_rel * rm;
    s->model_err = e / bound;
    confirmed = yaw_confirmed(s, yaw_rate_redundant);
    vouched = confirmed && lat_ok && s->kin_n >= MRS_KIN_WINDOW && s->kin_count == 0;
    /* confirmed: not the yaw rate's error */
    MRS_COUNT(s->model_count, e > bound && !vouched, c->model_steps,
              (confirmed != 0) ? MRS_OUTSIDE_MODEL : MRS_CHECK_MODEL);
}

/* 4'. the yaw-rate pair's suspicion on one sample's r - r_2, capped so that an offset the
 * window never confirms cannot freeze the law: MRS_SUSPECT_YAW_PAIR or 0 */
static uint16_t yaw_pair_suspicion(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double e)
{
    if (e > c->yaw_pair_hold || e < -c->yaw_pair_hold) {
        s->yaw_clear_n = 0;
        if (s->yaw_hold_n < MRS_YAW_PAIR_WINDOW) {
            s->yaw_hold_n += 1;
            return MRS_SUSPECT_YAW_PAIR;
        }
        return 0u;
    }
    if (s->yaw_clear_n < MRS_YAW_PAIR_WINDOW) {
        s->yaw_clear_n += 1;
    }
    if (s->yaw_clear_n >= MRS_YAW_PAIR_WINDOW) {
        s->yaw_hold_n = 0;
    }
    return 0u;
}

/* 4. yaw-rate pair: the mean of r - r_2 over the last MRS_YAW_PAIR_WINDOW samples; returns the
 * suspicion's flag */
static uint16_t yaw_pair_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate,
                               double yaw_rate_redundant)
{
    int32_t i;
    uint16_t suspect;
    if (!(yaw_rate_redundant > -1e3 && yaw_rate_redundant < 1e3)) {
        s->yaw_pair_n = 0; /* the window restarts when the second element is back */
        return 0u;
    }
    i = s->yaw_pair_idx;
    s->yaw_pair[i] = yaw_rate - yaw_rate_redundant;
    i += 1;
    if (i >= MRS_YAW_PAIR_WINDOW) {
        i = 0;
    }
    s->yaw_pair_idx = i;
    suspect = yaw_pair_suspicion(c, s, yaw_rate - yaw_rate_redundant);
    if (s->yaw_pair_n < MRS_YAW_PAIR_WINDOW) {
        s->yaw_pair_n += 1;
    }
    if (s->yaw_pair_n >= MRS_YAW_PAIR_WINDOW) {
        const double e = MRS_MAG((s->yaw_pair[0] + s->yaw_pair[1] + s->yaw_pair[2] + s->yaw_pair[3] +
                                  s->yaw_pair[4]) * (1.0 / MRS_YAW_PAIR_WINDOW));
        s->yaw_pair_err = e * c->inv_yaw_pair_bound;
        if (e > c->yaw_pair_bound) {
            s->latched |= MRS_CHECK_YAW_PAIR;
        }
    }
    return suspect;
}

/* 3'. the steering pair's suspicion: a jump of the driver's angle no hand makes between two
 * redundant samples holds the command until the next one, where the pair judges it */
static uint16_t steer_jump_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                                 int new_sample, int st2_ok)
{
    uint16_t suspect = 0u;
    if (new_sample || !st2_ok) {
        s->steer_hold_n = 0;
    } else {
        const double e = delta_driver - s->jump_prev;
        if (s->jump_ok && (e > c->steer_jump || e < -c->steer_jump)) {
            s->steer_hold_n = c->kin_gap_steps;
        }
        if (s->steer_hold_n > 0) {
            s->steer_hold_n -= 1;
            suspect = MRS_SUSPECT_STEER_JUMP;
        }
    }
    s->jump_prev = delta_driver;
    s->jump_ok = 1u;
    return suspect;
}

/* 1, at a new redundant sample: a_y / v - r midway between this sample and the last, as
 * measured and less the nominal car's beta', into the window of MRS_KIN_WINDOW intervals */
static void kinematic_sample(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate,
                             double lat_accel, double speed, double inv_v, double r_kin, double delta)
{
    const double raw = r_kin - yaw_rate;
    const double beta =
        (c->moment_m * inv_v * inv_v * yaw_rate + c->cf_m * inv_v * delta - r_kin) * c->inv_cs_m * speed;
    const double lat_beta = lat_accel * c->inv_cs_m;
    /* the nominal car's beta with the wheel angle through the sensors' lag, less beta */
    const double lag_beta = c->cf_m * inv_v * (s->delta_lag - delta) * c->inv_cs_m * speed;
    if (s->have_sample) {
        const double mid = 0.5 * (raw + s->raw_prev);
        int32_t i = s->kin_idx;
        s->kin_raw[i] = mid;
        s->kin_comp[i] = mid - (beta - s->beta_prev) / ((double)s->since * c->ts);
        s->kin_lat[i] = (lat_beta - s->lat_beta_prev) / ((double)s->since * c->ts);
        s->kin_sensor[i] = (s->lag_beta_prev - lag_beta) / ((double)s->since * c->ts);
        i += 1;
        if (i >= MRS_KIN_WINDOW) {
            i = 0;
        }
        s->kin_idx = i;
        if (s->kin_n < MRS_KIN_WINDOW) {
            s->kin_n += 1;
        }
    }
    s->have_sample = 1u;
    s->raw_prev = raw;
    s->beta_prev = beta;
    s->lat_beta_prev = lat_beta;
    s->lag_beta_prev = lag_beta;
    s->since = 0;
}

/* 1. the window's residual: the smaller of |raw| / yaw_raw_fraction and the smallest |comp| of
 * the family of nominal cars on mu in [mu_min, 1] (mu_min_paired while the yaw-rate pair runs)
 * and sensor lags in [0, sensor_tau]: 0 if its four corners differ in sign, else the smallest
 * corner's magnitude */
static double kinematic_residual(const mrs_monitor_coeffs_t *c, const mrs_monitor_state_t *s)
{
    const double raw = MRS_MAG((s->kin_raw[0] + s->kin_raw[1] + s->kin_raw[2] + s->kin_raw[3]) *
                               (1.0 / MRS_KIN_WINDOW)) * c->inv_yaw_raw_fraction;
    double comp = (s->kin_comp[0] + s->kin_comp[1] + s->kin_comp[2] + s->kin_comp[3]) * (1.0 / MRS_KIN_WINDOW);
    const double span = s->yaw_pair_n >= MRS_YAW_PAIR_WINDOW ? c->lat_span_paired : c->lat_span;
    const double far = span * ((s->kin_lat[0] + s->kin_lat[1] + s->kin_lat[2] + s->kin_lat[3]) *
                               (1.0 / MRS_KIN_WINDOW));
    const double sens =
        (s->kin_sensor[0] + s->kin_sensor[1] + s->kin_sensor[2] + s->kin_sensor[3]) * (1.0 / MRS_KIN_WINDOW);
    double lo = comp, hi = comp, x;
    x = comp + sens;
    lo = x < lo ? x : lo;
    hi = x > hi ? x : hi;
    x = comp + far;
    lo = x < lo ? x : lo;
    hi = x > hi ? x : hi;
    x = comp + far + sens;
    lo = x < lo ? x : lo;
    hi = x > hi ? x : hi;
    if (lo <= 0.0 && hi >= 0.0) {
        comp = 0.0;
    } else if (lo > 0.0) {
        comp = lo;
    } else {
        comp = -hi;
    }
    return comp < raw ? comp : raw;
}

/* 1. kinematic, at a new redundant sample: the window's residual against its bound */
static void kinematic_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate,
                            double inv_v, double r_kin)
{
    double e = kinematic_residual(c, s);
    double x, turn, bound;
    if (s->kin_n < MRS_KIN_WINDOW) {
        e = 0.0;
    }
    /* the relative allowance on the smaller of the turn's two measures, a_y / v and r: a
     * wrong one cannot widen its own bound */
    x = MRS_MAG(yaw_rate);
    turn = MRS_MAG(r_kin);
    bound = c->yaw_bound + c->yaw_rel * (x < turn ? x : turn);
    if (s->yaw_pair_n >= MRS_YAW_PAIR_WINDOW) {
        bound += c->side_accel * inv_v; /* the pair checks the yaw rate: allow a side force */
    }
    s->kin_err = e / bound;
    /* the yaw rate confirmed by its second element (this sample in the window, within the hold) */
    MRS_COUNT(s->kin_count, e > bound, c->yaw_count,
              (s->yaw_pair_n >= MRS_YAW_PAIR_WINDOW && s->yaw_clear_n >= MRS_YAW_PAIR_WINDOW) ?
                  MRS_OUTSIDE_MODEL : MRS_CHECK_KINEMATIC);
}

/* 3. steering pair, at a new redundant sample */
static void steer_pair_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                             double delta_driver_redundant)
{
    const double e = MRS_MAG(delta_driver - delta_driver_redundant);
    s->pair_err = e * c->inv_steer_bound;
    MRS_COUNT(s->pair_count, e > c->steer_bound, c->steer_count, MRS_CHECK_STEER_PAIR);
}

/* 7'. a steady-turn block goes on while r and a_y stay near its first sample's (r then on the
 * same side: configure keeps turn_yaw_tol below 2 turn_yaw_min); else, and at its start, it
 * starts at this sample */
static void turn_block_start(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate,
                             double lat_accel)
{
    if (s->turn_n > 0) {
        const double e = MRS_MAG(yaw_rate - s->turn_r0);
        const double x = MRS_MAG(lat_accel - s->turn_a0);
        const double am = MRS_MAG(s->turn_a0);
        if (e > c->turn_yaw_tol || x > c->turn_lat_tol + c->turn_lat_rel * am) {
            s->turn_n = 0;
            s->turn_settled = 0u;
        }
    }
    if (s->turn_n == 0) {
        s->turn_r0 = yaw_rate;
        s->turn_a0 = lat_accel;
        s->turn_res = 0.0;
        s->turn_r = 0.0;
    }
}

/* 7. the speed against a_y / r in a steady turn (blocks of MRS_TURN_BLOCK samples), at a new
 * redundant sample; out-voted by an agreeing second speed (speed_vouched) */
static void turn_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate, double lat_accel,
                       double speed, int speed_vouched)
{
    double e, rm, bound;
    if (MRS_MAG(yaw_rate) < c->turn_yaw_min) {
        s->turn_n = 0;
        s->turn_settled = 0u;
        return;
    }
    turn_block_start(c, s, yaw_rate, lat_accel);
    s->turn_res += yaw_rate * speed - lat_accel;
    s->turn_r += yaw_rate;
    s->turn_n += 1;
    if (s->turn_n < MRS_TURN_BLOCK) {
        return;
    }
    /* the speed less a_y / r over the block (r-weighted), against what the sensors' offsets and
     * the rest of the side slip can make of it at the block's mean |r| */
    e = MRS_MAG(s->turn_res / s->turn_r);
    rm = MRS_MAG(s->turn_r * (1.0 / MRS_TURN_BLOCK));
    bound = c->turn_speed_rel * speed + (c->turn_yaw_bias * speed + c->turn_lat_bias) / rm;
    if (s->turn_settled) {
        s->turn_err = e / bound;
        if (e > bound && !speed_vouched) {
            s->latched |= MRS_CHECK_TURN;
        }
    }
    s->turn_settled = 1u;
    s->turn_n = 0;
}

/* 5. one step of a frozen value whose partner moved: the count, saturated at frozen_steps,
 * latching bit there; shared by the four frozen checks (plausibility.py frozen_count) */
static int32_t frozen_count(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, int32_t same, unsigned bit)
{
    int32_t n = same;
    if (n < c->frozen_steps) {
        n += 1;
    }
    if (n >= c->frozen_steps) {
        s->latched |= bit;
    }
    return n;
}

/* 5. frozen yaw rate against a_y / v, taken at its first sample after the yaw rate's last change */
static void frozen_yaw_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate, double r_kin,
                             int lat_ok, int new_sample)
{
    if (yaw_rate != s->yaw_last) {
        s->yaw_last = yaw_rate;
        s->yaw_same = 0;
        s->yaw_ref_ok = 0u;
    } else if (new_sample && !s->yaw_ref_ok) {
        s->yaw_ref = r_kin;
        s->yaw_ref_ok = 1u;
    } else if (lat_ok && s->yaw_ref_ok && MRS_MAG(r_kin - s->yaw_ref) > c->frozen_move_yaw) {
        s->yaw_same = frozen_count(c, s, s->yaw_same, MRS_FROZEN_YAW);
    }
}

/* 5. frozen a_y against the yaw rate */
static void frozen_lat_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double yaw_rate,
                             double lat_accel)
{
    if (lat_accel != s->lat_last) {
        s->lat_last = lat_accel;
        s->lat_same = 0;
        s->lat_ref = yaw_rate;
    } else if (MRS_MAG(yaw_rate - s->lat_ref) > c->frozen_move_yaw) {
        s->lat_same = frozen_count(c, s, s->lat_same, MRS_FROZEN_LAT);
    }
}

/* 5. frozen driver's angle against the second channel, taken at its first sample after the
 * angle's last change */
static void frozen_steer_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                               double delta_driver_redundant, int new_sample)
{
    if (delta_driver != s->st_last) {
        s->st_last = delta_driver;
        s->st_same = 0;
        s->st_ref_ok = 0u;
    } else if (new_sample && !s->st_ref_ok) {
        s->st_ref = delta_driver_redundant;
        s->st_ref_ok = 1u;
    } else if (s->st_ref_ok && MRS_MAG(delta_driver_redundant - s->st_ref) > c->frozen_move_steer) {
        s->st_same = frozen_count(c, s, s->st_same, MRS_FROZEN_STEER);
    }
}

/* 5. frozen second steering channel against the driver's angle */
static void frozen_steer2_check(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                                double delta_driver_redundant)
{
    if (delta_driver_redundant != s->st2_last) {
        s->st2_last = delta_driver_redundant;
        s->st2_same = 0;
        s->st2_ref = delta_driver;
    } else if (MRS_MAG(delta_driver - s->st2_ref) > c->frozen_move_steer) {
        s->st2_same = frozen_count(c, s, s->st2_same, MRS_FROZEN_STEER_2);
    }
}

/* 5. frozen: unchanged for frozen_steps counted while the partner is away from where it was at
 * this value's last change */
static void frozen_checks(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                          double delta_driver_redundant, double yaw_rate, double lat_accel, double r_kin,
                          int lat_ok, int st2_ok, int new_sample)
{
    frozen_yaw_check(c, s, yaw_rate, r_kin, lat_ok, new_sample);
    if (lat_ok) {
        frozen_lat_check(c, s, yaw_rate, lat_accel);
    }
    if (st2_ok) {
        frozen_steer_check(c, s, delta_driver, delta_driver_redundant, new_sample);
        frozen_steer2_check(c, s, delta_driver, delta_driver_redundant);
    }
}

/* 1, 3 and 7 at a new redundant sample (either of its values changed) */
static void redundant_checks(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                             double delta_driver_redundant, double yaw_rate, double lat_accel, double speed,
                             double inv_v, double r_kin, double delta, int speed_vouched)
{
    kinematic_sample(c, s, yaw_rate, lat_accel, speed, inv_v, r_kin, delta);
    kinematic_check(c, s, yaw_rate, inv_v, r_kin);
    steer_pair_check(c, s, delta_driver, delta_driver_redundant);
    turn_check(c, s, yaw_rate, lat_accel, speed, speed_vouched);
}

/* the period's flags (the latched ones with this period's) and bits into the state */
static uint8_t monitor_finish(mrs_monitor_state_t *s, uint16_t flags)
{
    flags |= s->latched;
    s->flags = flags;
    s->bits = plausibility_bits(flags);
    return s->bits;
}

/* x valid: 0 for NaN and +-inf (Python's -1e3 < x < 1e3) */
static int in_range(double x)
{
    return x > -1e3 && x < 1e3;
}

/* the inputs every check but the speed's needs: valid (0 for NaN and +-inf), the car at
 * speed_min or faster */
static int primary_valid(const mrs_monitor_coeffs_t *c, double delta_driver, double yaw_rate, double speed,
                         double aux_cmd_applied)
{
    return (delta_driver > -1e3 && delta_driver < 1e3) && (yaw_rate > -1e3 && yaw_rate < 1e3) &&
           (speed >= c->speed_min && speed < 1e3) && (aux_cmd_applied > -1e3 && aux_cmd_applied < 1e3);
}

uint8_t mrs_monitor_step(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                         double delta_driver_redundant, double yaw_rate, double lat_accel, double speed,
                         double aux_cmd_applied, double yaw_rate_redundant, double speed_redundant)
{
    const int lat_ok = in_range(lat_accel);
    const int st2_ok = in_range(delta_driver_redundant);
    uint16_t flags;
    int primary_ok, speed_vouched, new_sample;
    double inv_v, r_kin, delta, r_ss;

    speed_step_check(c, s, speed);
    speed_vouched = speed_pair_check(c, s, speed, speed_redundant);
    primary_ok = primary_valid(c, delta_driver, yaw_rate, speed, aux_cmd_applied);
    flags = input_flags(s, yaw_rate, yaw_rate_redundant, speed, speed_redundant, lat_ok, st2_ok);
    if (!(lat_ok && st2_ok)) {
        redundant_frame_lost(c, s);
    }
    if (!primary_ok) {
        monitor_pause(s);
        return monitor_finish(s, flags);
    }
    inv_v = 1.0 / speed;
    r_kin = lat_ok ? lat_accel * inv_v : 0.0;
    if (!s->started) {
        s->aux_lag = aux_cmd_applied;
    }
    /* the angle on the car: the command sent the period before, through the actuator's lag */
    s->aux_lag += c->aux_alpha * (aux_cmd_applied - s->aux_lag);
    delta = delta_driver + s->aux_lag;
    r_ss = delta * speed / (c->wheelbase + c->k_us * speed * speed); /* the nominal car's steady-state yaw rate */
    if (!s->started) {
        monitor_start(s, delta_driver, delta_driver_redundant, yaw_rate, lat_accel, r_kin, r_ss, delta);
    }
    /* the wheel angle as the filtered a_y and yaw rate show its effect (the kinematic check) */
    s->delta_lag += c->delta_alpha * (delta - s->delta_lag);
    model_check(c, s, yaw_rate, r_ss, lat_ok, yaw_rate_redundant);
    flags |= yaw_pair_check(c, s, yaw_rate, yaw_rate_redundant);
    if (s->since < 1000000) {
        s->since += 1;
    }
    new_sample = lat_ok && st2_ok && (lat_accel != s->lat_prev || delta_driver_redundant != s->steer2_prev);
    flags |= steer_jump_check(c, s, delta_driver, new_sample, st2_ok);
    if (new_sample) {
        redundant_checks(c, s, delta_driver, delta_driver_redundant, yaw_rate, lat_accel, speed, inv_v, r_kin,
                         delta, speed_vouched);
    }
    if (lat_ok) {
        s->lat_prev = lat_accel;
    }
    if (st2_ok) {
        s->steer2_prev = delta_driver_redundant;
    }
    frozen_checks(c, s, delta_driver, delta_driver_redundant, yaw_rate, lat_accel, r_kin, lat_ok, st2_ok,
                  new_sample);
    return monitor_finish(s, flags);
}

/* ------------------------------------------------------------------ bounded authority */

void mrs_authority_default_config(mrs_authority_config_t *cfg)
{
    /* firmware_py/authority.py's AuthorityConfig(), from mrs_defaults.h (generated from it) */
    cfg->ts = MRS_AUTHORITY_DEFAULT_TS;
    cfg->u_max = MRS_AUTHORITY_DEFAULT_U_MAX;
    cfg->rate_max = MRS_AUTHORITY_DEFAULT_RATE_MAX;
    cfg->fade_rate = MRS_AUTHORITY_DEFAULT_FADE_RATE;
    cfg->fault_fade_rate = MRS_AUTHORITY_DEFAULT_FAULT_FADE_RATE;
    cfg->panic_window = MRS_AUTHORITY_DEFAULT_PANIC_WINDOW;
    cfg->engage = MRS_AUTHORITY_DEFAULT_ENGAGE;
    cfg->rearm_time = MRS_AUTHORITY_DEFAULT_REARM_TIME;
}

int mrs_authority_configure(const mrs_authority_config_t *g, mrs_authority_coeffs_t *c)
{
    if (!positive(g->ts) || !positive(g->u_max) || !positive(g->rate_max) || !positive(g->fade_rate) ||
        !positive(g->fault_fade_rate) || !positive(g->panic_window) || !positive(g->engage) ||
        !positive(g->rearm_time)) {
        return -1;
    }
    c->u_max = g->u_max;
    c->du_max = g->rate_max * g->ts;
    c->fade_step = g->fade_rate * g->ts;
    c->fault_fade_step = g->fault_fade_rate * g->ts;
    c->window_steps = steps_of(g->panic_window, g->ts);
    c->engage = g->engage;
    c->rearm_steps = steps_of(g->rearm_time, g->ts);
    return 0;
}

void mrs_authority_reset(mrs_authority_state_t *s)
{
    s->u = 0.0;
    s->engaged = 0;
    s->quiet = 0;
    s->flags = 0u;
}

/* why the command goes to zero this period: MRS_AUTH_FAULT (a plausibility fault, fade or a
 * non-finite request), MRS_AUTH_TIME (the panic window over while DEGRADED), else 0 */
static uint8_t fade_cause(const mrs_authority_coeffs_t *c, const mrs_authority_state_t *s, double u_request,
                          uint8_t plaus_bits, uint8_t fade)
{
    if ((plaus_bits & MRS_PLAUS_FAULT) != 0u || fade != 0u || !(u_request > -1e3 && u_request < 1e3)) {
        return MRS_AUTH_FAULT;
    }
    if (s->engaged >= c->window_steps && (plaus_bits & MRS_PLAUS_DEGRADED) != 0u) {
        return MRS_AUTH_TIME;
    }
    return 0u;
}

/* the request within +-u_max (MRS_AUTH_MAGNITUDE into s->flags when it bounds) */
static double magnitude_bound(const mrs_authority_coeffs_t *c, mrs_authority_state_t *s, double u_request)
{
    if (u_request > c->u_max) {
        s->flags |= MRS_AUTH_MAGNITUDE;
        return c->u_max;
    }
    if (u_request < -c->u_max) {
        s->flags |= MRS_AUTH_MAGNITUDE;
        return -c->u_max;
    }
    return u_request;
}

/* the step d within +-du (MRS_AUTH_RATE into s->flags when rate_max bounds it) */
static double rate_bound(const mrs_authority_coeffs_t *c, mrs_authority_state_t *s, double d, double du)
{
    if (d > du) {
        d = du;
        s->flags |= (du == c->du_max) ? MRS_AUTH_RATE : 0u;
    } else if (d < -du) {
        d = -du;
        s->flags |= (du == c->du_max) ? MRS_AUTH_RATE : 0u;
    }
    return d;
}

/* the panic window's count: periods the command or the request intervened (the request too: a
 * request the time rule faded does not re-arm the window by resting the command), restarted
 * after rearm_steps at rest in a row */
static void intervention_window(const mrs_authority_coeffs_t *c, mrs_authority_state_t *s, double u,
                                double u_request)
{
    if (u > c->engage || u < -c->engage || u_request > c->engage || u_request < -c->engage) {
        if (s->engaged < c->window_steps) {
            s->engaged += 1;
        }
        s->quiet = 0;
    } else {
        if (s->quiet < c->rearm_steps) {
            s->quiet += 1;
        }
        if (s->quiet >= c->rearm_steps) {
            s->engaged = 0;
        }
    }
}

double mrs_authority_step(const mrs_authority_coeffs_t *c, mrs_authority_state_t *s, double u_request,
                          uint8_t plaus_bits, uint8_t cut, uint8_t fade)
{
    const uint8_t why = fade_cause(c, s, u_request, plaus_bits, fade);
    double target, du, u;
    s->flags = why;
    if (why == MRS_AUTH_FAULT) {
        target = 0.0;
        du = (cut != 0u && (plaus_bits & MRS_PLAUS_FAULT) != 0u) ? c->du_max : c->fault_fade_step;
    } else if (why == MRS_AUTH_TIME) {
        target = 0.0;
        du = c->fade_step;
    } else {
        target = magnitude_bound(c, s, u_request);
        du = c->du_max;
    }
    u = s->u + rate_bound(c, s, target - s->u, du);
    intervention_window(c, s, u, u_request);
    s->u = u;
    return u;
}
