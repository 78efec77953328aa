/* mrsteer model regulator, C99 reference port. Line-for-line the Python firmware
 * (firmware_py/model_regulator.py); the order of operations is kept so that the float64 build
 * reproduces the golden vectors to the last bit on IEEE-754 hardware without FMA contraction. */
#include "mrs_controller.h"

#include <math.h> /* exp() in mrs_configure only (ZOH); isfinite and INFINITY are macros */

void mrs_default_config(mrs_config_t *cfg)
{
    cfg->q_form = MRS_Q_LIMITED;
    cfg->k = 43.0;
    cfg->tau = 0.0212;
    cfg->tau_n = 0.02;
    cfg->ts = 0.002;
    cfg->method = MRS_TUSTIN;
    cfg->aux_limit = 0.05235987755982989; /* 3 deg */
    cfg->rate_limit = 0.0;
    cfg->fade_rate = 0.10471975511965978; /* 6 deg/s */
    cfg->model_delay_steps = 1;
    cfg->speed_active_min = 3.0;
    cfg->speed_max = 70.0;
    cfg->driver_angle_max = 0.7;
    cfg->yaw_rate_max = 3.0;
    cfg->nominal_l_f = 1.25;
    cfg->nominal_l_r = 1.32;
    cfg->nominal_mass = 1296.0;
    cfg->nominal_c_f = 84000.0;
    cfg->nominal_c_r = 96000.0;
}

static int all_finite(const mrs_config_t *g)
{
    const double v[] = {g->k, g->tau, g->tau_n, g->ts, g->aux_limit, g->rate_limit, g->fade_rate,
                        g->speed_active_min, g->speed_max, g->driver_angle_max, g->yaw_rate_max,
                        g->nominal_l_f, g->nominal_l_r, g->nominal_mass, g->nominal_c_f, g->nominal_c_r};
    unsigned i;
    for (i = 0u; i < sizeof v / sizeof v[0]; ++i) {
        if (!isfinite(v[i])) {
            return 0;
        }
    }
    return 1;
}

int mrs_configure(const mrs_config_t *g, mrs_coeffs_t *c)
{
    double q0, tau_q, a, bw0, bw1, br0, br1, g_w0, wheelbase, k_us;

    if ((g->q_form != MRS_Q_LIMITED && g->q_form != MRS_Q_STANDARD) ||
        (g->method != MRS_TUSTIN && g->method != MRS_ZOH) || !all_finite(g)) {
        return -1;
    }
    if (!(g->k > 0.0 && g->tau > 0.0 && g->tau_n > 0.0 && g->ts > 0.0 && g->aux_limit > 0.0 &&
          g->fade_rate > 0.0 && g->speed_active_min > 0.0 && g->speed_max > 0.0 && g->driver_angle_max > 0.0 &&
          g->yaw_rate_max > 0.0 && g->nominal_l_f > 0.0 && g->nominal_l_r > 0.0 && g->nominal_mass > 0.0 &&
          g->nominal_c_f > 0.0 && g->nominal_c_r > 0.0) ||
        g->rate_limit < 0.0 || g->model_delay_steps < 0 || g->model_delay_steps > MRS_MAX_MODEL_DELAY ||
        g->speed_active_min >= g->speed_max) {
        return -1;
    }

    /* Q(s) = q0 / (tau_Q s + 1): eq. (22) limited, eq. (17) standard */
    tau_q = g->tau / (1.0 + g->k);
    q0 = (g->q_form == MRS_Q_LIMITED) ? g->k / (1.0 + g->k) : 1.0;
    if (g->method == MRS_TUSTIN) {
        const double den = 2.0 * tau_q + g->ts;
        a = (2.0 * tau_q - g->ts) / den;
        bw0 = g->ts / den;
        bw1 = bw0;
        br0 = (2.0 * g->tau_n + g->ts) / den;
        br1 = (g->ts - 2.0 * g->tau_n) / den;
    } else {
        const double cz = g->tau_n / tau_q;
        a = exp(-g->ts / tau_q);
        bw0 = 0.0;
        bw1 = 1.0 - a;
        br0 = cz;
        br1 = 1.0 - a - cz;
    }
    g_w0 = q0 * bw0;
    wheelbase = g->nominal_l_f + g->nominal_l_r;
    /* 1/K_n(v) = L/v + k_us v: eq. (15) inverted, nominal car at mu = 1 */
    k_us = (g->nominal_c_r * g->nominal_l_r - g->nominal_c_f * g->nominal_l_f) * g->nominal_mass /
           (g->nominal_c_f * g->nominal_c_r * wheelbase);

    c->a = (mrs_real_t)a;
    c->g_w0 = (mrs_real_t)g_w0;
    c->g_w1 = (mrs_real_t)(q0 * bw1);
    c->g_r0 = (mrs_real_t)(q0 * br0);
    c->g_r1 = (mrs_real_t)(q0 * br1);
    c->q0 = (mrs_real_t)q0;
    c->inv_one_minus_g_w0 = (mrs_real_t)(1.0 / (1.0 - g_w0));
    c->model_delay = g->model_delay_steps;
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
    s->needs_init = 1u;
    s->recovering = 0u;
    s->status = MRS_STATUS_INACTIVE;
    s->fault_flags = 0u;
}

