"""Plausibility monitor -- a porting reference in ``model_regulator``'s style.

E2E and SecOC prove that a frame is the sensor's, unaltered and fresh; this module checks that
the values in valid frames agree with each other and with the nominal car (issue 18), and
bounds what the command may do whatever computed it.

Structure (as ``model_regulator``): ``PlausibilityConfig`` (calibration) -> ``configure()``
(every coefficient once: the only divisions by calibration values and the only ``exp``) ->
``MonitorState`` (preallocated) -> ``monitor_step(c, s, ...)`` once per yaw-rate sample (the
controller node counts them by the frames' alive counter, so ``ts`` is the sensor's sample
time, equal to the control period by the DBC's ``MRS_ControlLoop``): scalar arithmetic on ``c``
and ``s`` only, no allocation.  ``monitor_step`` runs one unit per check family below (its
function, the coefficients and the state slots its docstring names), in the order and under the
names ``mrs_monitor_step`` has them in C, and ``plausibility_bits`` (``PLAUS_TABLE``) turns the
flags into bits.  The bounded authority that acts on
its bits is ``firmware_py.authority``.  Both are ported bit for bit (float64) to
``ports/c/mrs_monitor.c``.

The checks (docs/controller.md, "Plausibility monitor"; the reasoning: docs/decisions/0002-0007):

1. **Kinematic** (yaw rate against lateral acceleration): a_y = v (beta' + r), so in steady
   state r = a_y / v; the residual a_y / v - r is beta', which the car keeps small.  Evaluated
   at each new ``MRS_RedundantSensors`` sample (50 ms), against the yaw rate of the same cycle
   (the plant sends both frames in the same step, so the comparison has no hold error).  Less
   the beta' of a family of nominal cars: every friction in [``mu_min``, 1] (``mu_min_paired``
   while the yaw-rate pair runs), so that a car on low mu or under a yaw moment, whose physical
   channels move together, is not taken for a sensor that disagrees with them; and every
   sensor lag in [0, ``sensor_tau``] on the wheel angle, so that a brisk turn of the wheel, which reaches the nominal car's beta before the
   filtered a_y, is not either, whatever the sensors' filters.
2. **Model** (yaw rate against the steering): the nominal (mu = 1) car's steady-state yaw
   rate K_n(v) (delta_driver + aux) of eq. (15), lagged by a first-order filter, against the
   yaw rate.  ``aux`` in both checks is the command sent the period before through the
   actuator's nominal lag ``actuator_tau``: the angle it puts on the car.  Low mu makes the car yaw *less* than the model, disturbances (the yaw moments the
   controller exists for) make it yaw otherwise, so this bound is wide: a gross check that
   still works when the lateral acceleration is missing.  Out-voted (it does not count up) while
   two measurements confirm the yaw rate: its second element (4) and a_y / v (1).
3. **Steering pair**: the driver's angle against the steering sensor's second channel, at each
   new redundant sample.
4. **Yaw-rate pair**: the yaw rate against the yaw-rate sensor's second element, sampled with it
   (``MRS_YawRate`` carries both; a sender without the element sends SNA, NaN here, which
   pauses the check, and the element lost after it was received is DEGRADED): the
   mean of their difference over ``YAW_PAIR_WINDOW`` samples (10 ms).  No motion of the car
   moves that residual, so its bound sits just above the two elements' noise and offsets, and a
   stuck or scaled element is found while the command it drove is still small; the limiter then
   removes the command at its rate bound (``authority_step``'s ``cut``), not at the fault fade.
   Before that, a single sample of r - r_2 over ``yaw_pair_hold`` is a suspicion
   (``SUSPECT_YAW_PAIR``, not latched) on which the law's command may shrink but not grow
   (``step()``'s ``hold``, inside its own clamp: no windup), for at most ``YAW_PAIR_WINDOW``
   samples until ``YAW_PAIR_WINDOW`` samples in a row within it re-arm it: the law's answer
   to a sensor error that reaches it through the sensor's filter builds up while the
   window's mean is still confirming it.
   The steering pair has a suspicion too (``SUSPECT_STEER_JUMP``, not latched): the driver's
   angle moving by more than ``steer_jump`` in one sample, faster than any hand, between two
   redundant samples holds the law's command the same way until the next redundant sample lets
   the pair judge it (at most ``kin_gap``): a channel that sticks or jumps is answered by the
   law at full speed, and the pair sees it only at the 50 ms frame.
5. **Frozen**: a value that does not change at all (bit for bit) for ``frozen_time`` while its
   partner (yaw rate <-> a_y / v, one steering channel <-> the other) moves by more than
   ``frozen_move_*``: a real sensor's noise toggles its LSB, so an unchanging value while the
   car's motion changes is a frozen output.

6. **Speed**: a change from one speed value to the next larger than ``speed_step`` (no car
   changes its speed that fast; a sensor stuck at another value, offset or scaled jumps at its
   onset), checked before the pause below ``speed_min``, since K_n(v) follows the wrong speed
   at once; a missing speed restarts it.
7. **Speed in a steady turn**: a_y = v (r + beta'), and once the turn has settled beta' is
   gone, so the speed is a_y / r.  At each new redundant sample where |r| >= ``turn_yaw_min``,
   ``TURN_BLOCK`` samples (500 ms) in which r and a_y stay near the block's first make a block;
   a block that follows another such block (the side slip has settled) compares the speed with
   a_y / r (their r-weighted mean) against ``turn_speed_rel`` v plus what the sensors' offsets
   make of it, (``turn_yaw_bias`` v + ``turn_lat_bias``) / |r|.  A speed that drifts, which
   never jumps, is found here; straight on, nothing depends on the speed the law is given.
   Out-voted while the second speed (8) is there and agrees: the speed is measured then, and
   a_y / r off it is a side slip still settling.
8. **Speed pair**: the speed against a second, independent speed (``speed_redundant``, from the
   redundant frame: the wheel speeds on a car), in every period while both are valid, before
   the pause below ``speed_min`` (a drift carries the reading under it): |v - v_2| over
   ``speed_pair_bound`` + ``speed_pair_rel`` min(v, v_2), counted as the model check, trips at
   ``speed_pair_time``.  A drift, however slow and wherever the car is, is found once it has
   carried the speed that far; NaN (a sender without it) pauses the check, and the source lost
   after it was received is DEGRADED, as for the yaw-rate pair.  While the car brakes (the
   speed, lagged by ``speed_brake_tau``, above it by what a fall at ``speed_brake_decel``
   leaves) a second speed *below* the speed may be ``speed_slip_rel`` min(v, v_2) further off:
   the braked wheels' slip, which ABS holds at 10-20 %.

Each of 1 and 3 counts up by one on a sample over its bound and down by one (to 0) on a sample
within it, and trips at ``*_count``; 2 and 8 likewise per control period, tripping at
``model_time`` and ``speed_pair_time``; 4 trips on one window over its bound (at other rates
than 500 Hz its ``YAW_PAIR_WINDOW`` samples span another time), 6 on one jump, 7 on one block
over its bound.

While the yaw rate's second element confirms it (4 running, its window full, its last samples
within ``yaw_pair_hold``), a trip of 1 or 2 is not the yaw rate's fault: what disagrees is the
lateral acceleration, the car itself, which past its grip limit (sliding, spinning) is neither
the nominal car nor in a steady turn, or an input the speed pair or the steering pair answers
for.  It latches ``OUTSIDE_MODEL`` instead, which is DEGRADED and fades the command as a fault does
(``authority_step``'s ``fade``): the law's linear car does not hold there, and a wrong a_y
leaves the yaw rate with one check.  Without the element the trips are the yaw rate's, as the
monitor cannot tell the car from the sensor (docs/controller.md, "Outside the model").

A trip latches (until ``reset_monitor``: the next ignition cycle).  A missing redundant input
(NaN: the node's freshness check) pauses the checks that need it and sets DEGRADED; below
``speed_min`` every check but 6 and 8 pauses and its counters restart.

``monitor_step`` returns the ``CtrlStatus_Plausibility`` bits: ``PLAUS_YAW`` or ``PLAUS_STEER``
is a fault (the command fades to zero), ``PLAUS_DEGRADED`` a degraded state (fewer checks; the
authority limiter then ends an intervention at the panic window; with ``OUTSIDE_MODEL`` the
node fades the command at once).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_py.calibration import NOMINAL_C_F, NOMINAL_C_R, NOMINAL_L_F, NOMINAL_L_R, NOMINAL_MASS, SHIPPED_TS

# CtrlStatus_Plausibility (mrsteer_dbc.names.PLAUS_*; equal by test, this module imports stdlib only).
PLAUS_YAW = 0x01
PLAUS_STEER = 0x02
PLAUS_DEGRADED = 0x04
PLAUS_FAULT = PLAUS_YAW | PLAUS_STEER

# The detailed checks (MonitorState.flags).
CHECK_KINEMATIC = 0x01  # yaw rate against a_y / v
CHECK_MODEL = 0x02  # yaw rate against the nominal car's response to the steering
CHECK_STEER_PAIR = 0x04  # the two steering channels
CHECK_YAW_PAIR = 0x100  # the two yaw-rate elements (C: the flags are 16 bits)
CHECK_SPEED = 0x200  # the speed jumped between two samples by more than a car can change it
CHECK_TURN = 0x400  # the speed disagrees with a_y / r in a steady turn
CHECK_SPEED_PAIR = 0x1000  # the speed disagrees with the second speed
FROZEN_YAW = 0x08
FROZEN_LAT = 0x10
FROZEN_STEER = 0x20
FROZEN_STEER_2 = 0x40
MISSING = 0x80  # a redundant input is missing (not latched)
#: The yaw-rate pair's latest sample is over ``yaw_pair_hold``, which its window has not
#: confirmed (not latched): the node passes it (``SUSPECT_CHECKS``) to ``step()``'s ``hold``, on
#: which the law's command may shrink but not grow (docs/decisions/0004-suspicions-hold-the-law.md).
SUSPECT_YAW_PAIR = 0x800
#: The driver's angle moved by more than ``steer_jump`` in one sample since the last redundant
#: sample (not latched): held as ``SUSPECT_YAW_PAIR`` until the steering pair judges it at the
#: next one (docs/decisions/0004-suspicions-hold-the-law.md).
SUSPECT_STEER_JUMP = 0x2000
#: The kinematic (1) or the model (2) check tripped while the yaw rate's second element confirmed
#: it (latched): not the yaw rate, but a_y, the car (past its grip limit, spinning, it is neither
#: the nominal car nor in a steady turn) or another input the nominal car reads (the speed and
#: the steering have their own pairs, which report their faults).
#: PLAUS_DEGRADED, and the node fades the command as on a fault (``authority_step``'s ``fade``):
#: the law's linear car does not hold there (docs/controller.md, "Outside the model").
OUTSIDE_MODEL = 0x4000
#: The suspicions: the node passes ``flags & SUSPECT_CHECKS != 0`` as ``step()``'s ``hold``.
SUSPECT_CHECKS = SUSPECT_YAW_PAIR | SUSPECT_STEER_JUMP
#: The speed schedules the nominal car's yaw rate K_n(v) the law follows: its fault is the yaw
#: rate's (CtrlStatus_Plausibility 1).
YAW_CHECKS = (CHECK_KINEMATIC | CHECK_MODEL | FROZEN_YAW | FROZEN_LAT | CHECK_YAW_PAIR | CHECK_SPEED | CHECK_TURN
              | CHECK_SPEED_PAIR)
STEER_CHECKS = CHECK_STEER_PAIR | FROZEN_STEER | FROZEN_STEER_2
#: The degraded states: a redundant input missing, or the car outside the model.
DEGRADED_CHECKS = MISSING | OUTSIDE_MODEL
#: The pair checks, which find a fault while the command it drove is still building: the node
#: passes ``flags & CUT_CHECKS`` as ``authority_step``'s ``cut`` (docs/decisions/0003-a-second-yaw-rate-element-and-the-cut.md).
CUT_CHECKS = CHECK_YAW_PAIR | CHECK_STEER_PAIR | CHECK_SPEED | CHECK_SPEED_PAIR
#: The flags on which the command fades though no fault bit is set: the node passes
#: ``flags & FADE_CHECKS`` as ``authority_step``'s ``fade``.
FADE_CHECKS = OUTSIDE_MODEL

#: Samples (of the 50 ms redundant frame) the kinematic residual is averaged over: 200 ms.
KIN_WINDOW = 4
#: Yaw-rate samples the pair's difference is averaged over: 10 ms at 500 Hz.
YAW_PAIR_WINDOW = 5
#: Samples (of the 50 ms redundant frame) in one block of the steady-turn speed check: 500 ms.
TURN_BLOCK = 10

# The nominal car is the controller's own (section 3, mu = 1): one owner, firmware_py.calibration.


@dataclass(frozen=True)
class PlausibilityConfig:
    """Calibration of the monitor.  Angles in rad (front wheel), rates in rad/s, times in s.

    Each field's comment starts with its unit in brackets (``[1]``: a ratio) and says what the
    field bounds; ``python -m mrsteer_cli.doc_tables --write`` renders them into
    docs/controller.md's table of thresholds, so they are written here once."""

    # [s] the monitor's step: one yaw-rate sample (the control period by the DBC's MRS_ControlLoop)
    ts: float = SHIPPED_TS
    # [m/s] below it every check but the speed step and the speed pair pauses: a_y / v and K_n(v) say
    # too little there
    speed_min: float = 5.0
    # [rad/s] kinematic bound, constant part (2 deg/s): |a_y / v - r less the family's beta'| <=
    # yaw_bound + yaw_rel min(|a_y / v|, |r|) (+ side_accel / v while the yaw-rate pair runs)
    yaw_bound: float = 0.035
    # [1] kinematic bound, relative part, on the smaller of |a_y / v| and |r|, so that a wrong a_y or
    # yaw rate cannot widen its own bound
    yaw_rel: float = 0.1
    # [samples] redundant samples (50 ms each) over the kinematic bound, counted up and down, to trip;
    # the residual is already a mean over KIN_WINDOW samples
    yaw_count: int = 1
    # [1] the uncompensated residual a_y / v - r must also exceed this fraction of the bound: a sensor
    # error moves both residuals alike
    yaw_raw_fraction: float = 0.5
    # [rad] steering pair: |delta - delta_2| at each redundant sample (0.23 deg of wheel angle); at 40
    # m/s, K_n(v) times it is the kinematic yaw bound
    steer_bound: float = 0.004
    # [samples] redundant samples over steer_bound, counted up and down, to trip
    steer_count: int = 1
    # [rad/s] model bound, constant part: |r - r_model| <= model_margin + model_rel |r_model|
    model_margin: float = 0.15
    # [1] model bound, relative part: on low mu the car yaws between 0 and 1 times the nominal car
    model_rel: float = 1.0
    # [s] first-order lag of the nominal car's yaw response r_model = K_n(v) (delta_driver + aux)
    model_tau: float = 0.15
    # [s] net time over the model bound (counted up and down per step) to trip
    model_time: float = 0.15
    # [s] a value bit-for-bit unchanged this long while its partner moved is frozen
    frozen_time: float = 0.2
    # [rad/s] how far the yaw rate's partner (a_y / v; r for a_y) must move for the frozen check
    frozen_move_yaw: float = 0.02
    # [rad] how far the other steering channel must move for the frozen check
    frozen_move_steer: float = 0.003
    # [m] the nominal car (the controller's own, firmware_py.calibration): centre of gravity to front axle
    nominal_l_f: float = NOMINAL_L_F
    # [m] the nominal car: centre of gravity to rear axle
    nominal_l_r: float = NOMINAL_L_R
    # [kg] the nominal car's mass
    nominal_mass: float = NOMINAL_MASS
    # [N/rad] the nominal car's front cornering stiffness
    nominal_c_f: float = NOMINAL_C_F
    # [N/rad] the nominal car's rear cornering stiffness
    nominal_c_r: float = NOMINAL_C_R
    # [s] without a usable redundant sample for longer, the kinematic window restarts; a shorter gap
    # (one sample withheld or lost) is spanned by the next sample's interval
    kin_gap: float = 0.15
    # [1] lowest friction of the kinematic check's family of nominal cars (tyre stiffness scaled by mu)
    # without the yaw-rate pair: a low-mu car's side-slip rate is not a yaw-rate error
    mu_min: float = 0.5
    # [s] nominal first-order lag from the command sent the period before to the angle it puts on the
    # car (kinematic and model checks)
    actuator_tau: float = 0.025
    # [rad/s] yaw-rate pair: |mean of r - r_2 over YAW_PAIR_WINDOW samples| over it trips; above two
    # elements' noise and opposite 0.3 deg/s offsets
    yaw_pair_bound: float = 0.03
    # [s] largest lag the sensors' filters put on a_y and r (a 30 Hz 2nd-order Butterworth's delay): the
    # family sees the wheel angle through every lag in [0, sensor_tau]
    sensor_tau: float = 0.0075
    # [m/s^2] side force's acceleration (a gust) the kinematic bound allows, as side_accel / v, while
    # the yaw-rate pair runs and finds yaw-rate errors itself
    side_accel: float = 0.6
    # [m/s] speed step: the most the speed may change from one value to the next (75 m/s^2 over a 20 ms
    # frame); more is a sensor that jumped
    speed_step: float = 1.5
    # [rad/s] the steady-turn speed check runs at redundant samples where |r| is at least this
    turn_yaw_min: float = 0.1
    # [rad/s] within a steady-turn block r stays within this of the block's first sample, else the block
    # restarts
    turn_yaw_tol: float = 0.05
    # [m/s^2] within a block a_y stays within turn_lat_tol + turn_lat_rel |a_y| of the block's first sample
    turn_lat_tol: float = 0.1
    # [1] the relative part of that a_y tolerance
    turn_lat_rel: float = 0.08
    # [1] steady-turn bound: |v - a_y / r| <= turn_speed_rel v + (turn_yaw_bias v + turn_lat_bias) / |r|
    turn_speed_rel: float = 0.02
    # [rad/s] the yaw-rate offset the steady-turn bound allows (0.63 deg/s: issue 18 calls 0.6 deg/s normal)
    turn_yaw_bias: float = 0.011
    # [m/s^2] the a_y offset the steady-turn bound allows
    turn_lat_bias: float = 0.1
    # [rad/s] one sample of |r - r_2| over it is a suspicion: the law's command may shrink but not grow,
    # for at most YAW_PAIR_WINDOW samples (re-armed by as many within it in a row); in (0,
    # yaw_pair_bound]
    yaw_pair_hold: float = 0.02
    # [m/s] speed pair: |v - v_2| <= speed_pair_bound + speed_pair_rel min(v, v_2); above the second
    # speed's rounding (0.15 m/s)
    speed_pair_bound: float = 1.0
    # [1] speed pair, relative part: the tyres' rolling-radius spread and the wheels' slip in normal driving
    speed_pair_rel: float = 0.05
    # [s] net time over the speed pair's bound (counted up and down per step) to trip
    speed_pair_time: float = 0.1
    # [rad] the driver's angle moving by more than this in one sample between two redundant samples is a
    # suspicion (0.86 deg: faster than any hand at 100-500 Hz)
    steer_jump: float = 0.015
    # [1] the kinematic family's lowest friction while the yaw-rate pair runs (the paper's lowest mu): a
    # car sliding on it is not taken for a sensor error
    mu_min_paired: float = 0.3
    # [m/s^2] the car brakes (for the speed pair) while its speed falls at this or more: under the
    # deceleration at which ABS acts on any road of mu >= 0.1
    speed_brake_decel: float = 0.5
    # [s] the first-order lag through which the speed's fall is seen
    speed_brake_tau: float = 0.05
    # [1] while braking, a second speed below the speed may be speed_slip_rel min(v, v_2) further off:
    # braked wheels slip, 10-20 % under ABS
    speed_slip_rel: float = 0.25


