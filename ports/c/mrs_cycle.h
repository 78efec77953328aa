/*
 * mrsteer one control cycle: C99 port of firmware_py/cycle.py, bit for bit in double precision.
 *
 * The scheduling contract's order within one control period (docs/porting.md): the plausibility
 * monitor (mrs_monitor.h) over the yaw-rate samples since the last period, the law (mrs_step,
 * mrs_controller.h) with the monitor's suspicion of the yaw rate holding its command, and the
 * authority limiter with the monitor's cut and fade.  As its pieces: mrs_cycle_configure()
 * computes every coefficient once; mrs_cycle_reset() sets the power-on state; mrs_cycle_step()
 * is one control period of scalar arithmetic on the structs: no heap, no I/O, no clock.  What
 * the period's inputs are (which frames are fresh, how many yaw-rate samples came) is the
 * caller's: the node (mrs_node_core.c) reads them off the bus, mrs_replay off a file.
 */
#ifndef MRS_CYCLE_H
#define MRS_CYCLE_H

#include <stdint.h>

#include "mrs_controller.h"
#include "mrs_monitor.h"

/* The three pieces' coefficients, computed once (CycleCoefficients). */
typedef struct {
    mrs_coeffs_t law;
    mrs_monitor_coeffs_t monitor;
    mrs_authority_coeffs_t authority;
    /* the monitor's checks whose fault the limiter removes at its rate bound instead of fading:
     * MRS_CUT_CHECKS (the pairs) from mrs_cycle_configure; another mask only to weigh the design
     * against its options */
    uint16_t cut_checks;
} mrs_cycle_coeffs_t;

/* What one cycle leaves for the next (CycleState). */
typedef struct {
    mrs_state_t law;
    mrs_monitor_state_t monitor;
    mrs_authority_state_t authority;
    double command; /* the limited command of the last cycle (rad): what acts on the car now */
    uint8_t plausibility; /* the monitor's CtrlStatus_Plausibility bits, held between yaw-rate samples */
    unsigned reported; /* mrs_reported_state() of the last cycle (MRS_STATUS_*) */
} mrs_cycle_state_t;

/* One period's inputs (CycleInputs); NaN is an input that is not valid this period. The law
 * takes delta_driver, yaw_rate and speed as mrs_real_t; the monitor takes every one as double. */
typedef struct {
    double delta_driver; /* rad */
    double yaw_rate; /* rad/s */
    double speed; /* m/s */
    double lat_accel; /* m/s^2: the redundant sample (NaN: none fresh) */
    double delta_driver_redundant; /* rad: the second steering channel */
    double yaw_rate_redundant; /* rad/s: the yaw rate's second element */
    double speed_redundant; /* m/s: the second speed */
    int32_t monitor_steps; /* yaw-rate samples since the last period; 0 holds the monitor's bits */
    /* the driver's angle for the monitor's first step: the one that came with a redundant sample
     * not yet stepped over (a burst's newest angle is younger than it), else delta_driver */
    double monitor_driver;
    int starting; /* nonzero: the start state, some input not yet seen (mrs_reported_state) */
} mrs_cycle_inputs_t;

/* mrs_cycle_configure's refusals (0 on success). */
#define MRS_CYCLE_BAD_LAW (-1) /* mrs_configure refused the law's calibration */
#define MRS_CYCLE_BAD_GUARDS (-2) /* the monitor's or the limiter's configure refused its configuration */

/* The coefficients of the three pieces: 0, or MRS_CYCLE_BAD_LAW / MRS_CYCLE_BAD_GUARDS for an
 * impossible configuration (c is then not usable). */
int mrs_cycle_configure(const mrs_config_t *law, const mrs_monitor_config_t *monitor,
                        const mrs_authority_config_t *authority, mrs_cycle_coeffs_t *c);

/* Back to power-on: every state at rest, no command, no bits, INACTIVE. */
void mrs_cycle_reset(mrs_cycle_state_t *s);

/* One control period: the limited command to send (also s->command); s->plausibility,
 * s->reported and s->law.status / fault_flags say what happened. */
double mrs_cycle_step(const mrs_cycle_coeffs_t *c, mrs_cycle_state_t *s, const mrs_cycle_inputs_t *in);

#endif
