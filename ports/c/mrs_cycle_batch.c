/* Control cycles of many rows: see mrs_cycle_batch.h. */
#include "mrs_cycle_batch.h"

void mrs_cycle_batch_reset(int32_t n, mrs_cycle_state_t *states)
{
    int32_t i;
    for (i = 0; i < n; ++i) {
        mrs_cycle_reset(&states[i]);
    }
}

void mrs_cycle_batch(int32_t n, const mrs_cycle_coeffs_t *c, mrs_cycle_state_t *states,
                     const mrs_cycle_batch_inputs_t *in, const mrs_cycle_batch_outputs_t *out)
{
    int32_t i;
    mrs_cycle_inputs_t row;
    mrs_cycle_state_t *s;
    for (i = 0; i < n; ++i) {
        row.delta_driver = in->delta_driver[i];
        row.yaw_rate = in->yaw_rate[i];
        row.speed = in->speed[i];
        row.lat_accel = in->lat_accel[i];
        row.delta_driver_redundant = in->delta_driver_redundant[i];
        row.yaw_rate_redundant = in->yaw_rate_redundant[i];
        row.speed_redundant = in->speed_redundant[i];
        row.monitor_driver = in->monitor_driver[i];
        row.monitor_steps = in->monitor_steps[i];
        row.starting = (int)in->starting[i];
        s = &states[i];
        out->command[i] = mrs_cycle_step(c, s, &row);
        out->plausibility[i] = s->plausibility;
        out->reported[i] = (uint8_t)s->reported;
        out->status[i] = s->law.status;
        out->monitor_flags[i] = s->monitor.flags;
        out->authority_flags[i] = s->authority.flags;
    }
}

void mrs_authority_batch_reset(int32_t n, mrs_authority_state_t *states)
{
    int32_t i;
    for (i = 0; i < n; ++i) {
        mrs_authority_reset(&states[i]);
    }
}

void mrs_authority_batch(int32_t n, const mrs_authority_coeffs_t *c, mrs_authority_state_t *states,
                         const double *u_request, const uint8_t *plaus_bits, double *u)
{
    int32_t i;
    for (i = 0; i < n; ++i) {
        u[i] = mrs_authority_step(c, &states[i], u_request[i], plaus_bits[i], 0u, 0u);
    }
}
