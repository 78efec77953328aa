/* mrsteer model regulator, C99 reference port. Line-for-line the Python firmware
 * (firmware_py/model_regulator.py); the order of operations is kept so that the float64 build
 * reproduces the golden vectors to the last bit on IEEE-754 hardware without FMA contraction. */
#include "mrs_controller.h"

#include <math.h> /* exp(), tan(), sqrt() in mrs_configure only; isfinite and INFINITY are macros */

#include "mrs_defaults.h"
#include "mrs_monitor.h" /* MRS_PLAUS_* for mrs_reported_state */

void mrs_default_config(mrs_config_t *cfg)
{
    /* firmware_py/calibration.py's ControllerConfig(): the shipped law and the nominal car, from
     * mrs_defaults.h (generated from it); the schedule's unused rows are zero. */
    static const double v[] = MRS_CONTROLLER_DEFAULT_SCHEDULE_SPEED;
    static const double k[] = MRS_CONTROLLER_DEFAULT_SCHEDULE_K;
    static const double tau[] = MRS_CONTROLLER_DEFAULT_SCHEDULE_TAU;
    static const double tau_n[] = MRS_CONTROLLER_DEFAULT_SCHEDULE_TAU_N;
    const int n = MRS_CONTROLLER_DEFAULT_N_SCHEDULE;
    int i;
    cfg->q_form = MRS_CONTROLLER_DEFAULT_Q_FORM;
    cfg->k = 0.0; /* unused: scheduled */
    cfg->tau = 0.0;
    cfg->tau_n = 0.0;
    cfg->n_schedule = n;
    for (i = 0; i < MRS_MAX_SCHEDULE; ++i) {
        cfg->schedule_speed[i] = (i < n) ? v[i] : 0.0;
        cfg->schedule_k[i] = (i < n) ? k[i] : 0.0;
        cfg->schedule_tau[i] = (i < n) ? tau[i] : 0.0;
        cfg->schedule_tau_n[i] = (i < n) ? tau_n[i] : 0.0;
    }
    cfg->model_actuator_tau = MRS_CONTROLLER_DEFAULT_MODEL_ACTUATOR_TAU;
    cfg->model_filter_hz = MRS_CONTROLLER_DEFAULT_MODEL_FILTER_HZ;
    cfg->ts = MRS_CONTROLLER_DEFAULT_TS;
    cfg->method = MRS_CONTROLLER_DEFAULT_METHOD;
    cfg->aux_limit = MRS_CONTROLLER_DEFAULT_AUX_LIMIT;
    cfg->rate_limit = MRS_CONTROLLER_DEFAULT_RATE_LIMIT;
    cfg->fade_rate = MRS_CONTROLLER_DEFAULT_FADE_RATE;
    cfg->model_delay_steps = MRS_CONTROLLER_DEFAULT_MODEL_DELAY_STEPS;
    cfg->speed_active_min = MRS_CONTROLLER_DEFAULT_SPEED_ACTIVE_MIN;
    cfg->speed_max = MRS_CONTROLLER_DEFAULT_SPEED_MAX;
    cfg->driver_angle_max = MRS_CONTROLLER_DEFAULT_DRIVER_ANGLE_MAX;
    cfg->yaw_rate_max = MRS_CONTROLLER_DEFAULT_YAW_RATE_MAX;
    cfg->nominal_l_f = MRS_CONTROLLER_DEFAULT_NOMINAL_L_F;
    cfg->nominal_l_r = MRS_CONTROLLER_DEFAULT_NOMINAL_L_R;
    cfg->nominal_mass = MRS_CONTROLLER_DEFAULT_NOMINAL_MASS;
    cfg->nominal_c_f = MRS_CONTROLLER_DEFAULT_NOMINAL_C_F;
    cfg->nominal_c_r = MRS_CONTROLLER_DEFAULT_NOMINAL_C_R;
}

static int all_finite(const double *v, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        if (!isfinite(v[i])) {
            return 0;
        }
    }
    return 1;
}