@dataclass(frozen=True, slots=True)
class MonitorCoefficients:
    speed_min: float
    yaw_bound: float
    yaw_rel: float
    inv_yaw_raw_fraction: float
    yaw_count: int
    steer_bound: float
    inv_steer_bound: float
    steer_count: int
    model_margin: float
    model_rel: float
    model_alpha: float  # first-order lag per period: 1 - exp(-ts / model_tau)
    model_steps: int
    frozen_steps: int
    kin_gap_steps: int
    frozen_move_yaw: float
    frozen_move_steer: float
    wheelbase: float  # K_n(v) = v / (wheelbase + k_us v^2), eq. (15) at mu = 1
    k_us: float
    ts: float
    # The nominal car's a_y / v = -cs_m / v beta + moment_m / v^2 r + cf_m / v delta (eq. 14, mu = 1)
    inv_cs_m: float  # m / (c_f + c_r)
    moment_m: float  # (c_r l_r - c_f l_f) / m
    cf_m: float  # c_f / m
    lat_span: float  # 1 / mu_min - 1: how far the family's a_y term reaches beyond mu = 1's
    lat_span_paired: float  # 1 / mu_min_paired - 1: the same while the yaw-rate pair runs
    aux_alpha: float  # the actuator's lag per period: 1 - exp(-ts / actuator_tau)
    yaw_pair_bound: float
    inv_yaw_pair_bound: float
    yaw_pair_hold: float
    delta_alpha: float  # the sensors' lag per period: 1 - exp(-ts / sensor_tau)
    side_accel: float
    speed_step: float
    turn_yaw_min: float
    turn_yaw_tol: float
    turn_lat_tol: float
    turn_lat_rel: float
    turn_speed_rel: float
    turn_yaw_bias: float
    turn_lat_bias: float
    speed_pair_bound: float
    speed_pair_rel: float
    speed_pair_steps: int
    speed_brake_alpha: float  # the speed's lag per period: 1 - exp(-ts / speed_brake_tau)
    speed_brake_lag: float  # how far that lag stays above a speed falling at speed_brake_decel
    speed_slip_rel: float
    steer_jump: float