mrs_real_t mrs_step(const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver, mrs_real_t yaw_rate,
                    mrs_real_t speed)
{
    uint8_t flags = 0u;
    mrs_real_t u, inv_kn, rho, du, lo_slew, hi_slew, lo, hi, w, y;

    /* Written so that a NaN fails every comparison: non-finite inputs are faults. */
    if (!(-c->driver_angle_max <= delta_driver && delta_driver <= c->driver_angle_max)) {
        flags |= MRS_FAULT_DRIVER_ANGLE;
    }
    if (!(-c->yaw_rate_max <= yaw_rate && yaw_rate <= c->yaw_rate_max)) {
        flags |= MRS_FAULT_YAW_RATE;
    }
    if (!((mrs_real_t)0 <= speed && speed <= c->speed_max)) {
        flags |= MRS_FAULT_SPEED;
    }
    s->fault_flags = flags;

    if (flags != 0u || speed < c->speed_active_min) {
        /* Fault or too slow: inputs do not touch the state; fade to 0; re-initialise later. */
        u = s->u_prev;
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

    inv_kn = c->wheelbase / speed + c->k_us * speed;
    rho = inv_kn * yaw_rate;

    if (s->needs_init) {
        /* Filter at its steady state for the present inputs with the command held. */
        const mrs_real_t w0 = delta_driver + s->u_prev;
        int i;
        s->z = c->q0 * (w0 - rho) - (c->g_w0 * w0 - c->g_r0 * rho);
        for (i = 0; i < c->model_delay; ++i) {
            s->u_hist[i] = s->u_prev;
        }
        s->hist_idx = 0u;
        s->needs_init = 0u;
        s->recovering = 1u;
    }

    /* Admissible window: actuator range intersected with the slew window. */
    du = c->du_max;
    if (s->recovering && c->fade_step < du) {
        du = c->fade_step;
    }
    lo_slew = s->u_prev - du;
    hi_slew = s->u_prev + du;
    lo = lo_slew;
    hi = hi_slew;
    if (lo < -c->u_max) {
        lo = -c->u_max;
    }
    if (hi > c->u_max) {
        hi = c->u_max;
    }

    if (c->model_delay == 0) {
        /* Tustin's algebraic loop, solved exactly: u = clamp(p / (1 - g_w0), lo, hi). */
        const mrs_real_t p = c->g_w0 * delta_driver - c->g_r0 * rho + s->z;
        u = p * c->inv_one_minus_g_w0;
        if (u < lo) {
            u = lo;
        } else if (u > hi) {
            u = hi;
        }
        y = p + c->g_w0 * u;
        w = delta_driver + u;
    } else {
        /* The yaw rate measured now answers the command issued M steps ago. */
        uint8_t i = s->hist_idx;
        w = delta_driver + s->u_hist[i];
        y = c->g_w0 * w - c->g_r0 * rho + s->z;
        u = y;
        if (u < lo) {
            u = lo;
        } else if (u > hi) {
            u = hi;
        }
        s->u_hist[i] = u;
        ++i;
        if (i >= (uint8_t)c->model_delay) {
            i = 0u;
        }
        s->hist_idx = i;
    }

    s->z = c->g_w1 * w - c->g_r1 * rho + c->a * y;
    if (s->recovering && lo_slew < u && u < hi_slew) {
        s->recovering = 0u;
    }
    s->u_prev = u;
    s->status = (u >= c->u_max || u <= -c->u_max) ? MRS_STATUS_SATURATED : MRS_STATUS_ACTIVE;
    return u;
}