/* Breakpoint i of the schedule: speed and gains finite and positive, the speed above the last. */
static int valid_breakpoint(const mrs_config_t *g, int i)
{
    const double p[4] = {g->schedule_speed[i], g->schedule_k[i], g->schedule_tau[i], g->schedule_tau_n[i]};
    return all_finite(p, 4) && p[0] > 0.0 && p[1] > 0.0 && p[2] > 0.0 && p[3] > 0.0 &&
           !(i > 0 && !(p[0] > g->schedule_speed[i - 1]));
}

/* The gains (calibration.py _validate_gains): constant K, tau, tau_n finite and positive, or
 * every breakpoint's, the speeds ascending. */
static int valid_gains(const mrs_config_t *g)
{
    const int n = g->n_schedule;
    int i;
    if (n == 0 && !(isfinite(g->k) && isfinite(g->tau) && isfinite(g->tau_n) && g->k > 0.0 && g->tau > 0.0 &&
                    g->tau_n > 0.0)) {
        return 0;
    }
    for (i = 0; i < n; ++i) {
        if (!valid_breakpoint(g, i)) {
            return 0;
        }
    }
    return 1;
}

/* The positive fields (calibration.py _POSITIVE). */
static int valid_positive(const mrs_config_t *g)
{
    return g->ts > 0.0 && g->aux_limit > 0.0 && g->fade_rate > 0.0 && g->speed_active_min > 0.0 &&
           g->speed_max > 0.0 && g->driver_angle_max > 0.0 && g->yaw_rate_max > 0.0 && g->nominal_l_f > 0.0 &&
           g->nominal_l_r > 0.0 && g->nominal_mass > 0.0 && g->nominal_c_f > 0.0 && g->nominal_c_r > 0.0;
}

/* The law's internal model (calibration.py _validate_model): its delay, actuator lag, sensor
 * filter and rate limit. */
static int valid_model(const mrs_config_t *g)
{
    const int extended = (g->n_schedule > 0) || (g->model_actuator_tau > 0.0) || (g->model_filter_hz > 0.0);
    return !(g->rate_limit < 0.0 || g->model_actuator_tau < 0.0 || g->model_filter_hz < 0.0 ||
             g->model_filter_hz >= 0.5 / g->ts || g->model_delay_steps < 0 ||
             g->model_delay_steps > MRS_MAX_MODEL_DELAY || (extended && g->model_delay_steps == 0));
}

/* The calibration's checks, as firmware_py/calibration.py validate() makes them. */
static int valid(const mrs_config_t *g)
{
    const double v[] = {g->ts, g->aux_limit, g->rate_limit, g->fade_rate, g->model_actuator_tau,
                        g->model_filter_hz, g->speed_active_min, g->speed_max, g->driver_angle_max,
                        g->yaw_rate_max, g->nominal_l_f, g->nominal_l_r, g->nominal_mass, g->nominal_c_f,
                        g->nominal_c_r};
    if ((g->q_form != MRS_Q_LIMITED && g->q_form != MRS_Q_STANDARD) ||
        (g->method != MRS_TUSTIN && g->method != MRS_ZOH) || !all_finite(v, (int)(sizeof v / sizeof v[0])) ||
        g->n_schedule < 0 || g->n_schedule > MRS_MAX_SCHEDULE) {
        return 0;
    }
    return valid_gains(g) && valid_positive(g) && valid_model(g) && g->speed_active_min < g->speed_max;
}

/* One breakpoint's coefficient set (a, g_w0, g_w1, g_r0, g_r1, q0) from K, tau, tau_n. */
static void law_coefficients(const mrs_config_t *g, double k, double tau, double tau_n, double out[6])
{
    /* Q(s) = q0 / (tau_Q s + 1): eq. (22) limited, eq. (17) standard */
    const double tau_q = tau / (1.0 + k);
    const double q0 = (g->q_form == MRS_Q_LIMITED) ? k / (1.0 + k) : 1.0;
    double a, bw0, bw1, br0, br1;
    if (g->method == MRS_TUSTIN) {
        const double den = 2.0 * tau_q + g->ts;
        a = (2.0 * tau_q - g->ts) / den;
        bw0 = g->ts / den;
        bw1 = bw0;
        br0 = (2.0 * tau_n + g->ts) / den;
        br1 = (g->ts - 2.0 * tau_n) / den;
    } else {
        const double cz = tau_n / tau_q;
        a = exp(-g->ts / tau_q);
        bw0 = 0.0;
        bw1 = 1.0 - a;
        br0 = cz;
        br1 = 1.0 - a - cz;
    }
    out[0] = a;
    out[1] = q0 * bw0;
    out[2] = q0 * bw1;
    out[3] = q0 * br0;
    out[4] = q0 * br1;
    out[5] = q0;
}

