/*
 * mrsteer plausibility monitor and bounded authority: C99 port of firmware_py/plausibility.py,
 * bit for bit in double precision (tests/test_c_monitor.py replays the Python module's runs).
 *
 * As mrs_controller: mrs_monitor_configure() computes every coefficient once (the only
 * divisions by calibration values and the only exp()); mrs_monitor_step() and
 * mrs_authority_step() are one control period of scalar arithmetic on the structs: no heap,
 * no recursion, no library call.  docs/controller.md, "Plausibility monitor", gives the
 * checks and thresholds; docs/decisions/0002-0008 the reasoning.
 */
#ifndef MRS_MONITOR_H
#define MRS_MONITOR_H

#include <stdint.h>

#include "mrs_defaults.h"

/* CtrlStatus_Plausibility bits (mrsteer.dbc). */
#define MRS_PLAUS_YAW 0x01u
#define MRS_PLAUS_STEER 0x02u
#define MRS_PLAUS_DEGRADED 0x04u
#define MRS_PLAUS_FAULT (MRS_PLAUS_YAW | MRS_PLAUS_STEER)

/* The detailed checks (mrs_monitor_state_t.flags). */
#define MRS_CHECK_KINEMATIC 0x01u
#define MRS_CHECK_MODEL 0x02u
#define MRS_CHECK_STEER_PAIR 0x04u
#define MRS_FROZEN_YAW 0x08u
#define MRS_FROZEN_LAT 0x10u
#define MRS_FROZEN_STEER 0x20u
#define MRS_FROZEN_STEER_2 0x40u
#define MRS_MISSING 0x80u
#define MRS_CHECK_YAW_PAIR 0x100u
#define MRS_CHECK_SPEED 0x200u /* the speed jumped between two values by more than speed_step */
#define MRS_CHECK_TURN 0x400u /* the speed disagrees with a_y / r in a steady turn */
/* the yaw-rate pair's latest sample over yaw_pair_hold, not confirmed (not latched): the node
 * passes it (MRS_SUSPECT_CHECKS) as mrs_step's hold, on which the law's command may shrink but
 * not grow */
#define MRS_SUSPECT_YAW_PAIR 0x800u
#define MRS_CHECK_SPEED_PAIR 0x1000u /* the speed disagrees with the second speed */
/* the driver's angle moved by more than steer_jump in one sample since the last redundant
 * sample (not latched): held as MRS_SUSPECT_YAW_PAIR until the steering pair judges it */
#define MRS_SUSPECT_STEER_JUMP 0x2000u
/* the kinematic or the model check tripped while the yaw rate's second element confirmed it
 * (latched): a_y or the car (past its grip) disagrees, not the yaw rate; MRS_PLAUS_DEGRADED, and
 * the node fades the command as on a fault (mrs_authority_step's fade) */
#define MRS_OUTSIDE_MODEL 0x4000u
/* The suspicions: the node passes (flags & MRS_SUSPECT_CHECKS) != 0 as mrs_step's hold. */
#define MRS_SUSPECT_CHECKS (MRS_SUSPECT_YAW_PAIR | MRS_SUSPECT_STEER_JUMP)
/* The pair checks: the node passes (flags & MRS_CUT_CHECKS) != 0 as mrs_authority_step's cut. */
#define MRS_CUT_CHECKS (MRS_CHECK_YAW_PAIR | MRS_CHECK_STEER_PAIR | MRS_CHECK_SPEED | MRS_CHECK_SPEED_PAIR)
/* The node passes (flags & MRS_FADE_CHECKS) != 0 as mrs_authority_step's fade. */
#define MRS_FADE_CHECKS MRS_OUTSIDE_MODEL
#define MRS_YAW_CHECKS (MRS_CHECK_KINEMATIC | MRS_CHECK_MODEL | MRS_FROZEN_YAW | MRS_FROZEN_LAT | MRS_CHECK_YAW_PAIR | \
                        MRS_CHECK_SPEED | MRS_CHECK_TURN | MRS_CHECK_SPEED_PAIR)
#define MRS_STEER_CHECKS (MRS_CHECK_STEER_PAIR | MRS_FROZEN_STEER | MRS_FROZEN_STEER_2)
/* The degraded states: a redundant input missing, or the car outside the model. */
#define MRS_DEGRADED_CHECKS (MRS_MISSING | MRS_OUTSIDE_MODEL)