class MonitorState:
    """Preallocated monitor state (a C struct)."""

    __slots__ = ("started", "lat_prev", "steer2_prev", "kin_count", "pair_count", "model_count", "r_model",
                 "yaw_last", "yaw_same", "yaw_ref", "lat_last", "lat_same", "lat_ref",
                 "st_last", "st_same", "st_ref", "st2_last", "st2_same", "st2_ref", "latched", "flags", "bits",
                 "kin_err", "pair_err", "model_err", "kin_raw", "kin_comp", "kin_idx", "kin_n", "since",
                 "have_sample", "raw_prev", "beta_prev", "yaw_ref_ok", "st_ref_ok", "kin_lat",
                 "lat_beta_prev", "aux_lag", "yaw_pair", "yaw_pair_idx", "yaw_pair_n", "yaw_pair_err",
                 "yaw_hold_n", "yaw_clear_n",
                 "yaw2_seen", "delta_lag", "kin_sensor", "lag_beta_prev", "speed_last", "speed_seen",
                 "turn_n", "turn_settled", "turn_r0", "turn_a0", "turn_res", "turn_r", "turn_err",
                 "speed2_seen", "speed_pair_count", "speed_pair_err", "speed_lag",
                 "jump_prev", "jump_ok", "steer_hold_n")

    def __init__(self) -> None:
        reset_monitor(self)


