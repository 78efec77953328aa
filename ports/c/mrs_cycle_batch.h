/*
 * mrsteer control cycles of many rows: one period of mrs_cycle_step() for each of n independent
 * controllers sharing one set of coefficients (the campaign engine's batches, sim_plant/campaign,
 * loaded with cffi), and one period of the actuator's own authority limiter for each of n
 * actuators.  A plain loop over rows: no heap, no I/O, no clock; each row is exactly the scalar
 * cycle, bit for bit.  The inputs and outputs are struct of arrays, one array of n per field.
 */
#ifndef MRS_CYCLE_BATCH_H
#define MRS_CYCLE_BATCH_H

#include <stdint.h>

#include "mrs_cycle.h"

/* One period's inputs of n rows (mrs_cycle_inputs_t's fields, one array each). */
typedef struct {
    const double *delta_driver;
    const double *yaw_rate;
    const double *speed;
    const double *lat_accel;
    const double *delta_driver_redundant;
    const double *yaw_rate_redundant;
    const double *speed_redundant;
    const double *monitor_driver;
    const int32_t *monitor_steps;
    const uint8_t *starting;
} mrs_cycle_batch_inputs_t;

/* What one period leaves per row: the limited command (s->command), the plausibility bits, the
 * reported state, the law's status, the monitor's detailed flags and the limiter's flags. */
typedef struct {
    double *command;
    uint8_t *plausibility;
    uint8_t *reported;
    uint8_t *status;
    uint16_t *monitor_flags;
    uint8_t *authority_flags;
} mrs_cycle_batch_outputs_t;

/* Every row's state back to power-on (mrs_cycle_reset). */
void mrs_cycle_batch_reset(int32_t n, mrs_cycle_state_t *states);

/* One control period of rows 0..n-1: mrs_cycle_step(c, &states[i], row i of in), row i of out. */
void mrs_cycle_batch(int32_t n, const mrs_cycle_coeffs_t *c, mrs_cycle_state_t *states,
                     const mrs_cycle_batch_inputs_t *in, const mrs_cycle_batch_outputs_t *out);

/* Every limiter's state back to rest (mrs_authority_reset). */
void mrs_authority_batch_reset(int32_t n, mrs_authority_state_t *states);

/* One period of n authority limiters without cut or fade (an actuator's own, on the last status
 * frame's plausibility bits): u[i] = mrs_authority_step(c, &states[i], u_request[i], plaus_bits[i], 0, 0). */
void mrs_authority_batch(int32_t n, const mrs_authority_coeffs_t *c, mrs_authority_state_t *states,
                         const double *u_request, const uint8_t *plaus_bits, double *u);

#endif