/* MRS_KIN_WINDOW, MRS_YAW_PAIR_WINDOW, MRS_TURN_BLOCK (redundant samples in one block of the
 * steady-turn speed check): the windows' sizes, in mrs_defaults.h */

/* Authority limiter flags. */
#define MRS_AUTH_MAGNITUDE 0x01u
#define MRS_AUTH_RATE 0x02u
#define MRS_AUTH_TIME 0x04u
#define MRS_AUTH_FAULT 0x08u

typedef struct {
    double ts, speed_min, yaw_bound, yaw_rel;
    int yaw_count;
    double yaw_raw_fraction;
    double steer_bound;
    int steer_count;
    double model_margin, model_rel, model_tau, model_time, frozen_time, frozen_move_yaw, frozen_move_steer;
    double nominal_l_f, nominal_l_r, nominal_mass, nominal_c_f, nominal_c_r;
    double kin_gap; /* s without a usable redundant sample before the kinematic window restarts */
    double mu_min;  /* the kinematic check's family of nominal cars: every friction in [mu_min, 1] */
    double actuator_tau; /* the actuator's nominal lag behind the command sent, s */
    double yaw_pair_bound; /* |mean of r - r_2 over MRS_YAW_PAIR_WINDOW samples|, rad/s */
    double sensor_tau; /* the sensors' filters' lag on a_y and r, s: the kinematic check's wheel angle takes it */
    double side_accel; /* m/s^2 of a_y a side force may add: the kinematic bound widens by it / v while the yaw pair runs */
    double speed_step; /* m/s: the most the speed may change from one value to the next */
    /* the steady-turn speed check: |r| >= turn_yaw_min; r within turn_yaw_tol and a_y within
     * turn_lat_tol + turn_lat_rel |a_y| of the block's first sample; |v - a_y / r| against
     * turn_speed_rel v + (turn_yaw_bias v + turn_lat_bias) / |r| */
    double turn_yaw_min, turn_yaw_tol, turn_lat_tol, turn_lat_rel, turn_speed_rel, turn_yaw_bias, turn_lat_bias;
    double yaw_pair_hold; /* |r - r_2| of one sample over this, rad/s: the suspicion (<= yaw_pair_bound) */
    /* the speed pair: |v - v_2| over speed_pair_bound + speed_pair_rel min(v, v_2) (m/s) for
     * speed_pair_time (s) trips */
    double speed_pair_bound, speed_pair_rel, speed_pair_time;
    /* rad the driver's angle may move in one sample before the steering pair suspects it */
    double steer_jump;
    double mu_min_paired; /* the family's lowest friction while the yaw-rate pair runs */
    /* braking (the speed, lagged by speed_brake_tau s, falling at speed_brake_decel m/s^2 or more):
     * a second speed below the speed may be speed_slip_rel min(v, v_2) further off (wheel slip) */
    double speed_brake_decel, speed_brake_tau, speed_slip_rel;
} mrs_monitor_config_t;

typedef struct {
    double speed_min, yaw_bound, yaw_rel, inv_yaw_raw_fraction;
    int32_t yaw_count;
    double steer_bound, inv_steer_bound;
    int32_t steer_count;
    double model_margin, model_rel, model_alpha;
    int32_t model_steps, frozen_steps, kin_gap_steps;
    double frozen_move_yaw, frozen_move_steer, wheelbase, k_us, ts, inv_cs_m, moment_m, cf_m;
    double lat_span, aux_alpha; /* 1 / mu_min - 1; 1 - exp(-ts / actuator_tau) */
    double yaw_pair_bound, inv_yaw_pair_bound;
    double delta_alpha; /* 1 - exp(-ts / sensor_tau) */
    double side_accel, speed_step;
    double turn_yaw_min, turn_yaw_tol, turn_lat_tol, turn_lat_rel, turn_speed_rel, turn_yaw_bias, turn_lat_bias;
    double yaw_pair_hold;
    double speed_pair_bound, speed_pair_rel;
    int32_t speed_pair_steps;
    double steer_jump;
    double lat_span_paired; /* 1 / mu_min_paired - 1 */
    double speed_brake_alpha; /* 1 - exp(-ts / speed_brake_tau) */
    double speed_brake_lag; /* how far that lag stays above a speed falling at speed_brake_decel */
    double speed_slip_rel;
} mrs_monitor_coeffs_t;