def reset_monitor(s: MonitorState) -> None:
    """Power-on state: no sample seen, nothing latched."""
    s.started = False  # r_model and the *_prev values hold a sample
    s.lat_prev = 0.0
    s.steer2_prev = 0.0
    s.kin_count = 0
    s.pair_count = 0
    s.model_count = 0
    s.r_model = 0.0
    s.yaw_last = s.lat_last = s.st_last = s.st2_last = 0.0
    s.yaw_same = s.lat_same = s.st_same = s.st2_same = 0
    s.yaw_ref = s.lat_ref = s.st_ref = s.st2_ref = 0.0
    s.yaw_ref_ok = s.st_ref_ok = False  # yaw_ref, st_ref taken (from the 50 ms frame)
    s.latched = 0
    s.flags = 0
    s.bits = 0
    # The last residuals, as fractions of their bounds (diagnostics: the false-alarm margins).
    s.kin_err = s.pair_err = s.model_err = 0.0
    s.since = 0  # control periods since the last redundant sample
    s.have_sample = False  # raw_prev and beta_prev hold the last sample's
    s.raw_prev = 0.0
    s.beta_prev = 0.0
    s.kin_raw = [0.0] * KIN_WINDOW  # the last samples of a_y / v - r (C: double[4])
    s.kin_comp = [0.0] * KIN_WINDOW  # the same less the nominal car's beta'
    s.kin_lat = [0.0] * KIN_WINDOW  # the part of that beta' from a_y, which scales with 1 / mu
    s.lat_beta_prev = 0.0
    s.aux_lag = 0.0  # the auxiliary angle on the car: the command lagged by actuator_tau
    s.kin_idx = 0
    s.kin_n = 0  # samples in the window so far
    s.yaw_pair = [0.0] * YAW_PAIR_WINDOW  # the last samples of r - r_2 (C: double[5])
    s.yaw_pair_idx = 0
    s.yaw_pair_n = 0  # samples in the window so far
    s.yaw_pair_err = 0.0
    s.yaw_hold_n = 0  # samples of this suspicion the command was held on (at most YAW_PAIR_WINDOW)
    s.yaw_clear_n = 0  # samples in a row within yaw_pair_hold (YAW_PAIR_WINDOW of them re-arm the hold)
    s.yaw2_seen = False  # the yaw-rate sensor's second element has been received this cycle
    s.jump_prev = 0.0  # the driver's angle the sample before (for steer_jump)
    s.jump_ok = False  # jump_prev holds one
    s.steer_hold_n = 0  # samples the steering pair's suspicion still holds the command
    s.delta_lag = 0.0  # the wheel angle through the sensors' lag (sensor_tau)
    s.kin_sensor = [0.0] * KIN_WINDOW  # how much that lag moves the nominal car's beta' (C: double[4])
    s.lag_beta_prev = 0.0
    s.speed_last = 0.0  # the last valid speed (speed_seen: since the speed was last invalid)
    s.speed_lag = 0.0  # the speed through speed_brake_tau's lag (since speed_seen)
    s.speed_seen = False
    s.turn_n = 0  # samples in the steady-turn check's current block
    s.turn_settled = False  # the block before the current one was steady: the side slip has settled
    s.turn_r0 = s.turn_a0 = 0.0  # the block's first r and a_y
    s.turn_res = s.turn_r = 0.0  # the block's sums of r v - a_y and of r
    s.turn_err = 0.0
    s.speed2_seen = False  # the second speed has been received this cycle
    s.speed_pair_count = 0
    s.speed_pair_err = 0.0


def configure(cfg: PlausibilityConfig) -> MonitorCoefficients:
    check_positive(cfg, ("ts", "speed_min", "yaw_bound", "yaw_raw_fraction", "steer_bound", "model_margin", "model_tau", "model_time",
                          "frozen_time", "frozen_move_yaw", "frozen_move_steer", "nominal_l_f", "nominal_l_r",
                          "nominal_mass", "nominal_c_f", "nominal_c_r", "kin_gap", "actuator_tau",
                          "yaw_pair_bound", "yaw_pair_hold", "sensor_tau", "speed_step", "turn_yaw_min",
                          "turn_yaw_tol", "turn_lat_tol", "turn_speed_rel", "speed_pair_bound", "speed_pair_time",
                          "steer_jump", "speed_brake_decel", "speed_brake_tau"))
    for name in ("mu_min", "mu_min_paired"):
        value = getattr(cfg, name)
        if not (isinstance(value, float | int) and 0.05 <= value <= 1.0):
            raise ValueError(f"{name} must be in [0.05, 1], got {value!r}")
    for name in ("model_rel", "yaw_rel", "side_accel", "turn_lat_rel", "turn_yaw_bias", "turn_lat_bias",
                 "speed_pair_rel", "speed_slip_rel"):
        value = getattr(cfg, name)
        if not (isinstance(value, float | int) and 0.0 <= value < 1e3):
            raise ValueError(f"{name} must be in [0, 1000), got {value!r}")
    if not cfg.yaw_pair_hold <= cfg.yaw_pair_bound:
        # a suspicion comes before the fault it suspects: its threshold is not above the fault's
        raise ValueError(f"yaw_pair_hold must not exceed yaw_pair_bound, got {cfg.yaw_pair_hold!r} and "
                         f"{cfg.yaw_pair_bound!r}")
    if not cfg.turn_yaw_tol < 2.0 * cfg.turn_yaw_min:
        # a block's r all on one side, so that its sum of r is never 0 (check 7 divides by it)
        raise ValueError(f"turn_yaw_tol must be below 2 turn_yaw_min, got {cfg.turn_yaw_tol!r} and "
                         f"{cfg.turn_yaw_min!r}")
    if not cfg.speed_brake_tau <= 10.0:
        # a longer lag sees no braking (and its 1 - exp(-ts / tau) rounds to 0 from 1e15 s)
        raise ValueError(f"speed_brake_tau must be at most 10 s, got {cfg.speed_brake_tau!r}")
    for name in ("yaw_count", "steer_count"):
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 100:
            raise ValueError(f"{name} must be an integer in [1, 100], got {value!r}")
    wheelbase = cfg.nominal_l_f + cfg.nominal_l_r
    # A first-order lag follows a ramp falling at a per period (1 - alpha) a / alpha above it.
    brake_alpha = 1.0 - math.exp(-cfg.ts / cfg.speed_brake_tau)
    k_us = ((cfg.nominal_c_r * cfg.nominal_l_r - cfg.nominal_c_f * cfg.nominal_l_f) * cfg.nominal_mass
            / (cfg.nominal_c_f * cfg.nominal_c_r * wheelbase))
    return MonitorCoefficients(
        speed_min=cfg.speed_min, yaw_bound=cfg.yaw_bound, yaw_rel=cfg.yaw_rel,
        inv_yaw_raw_fraction=1.0 / cfg.yaw_raw_fraction,
        yaw_count=cfg.yaw_count, steer_bound=cfg.steer_bound, inv_steer_bound=1.0 / cfg.steer_bound,
        steer_count=cfg.steer_count, model_margin=cfg.model_margin, model_rel=cfg.model_rel,
        model_alpha=1.0 - math.exp(-cfg.ts / cfg.model_tau), model_steps=steps_of(cfg.model_time, cfg.ts),
        frozen_steps=steps_of(cfg.frozen_time, cfg.ts), kin_gap_steps=steps_of(cfg.kin_gap, cfg.ts),
        frozen_move_yaw=cfg.frozen_move_yaw,
        frozen_move_steer=cfg.frozen_move_steer, wheelbase=wheelbase, k_us=k_us, ts=cfg.ts,
        inv_cs_m=cfg.nominal_mass / (cfg.nominal_c_f + cfg.nominal_c_r),
        moment_m=(cfg.nominal_c_r * cfg.nominal_l_r - cfg.nominal_c_f * cfg.nominal_l_f) / cfg.nominal_mass,
        cf_m=cfg.nominal_c_f / cfg.nominal_mass, lat_span=1.0 / cfg.mu_min - 1.0,
        lat_span_paired=1.0 / cfg.mu_min_paired - 1.0,
        aux_alpha=1.0 - math.exp(-cfg.ts / cfg.actuator_tau), yaw_pair_bound=cfg.yaw_pair_bound,
        inv_yaw_pair_bound=1.0 / cfg.yaw_pair_bound, yaw_pair_hold=cfg.yaw_pair_hold,
        delta_alpha=1.0 - math.exp(-cfg.ts / cfg.sensor_tau),
        side_accel=cfg.side_accel, speed_step=cfg.speed_step, turn_yaw_min=cfg.turn_yaw_min,
        turn_yaw_tol=cfg.turn_yaw_tol, turn_lat_tol=cfg.turn_lat_tol, turn_lat_rel=cfg.turn_lat_rel,
        turn_speed_rel=cfg.turn_speed_rel, turn_yaw_bias=cfg.turn_yaw_bias, turn_lat_bias=cfg.turn_lat_bias,
        speed_pair_bound=cfg.speed_pair_bound, speed_pair_rel=cfg.speed_pair_rel,
        speed_pair_steps=steps_of(cfg.speed_pair_time, cfg.ts), speed_brake_alpha=brake_alpha,
        speed_brake_lag=(1.0 - brake_alpha) * cfg.speed_brake_decel * cfg.ts / brake_alpha,
        speed_slip_rel=cfg.speed_slip_rel, steer_jump=cfg.steer_jump)


