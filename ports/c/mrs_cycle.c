/* One control cycle: see mrs_cycle.h (firmware_py/cycle.py). */
#include "mrs_cycle.h"

int mrs_cycle_configure(const mrs_config_t *law, const mrs_monitor_config_t *monitor,
                        const mrs_authority_config_t *authority, mrs_cycle_coeffs_t *c)
{
    int result;
    if (mrs_configure(law, &c->law) != 0) {
        result = MRS_CYCLE_BAD_LAW;
    } else if ((mrs_monitor_configure(monitor, &c->monitor) != 0) ||
               (mrs_authority_configure(authority, &c->authority) != 0)) {
        result = MRS_CYCLE_BAD_GUARDS;
    } else {
        c->cut_checks = (uint16_t)MRS_CUT_CHECKS;
        result = 0;
    }
    return result;
}

void mrs_cycle_reset(mrs_cycle_state_t *s)
{
    mrs_init_state(&s->law);
    mrs_monitor_reset(&s->monitor);
    mrs_authority_reset(&s->authority);
    s->command = 0.0;
    s->plausibility = 0u;
    s->reported = MRS_STATUS_INACTIVE;
}

double mrs_cycle_step(const mrs_cycle_coeffs_t *c, mrs_cycle_state_t *s, const mrs_cycle_inputs_t *in)
{
    uint8_t bits = s->plausibility;
    double steer = in->monitor_driver;
    int32_t k;
    uint16_t flags;
    uint8_t hold;
    uint8_t cut;
    uint8_t fade;
    mrs_real_t u_law;
    double u;
    for (k = 0; k < in->monitor_steps; ++k) { /* a sample lost on the way is held at the newest values */
        bits = mrs_monitor_step(&c->monitor, &s->monitor, steer, in->delta_driver_redundant, in->yaw_rate,
                                in->lat_accel, in->speed, s->command, in->yaw_rate_redundant, in->speed_redundant);
        steer = in->delta_driver;
    }
    flags = s->monitor.flags;
    hold = ((flags & MRS_SUSPECT_CHECKS) != 0u) ? 1u : 0u;
    cut = ((flags & c->cut_checks) != 0u) ? 1u : 0u;
    fade = ((flags & MRS_FADE_CHECKS) != 0u) ? 1u : 0u;
    /* before the law: the monitor's suspicion of the yaw rate holds the law's command */
    u_law = mrs_step(&c->law, &s->law, (mrs_real_t)in->delta_driver, (mrs_real_t)in->yaw_rate,
                     (mrs_real_t)in->speed, hold);
    /* a pair check's fault (yaw rate or steering) is found while its command builds: removed at
     * the limiter's rate bound, not faded */
    u = mrs_authority_step(&c->authority, &s->authority, (double)u_law, bits, cut, fade);
    s->plausibility = bits;
    s->command = u;
    s->reported = mrs_reported_state((unsigned)s->law.status, (unsigned)bits, in->starting);
    return u;
}