typedef struct {
    uint8_t started, have_sample, yaw_ref_ok, st_ref_ok, bits;
    uint8_t yaw2_seen; /* the yaw-rate sensor's second element received since the reset */
    uint8_t speed_seen; /* speed_last holds a valid speed received since the speed was last invalid */
    uint8_t turn_settled; /* the steady-turn check's block before the current one was steady */
    uint8_t speed2_seen; /* the second speed received since the reset */
    uint16_t latched, flags;
    int32_t kin_count, pair_count, model_count, kin_idx, kin_n, since, yaw_pair_idx, yaw_pair_n;
    int32_t yaw_same, lat_same, st_same, st2_same;
    int32_t turn_n; /* samples in the steady-turn check's current block */
    int32_t yaw_hold_n; /* samples of this suspicion the command was held on (at most MRS_YAW_PAIR_WINDOW) */
    int32_t yaw_clear_n; /* samples in a row within yaw_pair_hold (MRS_YAW_PAIR_WINDOW of them re-arm the hold) */
    double lat_prev, steer2_prev, r_model, raw_prev, beta_prev, lat_beta_prev, aux_lag;
    double yaw_last, yaw_ref, lat_last, lat_ref, st_last, st_ref, st2_last, st2_ref;
    double kin_err, pair_err, model_err;
    double kin_raw[MRS_KIN_WINDOW], kin_comp[MRS_KIN_WINDOW], kin_lat[MRS_KIN_WINDOW];
    double yaw_pair[MRS_YAW_PAIR_WINDOW], yaw_pair_err;
    double delta_lag; /* the wheel angle through the sensors' lag */
    double lag_beta_prev, kin_sensor[MRS_KIN_WINDOW]; /* what that lag moves the nominal car's beta' */
    double speed_last;
    double speed_lag; /* the speed through speed_brake_tau's lag (since speed_seen) */
    double turn_r0, turn_a0, turn_res, turn_r, turn_err; /* the block's first r, a_y; sums of r v - a_y, r */
    int32_t speed_pair_count; /* the speed pair's up/down counter (trips at speed_pair_steps) */
    double speed_pair_err;
    double jump_prev; /* the driver's angle the sample before (for steer_jump) */
    uint8_t jump_ok; /* jump_prev holds one */
    int32_t steer_hold_n; /* samples the steering pair's suspicion still holds the command */
} mrs_monitor_state_t;

typedef struct {
    double ts, u_max, rate_max, fade_rate, fault_fade_rate, panic_window, engage, rearm_time;
} mrs_authority_config_t;

typedef struct {
    double u_max, du_max, fade_step, fault_fade_step;
    int32_t window_steps;
    double engage;
    int32_t rearm_steps;
} mrs_authority_coeffs_t;

typedef struct {
    double u;
    int32_t engaged, quiet;
    uint8_t flags;
} mrs_authority_state_t;

void mrs_monitor_default_config(mrs_monitor_config_t *cfg);
/* 0 on success, -1 if the calibration is invalid. */
int mrs_monitor_configure(const mrs_monitor_config_t *cfg, mrs_monitor_coeffs_t *c);
void mrs_monitor_reset(mrs_monitor_state_t *s);
/* One control period; returns the CtrlStatus_Plausibility bits. NaN marks a missing input;
 * a NaN yaw_rate_redundant pauses the yaw-rate pair check, and is DEGRADED once the element has
 * been received since the reset while yaw_rate is valid (a sender without it never sets it).
 * speed_redundant, the second speed, likewise for the speed pair (while speed is valid). */
uint8_t mrs_monitor_step(const mrs_monitor_coeffs_t *c, mrs_monitor_state_t *s, double delta_driver,
                         double delta_driver_redundant, double yaw_rate, double lat_accel, double speed,
                         double aux_cmd_applied, double yaw_rate_redundant, double speed_redundant);

void mrs_authority_default_config(mrs_authority_config_t *cfg);
int mrs_authority_configure(const mrs_authority_config_t *cfg, mrs_authority_coeffs_t *c);
void mrs_authority_reset(mrs_authority_state_t *s);
/* The command allowed this period for u_request (rad), given the monitor's bits; cut nonzero
 * with a fault (the monitor's MRS_CUT_CHECKS: a pair check) removes the command at rate_max, not
 * faded; fade nonzero (the monitor's MRS_FADE_CHECKS) fades it as a fault does. */
double mrs_authority_step(const mrs_authority_coeffs_t *c, mrs_authority_state_t *s, double u_request,
                          uint8_t plaus_bits, uint8_t cut, uint8_t fade);

#endif