def steps_of(t: float, ts: float) -> int:
    """A time in periods of ``ts``, rounded half up (as C's floor(x + 0.5); Python's round()
    takes a tie to even), at least 1 and at most a C int32's largest."""
    return min(max(1, math.floor(t / ts + 0.5)), 2**31 - 1)


def check_positive(cfg: object, names: tuple[str, ...]) -> None:
    """Each of ``names`` of ``cfg`` a positive finite number, else ValueError naming it."""
    for name in names:
        value = getattr(cfg, name)
        if not (isinstance(value, float | int) and math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be positive and finite, got {value!r}")


# One control period is the checks below in this order (the C port's mrs_monitor_step has the
# same units under the same names).  Each unit is one check family: its coefficients are the
# ``MonitorCoefficients`` fields its comment names, its state the ``MonitorState`` slots it
# names, its step the function; it latches its fault into ``s.latched`` and returns what the
# period's other units read (a suspicion flag, a vote).  ``plausibility_bits`` is the combiner.

#: The combiner's table: a detailed flag in the mask sets the CtrlStatus_Plausibility bit.
PLAUS_TABLE = ((YAW_CHECKS, PLAUS_YAW), (STEER_CHECKS, PLAUS_STEER), (DEGRADED_CHECKS, PLAUS_DEGRADED))


def plausibility_bits(flags: int) -> int:
    """The combiner: the CtrlStatus_Plausibility bits of the detailed ``flags`` (PLAUS_TABLE)."""
    bits = 0
    for mask, bit in PLAUS_TABLE:
        if flags & mask:
            bits |= bit
    return bits


def speed_step_check(c: MonitorCoefficients, s: MonitorState, speed: float) -> None:
    """6. Speed step: a jump no car makes.  Before the pause below, which a speed stuck under
    speed_min would otherwise bring on: K_n(v) follows the wrong speed whatever it is.
    Coefficients speed_step, speed_brake_alpha; state speed_seen, speed_last, speed_lag (the
    lagged speed is the speed pair's braking test)."""
    if 0.0 <= speed < 1e3:
        if s.speed_seen and speed != s.speed_last:
            e = speed - s.speed_last
            e = -e if e < 0.0 else e
            if e > c.speed_step:
                s.latched |= CHECK_SPEED
        if s.speed_seen:
            s.speed_lag += c.speed_brake_alpha * (speed - s.speed_lag)
        else:
            s.speed_lag = speed
        s.speed_last = speed
        s.speed_seen = True
    else:
        s.speed_seen = False  # missing (the node's freshness): the next valid value starts afresh


def speed_pair_check(c: MonitorCoefficients, s: MonitorState, speed: float, speed_redundant: float) -> bool:
    """8. Speed pair: before the pause too, since a drifting speed carries the reading under
    speed_min while the car is still fast.  Coefficients speed_pair_bound, speed_pair_rel,
    speed_brake_lag, speed_slip_rel, speed_pair_steps; state speed2_seen, speed_pair_count,
    speed_pair_err.  Returns the vote: the second speed there and agreeing (it out-votes check
    7).  Its loss is ``input_flags``'s."""
    if not 0.0 <= speed_redundant < 1e3:
        s.speed_pair_count = 0
        return False
    s.speed2_seen = True
    if not 0.0 <= speed < 1e3:
        s.speed_pair_count = 0
        return False
    e = speed - speed_redundant
    e = -e if e < 0.0 else e
    x = speed if speed < speed_redundant else speed_redundant
    bound = c.speed_pair_bound + c.speed_pair_rel * x
    # it vouches for the speed (out-votes check 7) only within the plain bound: the slip
    # it allows while braking would hide a speed reading that much high from check 7 too
    within = e <= bound
    if speed_redundant < speed and s.speed_lag - speed > c.speed_brake_lag:
        bound += c.speed_slip_rel * x  # braking: the wheels the second speed is read from slip
    s.speed_pair_err = e / bound
    if e > bound:
        s.speed_pair_count += 1
        if s.speed_pair_count >= c.speed_pair_steps:
            s.speed_pair_count = c.speed_pair_steps
            s.latched |= CHECK_SPEED_PAIR
    elif s.speed_pair_count > 0:
        s.speed_pair_count -= 1
    return s.speed_pair_count == 0 and within


def redundant_frame_lost(c: MonitorCoefficients, s: MonitorState) -> None:
    """The redundant frame missing this period (a_y or the second steering channel): the
    steady-turn check starts afresh when it is back, and after a long gap the kinematic window
    too.  Coefficient kin_gap_steps; state turn_n, turn_settled, since, have_sample, kin_n."""
    s.turn_n = 0
    s.turn_settled = False
    if s.since >= c.kin_gap_steps:
        # A long gap: no difference across it, and the kinematic window restarts when the
        # frame is back.  A shorter one (a sample withheld) is bridged as a lost frame is:
        # the next sample's interval spans it.
        s.have_sample = False
        s.kin_n = 0


def monitor_pause(s: MonitorState) -> None:
    """Paused (too slow, or step() faults on the input): restart the windows, keep the latch."""
    s.kin_count = s.pair_count = s.model_count = 0
    s.yaw_pair_n = 0
    s.yaw_same = s.lat_same = s.st_same = s.st2_same = 0
    s.jump_ok = False
    s.steer_hold_n = 0
    s.kin_n = 0
    s.turn_n = 0
    s.turn_settled = False
    s.started = False


def monitor_start(s: MonitorState, delta_driver: float, delta_driver_redundant: float, yaw_rate: float,
                  lat_accel: float, r_kin: float, r_ss: float, delta: float) -> None:
    """The first period after a pause: the lags and the previous samples start at this one."""
    s.r_model = r_ss
    s.kin_n = 0
    s.kin_idx = 0
    s.since = 0
    s.have_sample = False
    s.lat_prev = lat_accel
    s.steer2_prev = delta_driver_redundant
    s.yaw_last, s.lat_last, s.st_last, s.st2_last = yaw_rate, lat_accel, delta_driver, delta_driver_redundant
    s.yaw_ref, s.lat_ref, s.st_ref, s.st2_ref = r_kin, yaw_rate, delta_driver_redundant, delta_driver
    s.yaw_ref_ok = s.st_ref_ok = False
    s.delta_lag = delta
    s.turn_n = 0
    s.turn_settled = False
    s.started = True


def yaw_confirmed(s: MonitorState, yaw_rate_redundant: float) -> bool:
    """The yaw rate confirmed by its second element: valid, the pair's window full and its last
    samples each within yaw_pair_hold (no suspicion)."""
    return (-1e3 < yaw_rate_redundant < 1e3 and s.yaw_pair_n >= YAW_PAIR_WINDOW
            and s.yaw_clear_n >= YAW_PAIR_WINDOW)


def model_check(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, r_ss: float, lat_ok: bool,
                yaw_rate_redundant: float) -> None:
    """2. Model: the nominal car's steady-state yaw rate, lagged, against the yaw rate.
    Coefficients model_alpha, model_margin, model_rel, model_steps; state r_model, model_err,
    model_count (and the yaw-rate pair's and the kinematic window's, for the vote)."""
    s.r_model += c.model_alpha * (r_ss - s.r_model)
    e = yaw_rate - s.r_model
    e = -e if e < 0.0 else e
    rm = -s.r_model if s.r_model < 0.0 else s.r_model
    bound = c.model_margin + c.model_rel * rm
    s.model_err = e / bound
    # Out-voted: the yaw rate agrees with its second element (the last YAW_PAIR_WINDOW samples
    # within yaw_pair_hold) and with a_y / v (a full kinematic window within its bound, a_y
    # there).  Two measurements then confirm the yaw rate that the nominal car, which knows
    # neither the road's grip nor a yaw moment, disagrees with: a disturbance the actuator
    # cannot fully counter (the paper's 4000 Nm on mu 0.3), not a sensor error.  Not "its last
    # sample recent": a steady a_y on exact sensors repeats its value, which the monitor cannot
    # tell from no sample, and a frozen a_y is the frozen check's.
    confirmed = yaw_confirmed(s, yaw_rate_redundant)
    vouched = confirmed and lat_ok and s.kin_n >= KIN_WINDOW and s.kin_count == 0
    if e > bound and not vouched:
        s.model_count += 1
        if s.model_count >= c.model_steps:
            s.model_count = c.model_steps  # saturated: C counts in 32 bits
            # the yaw rate confirmed by its second element: not the yaw rate's error
            s.latched |= OUTSIDE_MODEL if confirmed else CHECK_MODEL
    elif s.model_count > 0:
        s.model_count -= 1


def yaw_pair_suspicion(c: MonitorCoefficients, s: MonitorState, e: float) -> int:
    """4'. The yaw-rate pair's suspicion on one sample's r - r_2, capped: an offset between hold
    and bound is no fault the window confirms, and must not keep the law's command from growing
    for as long as it lasts.  Coefficient yaw_pair_hold; state yaw_hold_n, yaw_clear_n.
    Returns SUSPECT_YAW_PAIR or 0."""
    if e > c.yaw_pair_hold or e < -c.yaw_pair_hold:
        s.yaw_clear_n = 0
        if s.yaw_hold_n < YAW_PAIR_WINDOW:
            s.yaw_hold_n += 1
            return SUSPECT_YAW_PAIR
        return 0
    if s.yaw_clear_n < YAW_PAIR_WINDOW:
        s.yaw_clear_n += 1
    if s.yaw_clear_n >= YAW_PAIR_WINDOW:
        s.yaw_hold_n = 0
    return 0


def yaw_pair_check(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, yaw_rate_redundant: float) -> int:
    """4. Yaw-rate pair: the mean of r - r_2 over the last YAW_PAIR_WINDOW samples.
    Coefficients yaw_pair_bound, inv_yaw_pair_bound; state yaw_pair, yaw_pair_idx, yaw_pair_n,
    yaw_pair_err.  Returns the suspicion's flag (``yaw_pair_suspicion``)."""
    if not -1e3 < yaw_rate_redundant < 1e3:
        s.yaw_pair_n = 0  # the window restarts when the second element is back
        return 0
    i = s.yaw_pair_idx
    s.yaw_pair[i] = yaw_rate - yaw_rate_redundant
    i += 1
    if i >= YAW_PAIR_WINDOW:
        i = 0
    s.yaw_pair_idx = i
    suspect = yaw_pair_suspicion(c, s, yaw_rate - yaw_rate_redundant)
    if s.yaw_pair_n < YAW_PAIR_WINDOW:
        s.yaw_pair_n += 1
    if s.yaw_pair_n >= YAW_PAIR_WINDOW:
        e = (s.yaw_pair[0] + s.yaw_pair[1] + s.yaw_pair[2] + s.yaw_pair[3] + s.yaw_pair[4]) * (
            1.0 / YAW_PAIR_WINDOW)
        e = -e if e < 0.0 else e
        s.yaw_pair_err = e * c.inv_yaw_pair_bound
        if e > c.yaw_pair_bound:
            s.latched |= CHECK_YAW_PAIR
    return suspect


def steer_jump_check(c: MonitorCoefficients, s: MonitorState, delta_driver: float, new_sample: bool,
                     st2_ok: bool) -> int:
    """3'. The steering pair's suspicion: a jump of the driver's angle no hand makes between two
    redundant samples holds the command until the next one, where the pair judges it.
    Coefficients steer_jump, kin_gap_steps; state jump_prev, jump_ok, steer_hold_n.  Returns
    SUSPECT_STEER_JUMP or 0."""
    suspect = 0
    if new_sample or not st2_ok:
        s.steer_hold_n = 0  # the pair judges now, or cannot
    else:
        e = delta_driver - s.jump_prev
        if s.jump_ok and (e > c.steer_jump or e < -c.steer_jump):
            s.steer_hold_n = c.kin_gap_steps
        if s.steer_hold_n > 0:
            s.steer_hold_n -= 1
            suspect = SUSPECT_STEER_JUMP
    s.jump_prev = delta_driver
    s.jump_ok = True
    return suspect


def kinematic_sample(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, lat_accel: float, speed: float,
                     inv_v: float, r_kin: float, delta: float) -> None:
    """1, at a new redundant sample: a_y / v - r = beta', midway between this sample and the
    last, as measured ("raw") and less the nominal car's beta' (the difference of its beta over
    the interval: "comp"), into the window of KIN_WINDOW intervals.  A yaw-rate or a_y error
    moves both alike; a transient the nominal car explains (a steering step, a yaw moment) moves
    only raw; one it does not (a side force, low mu, where its beta is 1/mu too large) moves comp
    more.  Coefficients moment_m, cf_m, inv_cs_m, ts; state kin_raw, kin_comp, kin_lat,
    kin_sensor, kin_idx, kin_n, have_sample, raw_prev, beta_prev, lat_beta_prev, lag_beta_prev,
    since."""
    raw = r_kin - yaw_rate
    # The nominal car's side-slip angle from a_y, delta and r (eq. 14, mu = 1, solved for beta:
    # a_y = -(c_f + c_r) / m beta + moment_m r / v + c_f / m delta), nearly insensitive to r
    # (moment_m / v is the small understeer term), so a yaw-rate error hardly moves it.
    beta = (c.moment_m * inv_v * inv_v * yaw_rate + c.cf_m * inv_v * delta - r_kin) * c.inv_cs_m * speed
    lat_beta = lat_accel * c.inv_cs_m  # the a_y term of beta (with the minus sign: beta = ... - lat_beta)
    # The nominal car's beta with the wheel angle through the sensors' lag, less beta: a
    # steering step reaches beta at once but the filtered a_y only after the lag, so on
    # filtered sensors beta' jumped a sample early (a false alarm on a brisk turn of the
    # wheel at 10 m/s), and on unfiltered ones the lagged beta' would.
    lag_beta = c.cf_m * inv_v * (s.delta_lag - delta) * c.inv_cs_m * speed
    if s.have_sample:
        mid = 0.5 * (raw + s.raw_prev)
        i = s.kin_idx
        s.kin_raw[i] = mid
        s.kin_comp[i] = mid - (beta - s.beta_prev) / (s.since * c.ts)
        s.kin_lat[i] = (lat_beta - s.lat_beta_prev) / (s.since * c.ts)
        s.kin_sensor[i] = (s.lag_beta_prev - lag_beta) / (s.since * c.ts)
        i += 1
        if i >= KIN_WINDOW:
            i = 0
        s.kin_idx = i
        if s.kin_n < KIN_WINDOW:
            s.kin_n += 1
    s.have_sample = True
    s.raw_prev = raw
    s.beta_prev = beta
    s.lat_beta_prev = lat_beta
    s.lag_beta_prev = lag_beta
    s.since = 0


def kinematic_residual(c: MonitorCoefficients, s: MonitorState) -> float:
    """1. The window's residual: the smaller of |raw| / yaw_raw_fraction and the smallest
    |comp| of the family of nominal cars on mu in [mu_min, 1] (mu_min_paired while the yaw-rate
    pair runs: it finds yaw-rate errors itself) and sensor lags in [0, sensor_tau].  The car on
    mu has the a_y term of beta 1 / mu times mu = 1's, so its residual is comp + (1 / mu - 1)
    lat, linear in 1 / mu, and the lagged car's is comp + sens (taken as linear between the two
    lags).  The smallest |residual| of the family is 0 if its four corners differ in sign, else
    the smallest corner's.  Raw alone would be slow, because the controller's answer to a
    yaw-rate error is itself a transient that hides the error from raw for a few hundred ms.
    Coefficients lat_span, lat_span_paired, inv_yaw_raw_fraction."""
    raw = (s.kin_raw[0] + s.kin_raw[1] + s.kin_raw[2] + s.kin_raw[3]) * (1.0 / KIN_WINDOW)
    comp = (s.kin_comp[0] + s.kin_comp[1] + s.kin_comp[2] + s.kin_comp[3]) * (1.0 / KIN_WINDOW)
    span = c.lat_span_paired if s.yaw_pair_n >= YAW_PAIR_WINDOW else c.lat_span
    far = span * ((s.kin_lat[0] + s.kin_lat[1] + s.kin_lat[2] + s.kin_lat[3]) * (1.0 / KIN_WINDOW))
    sens = (s.kin_sensor[0] + s.kin_sensor[1] + s.kin_sensor[2] + s.kin_sensor[3]) * (1.0 / KIN_WINDOW)
    raw = (-raw if raw < 0.0 else raw) * c.inv_yaw_raw_fraction
    lo = hi = comp
    x = comp + sens
    lo = x if x < lo else lo
    hi = x if x > hi else hi
    x = comp + far
    lo = x if x < lo else lo
    hi = x if x > hi else hi
    x = comp + far + sens
    lo = x if x < lo else lo
    hi = x if x > hi else hi
    if lo <= 0.0 <= hi:
        comp = 0.0
    elif lo > 0.0:
        comp = lo
    else:
        comp = -hi
    return comp if comp < raw else raw


def kinematic_check(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, inv_v: float, r_kin: float) -> None:
    """1. Kinematic, at a new redundant sample: the window's residual against its bound.
    Coefficients yaw_bound, yaw_rel, side_accel, yaw_count; state kin_err, kin_count."""
    e = kinematic_residual(c, s)
    if s.kin_n < KIN_WINDOW:
        e = 0.0  # the window is not full yet
    # The relative allowance on the smaller of the turn's two measures, a_y / v and r: a
    # wrong one cannot widen its own bound (an a_y drift was found 0.3-0.7 s late).
    turn = -r_kin if r_kin < 0.0 else r_kin
    x = -yaw_rate if yaw_rate < 0.0 else yaw_rate
    turn = x if x < turn else turn
    bound = c.yaw_bound + c.yaw_rel * turn
    if s.yaw_pair_n >= YAW_PAIR_WINDOW:
        bound += c.side_accel * inv_v
    s.kin_err = e / bound
    if e > bound:
        s.kin_count += 1
        if s.kin_count >= c.yaw_count:
            s.kin_count = c.yaw_count
            # the yaw rate confirmed by its second element (this sample in the pair's
            # window and within its hold): not the yaw rate's error
            confirmed = s.yaw_pair_n >= YAW_PAIR_WINDOW and s.yaw_clear_n >= YAW_PAIR_WINDOW
            s.latched |= OUTSIDE_MODEL if confirmed else CHECK_KINEMATIC
    elif s.kin_count > 0:
        s.kin_count -= 1


def steer_pair_check(c: MonitorCoefficients, s: MonitorState, delta_driver: float,
                     delta_driver_redundant: float) -> None:
    """3. Steering pair, at a new redundant sample.  Coefficients steer_bound, inv_steer_bound,
    steer_count; state pair_err, pair_count."""
    e = delta_driver - delta_driver_redundant
    e = -e if e < 0.0 else e
    s.pair_err = e * c.inv_steer_bound
    if e > c.steer_bound:
        s.pair_count += 1
        if s.pair_count >= c.steer_count:
            s.pair_count = c.steer_count
            s.latched |= CHECK_STEER_PAIR
    elif s.pair_count > 0:
        s.pair_count -= 1


def turn_block_start(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, lat_accel: float) -> None:
    """7'. A steady-turn block goes on while r and a_y stay near its first sample's (r then on
    the same side: configure keeps turn_yaw_tol below 2 turn_yaw_min); else, and at its start,
    it starts at this sample.  Coefficients turn_yaw_tol, turn_lat_tol, turn_lat_rel; state
    turn_n, turn_settled, turn_r0, turn_a0, turn_res, turn_r."""
    if s.turn_n > 0:
        e = yaw_rate - s.turn_r0
        e = -e if e < 0.0 else e
        x = lat_accel - s.turn_a0
        x = -x if x < 0.0 else x
        am = -s.turn_a0 if s.turn_a0 < 0.0 else s.turn_a0
        if e > c.turn_yaw_tol or x > c.turn_lat_tol + c.turn_lat_rel * am:
            s.turn_n = 0
            s.turn_settled = False
    if s.turn_n == 0:
        s.turn_r0 = yaw_rate
        s.turn_a0 = lat_accel
        s.turn_res = 0.0
        s.turn_r = 0.0


def turn_check(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, lat_accel: float, speed: float,
               speed_vouched: bool) -> None:
    """7. The speed against a_y / r in a steady turn (blocks of TURN_BLOCK samples), at a new
    redundant sample.  Coefficients turn_yaw_min, turn_speed_rel, turn_yaw_bias, turn_lat_bias;
    state turn_n, turn_settled, turn_res, turn_r, turn_err (and the speed pair's vote)."""
    e = -yaw_rate if yaw_rate < 0.0 else yaw_rate
    if e < c.turn_yaw_min:
        s.turn_n = 0
        s.turn_settled = False
        return
    turn_block_start(c, s, yaw_rate, lat_accel)
    s.turn_res += yaw_rate * speed - lat_accel
    s.turn_r += yaw_rate
    s.turn_n += 1
    if s.turn_n < TURN_BLOCK:
        return
    # the speed less a_y / r over the block (r-weighted), against what the sensors' offsets and
    # the rest of the side slip can make of it at the block's mean |r|
    e = s.turn_res / s.turn_r
    e = -e if e < 0.0 else e
    rm = s.turn_r * (1.0 / TURN_BLOCK)
    rm = -rm if rm < 0.0 else rm
    bound = c.turn_speed_rel * speed + (c.turn_yaw_bias * speed + c.turn_lat_bias) / rm
    if s.turn_settled:
        s.turn_err = e / bound
        # Out-voted by the second speed when it is there and agrees: the speed is then measured
        # twice, and a_y / r off it is a side slip still settling (a slide on low mu), not a
        # speed error
        if e > bound and not speed_vouched:
            s.latched |= CHECK_TURN
    s.turn_settled = True
    s.turn_n = 0


def frozen_count(c: MonitorCoefficients, s: MonitorState, same: int, bit: int) -> int:
    """5. One step of a frozen value whose partner moved: the count, saturated at frozen_steps,
    latching ``bit`` there.  Shared by the four frozen checks."""
    if same < c.frozen_steps:
        same += 1
    if same >= c.frozen_steps:
        s.latched |= bit
    return same


def frozen_yaw_check(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, r_kin: float, lat_ok: bool,
                     new_sample: bool) -> None:
    """5. Frozen yaw rate against a_y / v, taken at its first sample after the yaw rate's last
    change.  Coefficients frozen_move_yaw, frozen_steps; state yaw_last, yaw_same, yaw_ref,
    yaw_ref_ok."""
    if yaw_rate != s.yaw_last:
        s.yaw_last, s.yaw_same, s.yaw_ref_ok = yaw_rate, 0, False
    elif new_sample and not s.yaw_ref_ok:
        s.yaw_ref, s.yaw_ref_ok = r_kin, True
    elif lat_ok and s.yaw_ref_ok:
        e = r_kin - s.yaw_ref
        e = -e if e < 0.0 else e
        if e > c.frozen_move_yaw:
            s.yaw_same = frozen_count(c, s, s.yaw_same, FROZEN_YAW)


def frozen_lat_check(c: MonitorCoefficients, s: MonitorState, yaw_rate: float, lat_accel: float) -> None:
    """5. Frozen a_y against the yaw rate.  Coefficients frozen_move_yaw, frozen_steps; state
    lat_last, lat_same, lat_ref."""
    if lat_accel != s.lat_last:
        s.lat_last, s.lat_same, s.lat_ref = lat_accel, 0, yaw_rate
    else:
        e = yaw_rate - s.lat_ref
        e = -e if e < 0.0 else e
        if e > c.frozen_move_yaw:
            s.lat_same = frozen_count(c, s, s.lat_same, FROZEN_LAT)


def frozen_steer_check(c: MonitorCoefficients, s: MonitorState, delta_driver: float, delta_driver_redundant: float,
                       new_sample: bool) -> None:
    """5. Frozen driver's angle against the second channel, taken at its first sample after the
    angle's last change.  Coefficients frozen_move_steer, frozen_steps; state st_last, st_same,
    st_ref, st_ref_ok."""
    if delta_driver != s.st_last:
        s.st_last, s.st_same, s.st_ref_ok = delta_driver, 0, False
    elif new_sample and not s.st_ref_ok:
        s.st_ref, s.st_ref_ok = delta_driver_redundant, True
    elif s.st_ref_ok:
        e = delta_driver_redundant - s.st_ref
        e = -e if e < 0.0 else e
        if e > c.frozen_move_steer:
            s.st_same = frozen_count(c, s, s.st_same, FROZEN_STEER)


def frozen_steer2_check(c: MonitorCoefficients, s: MonitorState, delta_driver: float,
                        delta_driver_redundant: float) -> None:
    """5. Frozen second steering channel against the driver's angle.  Coefficients
    frozen_move_steer, frozen_steps; state st2_last, st2_same, st2_ref."""
    if delta_driver_redundant != s.st2_last:
        s.st2_last, s.st2_same, s.st2_ref = delta_driver_redundant, 0, delta_driver
    else:
        e = delta_driver - s.st2_ref
        e = -e if e < 0.0 else e
        if e > c.frozen_move_steer:
            s.st2_same = frozen_count(c, s, s.st2_same, FROZEN_STEER_2)


def frozen_checks(c: MonitorCoefficients, s: MonitorState, delta_driver: float, delta_driver_redundant: float,
                  yaw_rate: float, lat_accel: float, r_kin: float, lat_ok: bool, st2_ok: bool,
                  new_sample: bool) -> None:
    """5. Frozen: unchanged for frozen_steps counted while the partner is away from where it was
    at this value's last change.  A partner from the 50 ms frame (a_y / v for the yaw rate, the
    second channel for the driver's angle) is taken at its first sample after that change: the
    sample held then may be up to a frame old."""
    frozen_yaw_check(c, s, yaw_rate, r_kin, lat_ok, new_sample)
    if lat_ok:
        frozen_lat_check(c, s, yaw_rate, lat_accel)
    if st2_ok:
        frozen_steer_check(c, s, delta_driver, delta_driver_redundant, new_sample)
        frozen_steer2_check(c, s, delta_driver, delta_driver_redundant)


def redundant_checks(c: MonitorCoefficients, s: MonitorState, delta_driver: float, delta_driver_redundant: float,
                     yaw_rate: float, lat_accel: float, speed: float, inv_v: float, r_kin: float,
                     delta: float, speed_vouched: bool) -> None:
    """1, 3 and 7 at a new redundant sample (either of its values changed)."""
    kinematic_sample(c, s, yaw_rate, lat_accel, speed, inv_v, r_kin, delta)
    kinematic_check(c, s, yaw_rate, inv_v, r_kin)
    steer_pair_check(c, s, delta_driver, delta_driver_redundant)
    turn_check(c, s, yaw_rate, lat_accel, speed, speed_vouched)


def monitor_finish(s: MonitorState, flags: int) -> int:
    """The period's flags (the latched ones with this period's) and bits into the state."""
    flags |= s.latched
    bits = plausibility_bits(flags)
    s.flags = flags
    s.bits = bits
    return bits


def input_flags(s: MonitorState, yaw_rate: float, yaw_rate_redundant: float, speed: float, speed_redundant: float,
                lat_ok: bool, st2_ok: bool) -> int:
    """MISSING when a redundant input the car has is gone: the second speed (once received,
    while the speed is valid: the speed pair pauses), the yaw rate's second element (likewise:
    the pair check pauses, which leaves a stuck first element to the slower checks), a_y or the
    second steering channel."""
    flags = 0
    if s.speed2_seen and not 0.0 <= speed_redundant < 1e3 and 0.0 <= speed < 1e3:
        flags |= MISSING
    if -1e3 < yaw_rate_redundant < 1e3:
        s.yaw2_seen = True
    elif s.yaw2_seen and -1e3 < yaw_rate < 1e3:
        flags |= MISSING
    if not (lat_ok and st2_ok):
        flags |= MISSING
    return flags


def primary_valid(c: MonitorCoefficients, delta_driver: float, yaw_rate: float, speed: float,
                  aux_cmd_applied: float) -> bool:
    """The inputs every check but the speed's needs: valid (False for NaN and +-inf), and the
    car at speed_min or faster."""
    return (-1e3 < delta_driver < 1e3) and (-1e3 < yaw_rate < 1e3) and (c.speed_min <= speed < 1e3) and (
        -1e3 < aux_cmd_applied < 1e3)


def monitor_step(c: MonitorCoefficients, s: MonitorState, delta_driver: float, delta_driver_redundant: float,
                 yaw_rate: float, lat_accel: float, speed: float, aux_cmd_applied: float,
                 yaw_rate_redundant: float = math.nan, speed_redundant: float = math.nan) -> int:
    """Check this period's inputs; returns the CtrlStatus_Plausibility bits (``s.flags``: the
    detailed checks).  ``aux_cmd_applied``: the auxiliary command sent the period before (the
    monitor lags it by the actuator's ``actuator_tau`` to the angle on the car).  NaN for
    a missing input: a missing primary input pauses every check but the two on the speed (step()
    faults on it), a missing redundant one the checks that need it (DEGRADED).  ``yaw_rate_redundant``, the
    yaw-rate sensor's second element, pauses its pair check when NaN; DEGRADED too once the
    element has been received since ``reset_monitor`` while the first element is valid (a lost
    element).  A sender without it (SNA from the start, or the default NaN) never sets it:
    every result is then as without the check.  ``speed_redundant``, the second speed, likewise
    for the speed pair."""
    speed_step_check(c, s, speed)
    speed_vouched = speed_pair_check(c, s, speed, speed_redundant)
    # A NaN fails every comparison: these are False for NaN and +-inf.
    primary_ok = primary_valid(c, delta_driver, yaw_rate, speed, aux_cmd_applied)
    lat_ok = -1e3 < lat_accel < 1e3
    st2_ok = -1e3 < delta_driver_redundant < 1e3
    flags = input_flags(s, yaw_rate, yaw_rate_redundant, speed, speed_redundant, lat_ok, st2_ok)
    if not (lat_ok and st2_ok):
        redundant_frame_lost(c, s)
    if not primary_ok:
        monitor_pause(s)
        return monitor_finish(s, flags)
    inv_v = 1.0 / speed
    r_kin = lat_accel * inv_v if lat_ok else 0.0
    if not s.started:
        s.aux_lag = aux_cmd_applied
    # The angle on the car: the command sent the period before, through the actuator's lag.
    # Taking the command itself for it made the nominal car's beta' (below) jump by half the
    # command's rate while the law slews: 0.09 rad/s, a false alarm on every strong yaw moment.
    s.aux_lag += c.aux_alpha * (aux_cmd_applied - s.aux_lag)
    delta = delta_driver + s.aux_lag
    r_ss = delta * speed / (c.wheelbase + c.k_us * speed * speed)  # the nominal car's steady-state yaw rate
    if not s.started:
        monitor_start(s, delta_driver, delta_driver_redundant, yaw_rate, lat_accel, r_kin, r_ss, delta)
    # The wheel angle as filtered a_y and yaw rate show its effect (the kinematic check's family).
    s.delta_lag += c.delta_alpha * (delta - s.delta_lag)
    model_check(c, s, yaw_rate, r_ss, lat_ok, yaw_rate_redundant)
    flags |= yaw_pair_check(c, s, yaw_rate, yaw_rate_redundant)
    if s.since < 1000000:
        s.since += 1
    new_sample = lat_ok and st2_ok and (lat_accel != s.lat_prev or delta_driver_redundant != s.steer2_prev)
    flags |= steer_jump_check(c, s, delta_driver, new_sample, st2_ok)
    if new_sample:
        redundant_checks(c, s, delta_driver, delta_driver_redundant, yaw_rate, lat_accel, speed, inv_v, r_kin, delta,
                         speed_vouched)
    if lat_ok:
        s.lat_prev = lat_accel
    if st2_ok:
        s.steer2_prev = delta_driver_redundant
    frozen_checks(c, s, delta_driver, delta_driver_redundant, yaw_rate, lat_accel, r_kin, lat_ok, st2_ok, new_sample)
    return monitor_finish(s, flags)


class PlausibilityMonitor:
    """Convenience owner of one configured monitor."""

    def __init__(self, config: PlausibilityConfig | None = None) -> None:
        self.config = config if config is not None else PlausibilityConfig()
        self.coefficients = configure(self.config)
        self.state = MonitorState()

    def step(self, delta_driver: float, delta_driver_redundant: float, yaw_rate: float, lat_accel: float,
             speed: float, aux_cmd_applied: float, yaw_rate_redundant: float = math.nan,
             speed_redundant: float = math.nan) -> int:
        return monitor_step(self.coefficients, self.state, delta_driver, delta_driver_redundant, yaw_rate,
                            lat_accel, speed, aux_cmd_applied, yaw_rate_redundant, speed_redundant)
