/*
 * mrsteer limited-integrator model regulator: C99 reference port of firmware_py/model_regulator.py.
 *
 * Split as generated embedded code is: mrs_configure() computes every coefficient once from the
 * calibration (the only place with divisions by calibration values, exp() or validation);
 * mrs_init_state() sets the power-on state; mrs_step() is one control period of scalar
 * arithmetic on the coefficient and state structs: no heap, no recursion, no library call.
 *
 * Build with -DMRS_FLOAT32 for single precision (mrs_real_t = float); the default is double.
 * docs/porting.md is the guide; tests/vectors/ holds the golden vectors.
 */
#ifndef MRS_CONTROLLER_H
#define MRS_CONTROLLER_H

#include <stdint.h>

#ifdef MRS_FLOAT32
typedef float mrs_real_t;
#else
typedef double mrs_real_t;
#endif

#include "mrs_defaults.h" /* MRS_MAX_MODEL_DELAY, MRS_MAX_SCHEDULE: the tables' sizes */

/* Status as sent on the bus (AuxSteerCmd_State, CtrlStatus_State; model_regulator.STATUS_*):
 * mrs_step() gives the first four, the node reports mrs_reported_state() of it. */
#define MRS_STATUS_INACTIVE 0u
#define MRS_STATUS_ACTIVE 1u
#define MRS_STATUS_SATURATED 2u
#define MRS_STATUS_FAULT 3u
#define MRS_STATUS_DEGRADED 4u
#define MRS_STATUS_STARTING 5u

/* Fault flags: which input was invalid. */
#define MRS_FAULT_DRIVER_ANGLE 0x01u
#define MRS_FAULT_YAW_RATE 0x02u
#define MRS_FAULT_SPEED 0x04u

typedef enum { MRS_Q_LIMITED = 0, MRS_Q_STANDARD = 1 } mrs_q_form_t;
typedef enum { MRS_TUSTIN = 0, MRS_ZOH = 1 } mrs_method_t;

/* Calibration (ControllerConfig). Angles in rad of front-wheel angle, times in s.
 * The gains are a speed schedule (n_schedule > 0 breakpoints) or, with n_schedule == 0, the
 * constant k, tau, tau_n (ignored when scheduled). model_actuator_tau and model_filter_hz put
 * the actuator lag and the yaw-rate low-pass into the nominal model (0: none). */
typedef struct {
    mrs_q_form_t q_form;
    double k, tau, tau_n;
    int n_schedule;
    double schedule_speed[MRS_MAX_SCHEDULE], schedule_k[MRS_MAX_SCHEDULE], schedule_tau[MRS_MAX_SCHEDULE],
        schedule_tau_n[MRS_MAX_SCHEDULE];
    double model_actuator_tau, model_filter_hz;
    double ts;
    mrs_method_t method;
    double aux_limit, rate_limit, fade_rate;
    int model_delay_steps;
    double speed_active_min, speed_max, driver_angle_max, yaw_rate_max;
    double nominal_l_f, nominal_l_r, nominal_mass, nominal_c_f, nominal_c_r;
} mrs_config_t;

/* Everything mrs_step() needs (Coefficients): the law's coefficient set per breakpoint, the
 * nominal actuator (act_*) and filter (flt_*), the limits. */
typedef struct {
    int n_sched;
    mrs_real_t sched_v[MRS_MAX_SCHEDULE], sched_inv_dv[MRS_MAX_SCHEDULE];
    mrs_real_t sched_a[MRS_MAX_SCHEDULE], sched_g_w0[MRS_MAX_SCHEDULE], sched_g_w1[MRS_MAX_SCHEDULE],
        sched_g_r0[MRS_MAX_SCHEDULE], sched_g_r1[MRS_MAX_SCHEDULE], sched_q0[MRS_MAX_SCHEDULE];
    mrs_real_t inv_one_minus_g_w0;
    int model_delay;
    mrs_real_t act_a, act_b, flt_b0, flt_b1, flt_b2, flt_a1, flt_a2;
    mrs_real_t wheelbase, k_us, u_max, du_max, fade_step;
    mrs_real_t speed_active_min, speed_max, driver_angle_max, yaw_rate_max;
} mrs_coeffs_t;

/* Preallocated state (State). */
typedef struct {
    mrs_real_t z, u_prev;
    mrs_real_t u_hist[MRS_MAX_MODEL_DELAY];
    mrs_real_t p_n, f_s1, f_s2;
    uint8_t hist_idx, needs_init, recovering, status, fault_flags;
} mrs_state_t;

/* The shipped calibration (500 Hz). */
void mrs_default_config(mrs_config_t *cfg);

/* Validate the calibration and fill the coefficients; 0 on success, -1 if it is invalid. */
int mrs_configure(const mrs_config_t *cfg, mrs_coeffs_t *c);

/* Power-on state: command 0, re-initialised on the first valid step. */
void mrs_init_state(mrs_state_t *s);

/* One control period: driver's front-wheel angle (rad), yaw rate (rad/s), speed (m/s) in;
 * auxiliary front-wheel angle command (rad) out. s->status and s->fault_flags say what happened.
 * Non-finite inputs are faults: they never reach the state or the output. hold nonzero (the
 * monitor's suspicions, MRS_SUSPECT_CHECKS): the command may move toward zero
 * but no further from it than it is, inside the law's clamp; 0 is the law without it. */
mrs_real_t mrs_step(const mrs_coeffs_t *c, mrs_state_t *s, mrs_real_t delta_driver, mrs_real_t yaw_rate,
                    mrs_real_t speed, uint8_t hold);

/* The state the node sends for mrs_step()'s status and the plausibility monitor's bits
 * (CtrlStatus_Plausibility, mrs_monitor.h): FAULT on a plausibility fault; else STARTING while the
 * node is starting (nonzero: its inputs not all received yet); else FAULT when mrs_step() faulted,
 * DEGRADED when the monitor is degraded, else mrs_step()'s status. model_regulator.reported_state. */
unsigned mrs_reported_state(unsigned status, unsigned plausibility, int starting);

#endif