/* The nominal sensor filter: 2nd-order Butterworth, Tustin with the cut-off pre-warped
 * (scipy.signal.butter): b0, b1, b2, a1, a2; a pass-through without model_filter_hz. */
static void nominal_filter(const mrs_config_t *g, double flt[5])
{
    if (g->model_filter_hz > 0.0) {
        const double w = tan(3.141592653589793 * g->model_filter_hz * g->ts);
        const double nn = 1.0 / (1.0 + sqrt(2.0) * w + w * w);
        const double b0 = w * w * nn;
        flt[0] = b0;
        flt[1] = 2.0 * b0;
        flt[2] = b0;
        flt[3] = 2.0 * (w * w - 1.0) * nn;
        flt[4] = (1.0 - sqrt(2.0) * w + w * w) * nn;
    }
}

int mrs_configure(const mrs_config_t *g, mrs_coeffs_t *c)
{
    double wheelbase, k_us, act_a, g_w0_first = 0.0;
    double flt[5] = {1.0, 0.0, 0.0, 0.0, 0.0};
    int i;
    const int n = (g->n_schedule > 0) ? g->n_schedule : 1;
    if (!valid(g)) {
        return -1;
    }
    for (i = 0; i < MRS_MAX_SCHEDULE; ++i) {
        double p[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
        if (i < n) {
            if (g->n_schedule > 0) {
                law_coefficients(g, g->schedule_k[i], g->schedule_tau[i], g->schedule_tau_n[i], p);
            } else {
                law_coefficients(g, g->k, g->tau, g->tau_n, p);
            }
        }
        c->sched_v[i] = (mrs_real_t)((g->n_schedule > 0 && i < n) ? g->schedule_speed[i] : 0.0);
        c->sched_inv_dv[i] = (mrs_real_t)((i + 1 < n) ? 1.0 / (g->schedule_speed[i + 1] - g->schedule_speed[i])
                                                       : 0.0);
        c->sched_a[i] = (mrs_real_t)p[0];
        c->sched_g_w0[i] = (mrs_real_t)p[1];
        c->sched_g_w1[i] = (mrs_real_t)p[2];
        c->sched_g_r0[i] = (mrs_real_t)p[3];
        c->sched_g_r1[i] = (mrs_real_t)p[4];
        c->sched_q0[i] = (mrs_real_t)p[5];
        if (i == 0) {
            g_w0_first = p[1];
        }
    }
    c->n_sched = n;
    /* Nominal actuator: ZOH of 1/(tau_an s + 1) */
    act_a = (g->model_actuator_tau > 0.0) ? exp(-g->ts / g->model_actuator_tau) : 0.0;
    nominal_filter(g, flt);
    wheelbase = g->nominal_l_f + g->nominal_l_r;
    /* 1/K_n(v) = L/v + k_us v: eq. (15) inverted, nominal car at mu = 1 */
    k_us = (g->nominal_c_r * g->nominal_l_r - g->nominal_c_f * g->nominal_l_f) * g->nominal_mass /
           (g->nominal_c_f * g->nominal_c_r * wheelbase);

    c->inv_one_minus_g_w0 = (mrs_real_t)(1.0 / (1.0 - g_w0_first));
    c->model_delay = g->model_delay_steps;
    c->act_a = (mrs_real_t)act_a;
    c->act_b = (mrs_real_t)(1.0 - act_a);
    c->flt_b0 = (mrs_real_t)flt[0];
    c->flt_b1 = (mrs_real_t)flt[1];
    c->flt_b2 = (mrs_real_t)flt[2];
    c->flt_a1 = (mrs_real_t)flt[3];
    c->flt_a2 = (mrs_real_t)flt[4];
    c->wheelbase = (mrs_real_t)wheelbase;
    c->k_us = (mrs_real_t)k_us;
    c->u_max = (mrs_real_t)g->aux_limit;
    c->du_max = (g->rate_limit > 0.0) ? (mrs_real_t)(g->rate_limit * g->ts) : (mrs_real_t)INFINITY;
    c->fade_step = (mrs_real_t)(g->fade_rate * g->ts);
    c->speed_active_min = (mrs_real_t)g->speed_active_min;
    c->speed_max = (mrs_real_t)g->speed_max;
    c->driver_angle_max = (mrs_real_t)g->driver_angle_max;
    c->yaw_rate_max = (mrs_real_t)g->yaw_rate_max;
    return 0;
}

void mrs_init_state(mrs_state_t *s)
{
    int i;
    s->z = 0;
    s->u_prev = 0;
    for (i = 0; i < MRS_MAX_MODEL_DELAY; ++i) {
        s->u_hist[i] = 0;
    }
    s->hist_idx = 0u;
    s->p_n = 0;
    s->f_s1 = 0;
    s->f_s2 = 0;
    s->needs_init = 1u;
    s->recovering = 0u;
    s->status = MRS_STATUS_INACTIVE;
    s->fault_flags = 0u;
}

/* The law's units, in the order mrs_step() runs them, with model_regulator.py's names. */

/* The MRS_FAULT_* flags of the inputs out of range; written so that a NaN fails every
 * comparison: non-finite inputs are faults. */
static uint8_t input_faults(const mrs_coeffs_t *c, mrs_real_t delta_driver, mrs_real_t yaw_rate, mrs_real_t speed)
{
    uint8_t flags = 0u;
    if (!(-c->driver_angle_max <= delta_driver && delta_driver <= c->driver_angle_max)) {
        flags |= MRS_FAULT_DRIVER_ANGLE;
    }
    if (!(-c->yaw_rate_max <= yaw_rate && yaw_rate <= c->yaw_rate_max)) {
        flags |= MRS_FAULT_YAW_RATE;
    }
    if (!((mrs_real_t)0 <= speed && speed <= c->speed_max)) {
        flags |= MRS_FAULT_SPEED;
    }
    return flags;
}

/* Fault or too slow: inputs do not touch the state; fade to 0; re-initialise later. */
static mrs_real_t fade_out(const mrs_coeffs_t *c, mrs_state_t *s, uint8_t flags)
{
    mrs_real_t u = s->u_prev;
    if (u > c->fade_step) {
        u -= c->fade_step;
    } else if (u < -c->fade_step) {
        u += c->fade_step;
    } else {
        u = 0;
    }
    s->u_prev = u;
    s->status = (flags != 0u) ? MRS_STATUS_FAULT : MRS_STATUS_INACTIVE;
    s->needs_init = 1u;
    return u;
}

/* The speed strictly between the first and the last breakpoint: the gains interpolate. */
static int schedule_interior(const mrs_coeffs_t *c, mrs_real_t speed)
{
    const int n = c->n_sched;
    return n > 1 && c->sched_v[0] < speed && speed < c->sched_v[n - 1];
}

/* The last breakpoint at or below the speed (ascending); 0 below the first. */
static int schedule_index(const mrs_coeffs_t *c, mrs_real_t speed)
{
    int j = 0;
    const int n = c->n_sched;
    if (n > 1 && speed > c->sched_v[0]) {
        if (speed >= c->sched_v[n - 1]) {
            j = n - 1;
        } else {
            int i;
            for (i = 1; i < n - 1; ++i) {
                if (speed >= c->sched_v[i]) {
                    j = i;
                }
            }
        }
    }
    return j;
}

/* The breakpoint the gains interpolate toward: the next one inside the schedule, else j. */
static int schedule_upper(const mrs_coeffs_t *c, mrs_real_t speed, int j)
{
    return schedule_interior(c, speed) ? j + 1 : j;
}

/* How far the speed is from breakpoint j toward the next one: 0 outside the schedule. */
static mrs_real_t schedule_fraction(const mrs_coeffs_t *c, mrs_real_t speed, int j)
{
    return schedule_interior(c, speed) ? (speed - c->sched_v[j]) * c->sched_inv_dv[j] : (mrs_real_t)0;
}

/* The coefficient of table a fraction f of the way from breakpoint j to j1. */
static mrs_real_t interpolate(const mrs_real_t *table, int j, int j1, mrs_real_t f)
{
    return table[j] + f * (table[j1] - table[j]);
}

/* Every filter at its steady state for the present inputs with the command held. */
static void restart(const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver, mrs_real_t rho, mrs_real_t q0,
                    mrs_real_t g_w0, mrs_real_t g_r0)
{
    const mrs_real_t w0 = delta_driver + s->u_prev;
    int i;
    s->z = q0 * (w0 - rho) - (g_w0 * w0 - g_r0 * rho);
    for (i = 0; i < c->model_delay; ++i) {
        s->u_hist[i] = s->u_prev;
    }
    s->hist_idx = 0u;
    s->p_n = s->u_prev;
    s->f_s1 = (1 - c->flt_b0) * w0;
    s->f_s2 = (c->flt_b2 - c->flt_a2) * w0;
    s->needs_init = 0u;
    s->recovering = 1u;
}

/* The most the command may move this period: the rate limit, the fade step while it recovers. */
static mrs_real_t slew_step(const mrs_coeffs_t *c, const mrs_state_t *s)
{
    mrs_real_t du = c->du_max;
    if (s->recovering && c->fade_step < du) {
        du = c->fade_step;
    }
    return du;
}

/* The admissible window's lower end: the actuator's range intersected with the slew window; on
 * hold (lo <= u_prev already) it keeps u_prev and 0's side of it. */
static mrs_real_t window_low(const mrs_coeffs_t *c, const mrs_state_t *s, mrs_real_t lo_slew, uint8_t hold)
{
    mrs_real_t lo = lo_slew;
    if (lo < -c->u_max) {
        lo = -c->u_max;
    }
    if (hold != 0u) {
        if (s->u_prev > (mrs_real_t)0) {
            lo = lo > (mrs_real_t)0 ? lo : (mrs_real_t)0;
        } else {
            lo = s->u_prev > lo ? s->u_prev : lo;
        }
    }
    return lo;
}

/* The admissible window's upper end (as window_low). */
static mrs_real_t window_high(const mrs_coeffs_t *c, const mrs_state_t *s, mrs_real_t hi_slew, uint8_t hold)
{
    mrs_real_t hi = hi_slew;
    if (hi > c->u_max) {
        hi = c->u_max;
    }
    if (hold != 0u) {
        if (s->u_prev > (mrs_real_t)0) {
            hi = s->u_prev < hi ? s->u_prev : hi;
        } else {
            hi = hi < (mrs_real_t)0 ? hi : (mrs_real_t)0;
        }
    }
    return hi;
}

/* u within [lo, hi]. */
static mrs_real_t clamp(mrs_real_t u, mrs_real_t lo, mrs_real_t hi)
{
    return (u < lo) ? lo : ((u > hi) ? hi : u);
}

/* Tustin's algebraic loop of the constant law, solved exactly: u = clamp(p / (1 - g_w0), lo, hi). */
static mrs_real_t constant_law(const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver, mrs_real_t rho,
                               mrs_real_t a, mrs_real_t g_w0, mrs_real_t g_w1, mrs_real_t g_r0, mrs_real_t g_r1,
                               mrs_real_t lo, mrs_real_t hi)
{
    const mrs_real_t p = g_w0 * delta_driver - g_r0 * rho + s->z;
    const mrs_real_t u = clamp(p * c->inv_one_minus_g_w0, lo, hi);
    const mrs_real_t y = p + g_w0 * u;
    const mrs_real_t w = delta_driver + u;
    s->z = g_w1 * w - g_r1 * rho + a * y;
    return u;
}

/* The yaw rate measured now answers the command issued M steps ago, through the actuator and
 * the sensor filter: the nominal model's answer to that command (no algebraic loop). */
static mrs_real_t delayed_law(const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver, mrs_real_t rho,
                              mrs_real_t a, mrs_real_t g_w0, mrs_real_t g_w1, mrs_real_t g_r0, mrs_real_t g_r1,
                              mrs_real_t lo, mrs_real_t hi)
{
    uint8_t i = s->hist_idx;
    mrs_real_t x, w, y, u;
    s->p_n = c->act_a * s->p_n + c->act_b * s->u_hist[i];
    x = delta_driver + s->p_n;
    w = c->flt_b0 * x + s->f_s1;
    s->f_s1 = c->flt_b1 * x - c->flt_a1 * w + s->f_s2;
    s->f_s2 = c->flt_b2 * x - c->flt_a2 * w;
    y = g_w0 * w - g_r0 * rho + s->z;
    u = clamp(y, lo, hi);
    s->u_hist[i] = u;
    ++i;
    if (i >= (uint8_t)c->model_delay) {
        i = 0u;
    }
    s->hist_idx = i;
    s->z = g_w1 * w - g_r1 * rho + a * y;
    return u;
}

mrs_real_t mrs_step(const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver, mrs_real_t yaw_rate,
                    mrs_real_t speed, uint8_t hold)
{
    const uint8_t flags = input_faults(c, delta_driver, yaw_rate, speed);
    mrs_real_t u, inv_kn, rho, du, lo_slew, hi_slew, lo, hi, f, a, g_w0, g_w1, g_r0, g_r1;
    int j, j1;
    s->fault_flags = flags;
    if (flags != 0u || speed < c->speed_active_min) {
        return fade_out(c, s, flags);
    }
    inv_kn = c->wheelbase / speed + c->k_us * speed;
    rho = inv_kn * yaw_rate; /* the yaw rate as the wheel angle the nominal car needs for it */
    /* The coefficient set at this speed: linear between breakpoints, held outside them. */
    j = schedule_index(c, speed);
    j1 = schedule_upper(c, speed, j);
    f = schedule_fraction(c, speed, j);
    a = interpolate(c->sched_a, j, j1, f);
    g_w0 = interpolate(c->sched_g_w0, j, j1, f);
    g_w1 = interpolate(c->sched_g_w1, j, j1, f);
    g_r0 = interpolate(c->sched_g_r0, j, j1, f);
    g_r1 = interpolate(c->sched_g_r1, j, j1, f);
    if (s->needs_init) {
        restart(c, s, delta_driver, rho, interpolate(c->sched_q0, j, j1, f), g_w0, g_r0);
    }
    /* Admissible window: actuator range intersected with the slew window. */
    du = slew_step(c, s);
    lo_slew = s->u_prev - du;
    hi_slew = s->u_prev + du;
    lo = window_low(c, s, lo_slew, hold);
    hi = window_high(c, s, hi_slew, hold);
    if (c->model_delay == 0) {
        u = constant_law(c, s, delta_driver, rho, a, g_w0, g_w1, g_r0, g_r1, lo, hi);
    } else {
        u = delayed_law(c, s, delta_driver, rho, a, g_w0, g_w1, g_r0, g_r1, lo, hi);
    }
    if (s->recovering && hold == 0u && lo_slew < u && u < hi_slew) {
        s->recovering = 0u;
    }
    s->u_prev = u;
    s->status = (u >= c->u_max || u <= -c->u_max) ? MRS_STATUS_SATURATED : MRS_STATUS_ACTIVE;
    return u;
}

unsigned mrs_reported_state(unsigned status, unsigned plausibility, int starting)
{
    unsigned state = status; /* mrs_step()'s INACTIVE, ACTIVE or SATURATED unless below */
    if ((plausibility & MRS_PLAUS_FAULT) != 0u) {
        state = MRS_STATUS_FAULT;
    } else if (starting != 0) {
        state = MRS_STATUS_STARTING;
    } else if (status == MRS_STATUS_FAULT) {
        state = MRS_STATUS_FAULT;
    } else if ((plausibility & MRS_PLAUS_DEGRADED) != 0u) {
        state = MRS_STATUS_DEGRADED;
    } else {
        /* step()'s status stands */
    }
    return state;
}
