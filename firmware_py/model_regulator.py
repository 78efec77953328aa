"""Fixed-step limited-integrator model regulator (paper Figure 6) -- the porting reference.

Structure, in the style of generated embedded code:

* ``ControllerConfig``  -- calibration (``firmware_py.calibration``: what an ECU holds in flash);
* ``configure(cfg)``    -- computes every coefficient once (``Coefficients``), like
  ``model_initialize``; this is the only place with divisions by configuration values,
  ``exp``, ``tan`` or validation of the calibration;
* ``State``             -- the preallocated mutable state (a C struct);
* ``step(c, s, ...)``   -- one control period: scalar float arithmetic on ``c`` and ``s``
  only: no allocation, no numpy, no I/O, no clock reads, no library calls.

The control law (derivation in docs/controller.md). With Q(s) = q0 / (tau_Q s + 1) and the
desired model G_n(s) = K_n(v) / (tau_n s + 1) of eq. (18), eq. (6) gives the auxiliary
steering angle

    delta_mr = Q [F_n A_n (delta_d + u_a)] - q0 (tau_n s + 1) / (tau_Q s + 1) [rho],   rho = r / K_n(v)

where u_a is the auxiliary command actually applied (after saturation and rate limit),
delta_d the driver's front-wheel angle, A_n the nominal actuator (M samples of delay, then a
first-order lag, ``model_actuator_tau``) and F_n the nominal yaw-rate filter (2nd-order
Butterworth, ``model_filter_hz``): the nominal model is F_n A_n G_n, and with Q = Q0 F_n A_n
(eq. 12) Q/G_n stays the lead-lag above.  Limited integrator, eq. (22): q0 = K / (1 + K),
tau_Q = tau / (1 + K); standard, eq. (17): q0 = 1, tau_Q = tau / (1 + K).  K, tau and tau_n
may be scheduled over speed: step() interpolates the coefficient sets.  Feeding the *applied*
command back is what makes this form windup-free: A_n, F_n and Q are stable filters of
bounded signals, so the state stays bounded while the output is clamped, and the output
leaves saturation as soon as the unclamped law does.

Both filters of Q share its pole, so the law is one first-order recursion (direct form II
transposed, one state z) on w, the nominal model's output:

    p[k]   = a_n p[k-1] + b_n u_a[k-M]                  (A_n; p = u_a[k-M] without a lag)
    w[k]   = F_n(delta_d[k] + p[k])                     (DF2T biquad; w = its input without one)
    y[k]   = g_w0 w[k] - g_r0 rho[k] + z[k]
    z[k+1] = g_w1 w[k] - g_r1 rho[k] + a y[k]
    u_a[k] = clamp(y[k], lo[k], hi[k])

With M = 0 (the paper's structure) w = delta_d + u_a[k]; with Tustin g_w0 != 0 the loop is
then algebraic and solved exactly (see step()).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# Controller status, as sent on the bus (AuxSteerCmd_State, CtrlStatus_State): step() gives the
# first four (``State.status``), the node reports ``reported_state()`` of it.
STATUS_INACTIVE = 0  # below activation speed, or not yet run: command held at / faded to 0
STATUS_ACTIVE = 1
STATUS_SATURATED = 2  # command clamped at the actuator limit
STATUS_FAULT = 3  # an input was non-finite or out of range, or a plausibility fault: command fades to 0
STATUS_DEGRADED = 4  # the plausibility monitor degraded (PLAUS_DEGRADED): fewer checks, or the command fades
STATUS_STARTING = 5  # from power-up until every sensor input has been received once (the node's)

# Fault flags (bit set), which input caused STATUS_FAULT.
FAULT_DRIVER_ANGLE = 0x01
FAULT_YAW_RATE = 0x02
FAULT_SPEED = 0x04

# The plausibility monitor's CtrlStatus_Plausibility bits, for reported_state().
from firmware_py.plausibility import PLAUS_DEGRADED, PLAUS_FAULT  # noqa: E402

# The calibration lives in its own module; it is re-exported here because a port reads
# both together (ports/c/mrs_controller.h holds the config, coefficient and state structs).
from firmware_py.calibration import (  # noqa: E402  (re-exports)
    AUX_LIMIT, DEFAULT_TAU_N, MAX_MODEL_DELAY, MAX_SCHEDULE, METHOD_TUSTIN, METHOD_ZOH, NOMINAL_C_F,
    NOMINAL_C_R, NOMINAL_L_F, NOMINAL_L_R, NOMINAL_MASS, PAPER_CONFIG, PAPER_K, PAPER_TAU, PREVIOUS_CONFIG,
    Q_LIMITED, Q_STANDARD, ControllerConfig, constant_gains, describe_gains, format_gains, plain_law, validate,
)

__all__ = [
    "AUX_LIMIT", "DEFAULT_TAU_N", "MAX_MODEL_DELAY", "MAX_SCHEDULE", "METHOD_TUSTIN", "METHOD_ZOH", "NOMINAL_C_F",
    "NOMINAL_C_R", "NOMINAL_L_F", "NOMINAL_L_R", "NOMINAL_MASS", "PAPER_CONFIG", "PAPER_K", "PAPER_TAU",
    "PREVIOUS_CONFIG", "Q_LIMITED", "Q_STANDARD", "ControllerConfig", "constant_gains", "describe_gains", "format_gains",
    "plain_law", "validate",
    "STATUS_INACTIVE", "STATUS_ACTIVE", "STATUS_SATURATED", "STATUS_FAULT", "FAULT_DRIVER_ANGLE",
    "FAULT_YAW_RATE", "FAULT_SPEED", "Coefficients", "LawPoint", "State", "q_filter", "configure", "law_at",
    "reset", "step", "ModelRegulator",
    "STATUS_DEGRADED", "STATUS_STARTING", "reported_state",
]


@dataclass(frozen=True, slots=True)
class Coefficients:
    """Everything step() needs, computed once by configure().

    The law's coefficient set (a, g_w*, g_r*, q0) is a table over the speed breakpoints
    ``sched_v`` (one entry for a constant law); step() interpolates it linearly and holds it
    outside the breakpoints.  In C these are arrays of ``MRS_MAX_SCHEDULE``."""

    n_sched: int
    sched_v: tuple[float, ...]  # breakpoints, m/s
    sched_inv_dv: tuple[float, ...]  # 1 / (v[i+1] - v[i])
    sched_a: tuple[float, ...]  # pole of Q in z
    sched_g_w0: tuple[float, ...]  # w path (q0 * Q numerator)
    sched_g_w1: tuple[float, ...]
    sched_g_r0: tuple[float, ...]  # rho path (q0 * lead-lag numerator)
    sched_g_r1: tuple[float, ...]
    sched_q0: tuple[float, ...]  # d.c. gain of Q
    inv_one_minus_g_w0: float  # 1 / (1 - g_w0), algebraic loop of the M = 0 form (constant law only)
    model_delay: int  # M: w uses the command issued M steps ago (0: this step's)
    act_a: float  # nominal actuator p = act_a p + act_b u[k-M]: exp(-Ts/tau_an), 1 - act_a (0, 1: none)
    act_b: float
    flt_b0: float  # nominal yaw-rate filter, DF2T biquad (1, 0, 0, 0, 0: none)
    flt_b1: float
    flt_b2: float
    flt_a1: float
    flt_a2: float
    wheelbase: float  # 1/K_n(v) = wheelbase / v + k_us * v   (eq. 15 inverted)
    k_us: float
    u_max: float
    du_max: float  # rate limit per step; +inf when disabled
    fade_step: float
    speed_active_min: float
    speed_max: float
    driver_angle_max: float
    yaw_rate_max: float
    ts: float


@dataclass(frozen=True, slots=True)
class LawPoint:
    """The law's coefficient set at one speed, as step() interpolates it."""

    a: float
    g_w0: float
    g_w1: float
    g_r0: float
    g_r1: float
    q0: float


class State:
    """Preallocated controller state. ``needs_init`` forces a bumpless re-start."""

    __slots__ = ("z", "u_prev", "u_hist", "hist_idx", "p_n", "f_s1", "f_s2", "needs_init", "recovering",
                 "status", "fault_flags")

    def __init__(self) -> None:
        self.z = 0.0
        self.u_prev = 0.0
        self.u_hist = [0.0] * MAX_MODEL_DELAY  # ring buffer of the last M commands (C: double[8])
        self.hist_idx = 0
        self.p_n = 0.0  # nominal actuator position
        self.f_s1 = 0.0  # nominal filter states
        self.f_s2 = 0.0
        self.needs_init = True
        self.recovering = False
        self.status = STATUS_INACTIVE
        self.fault_flags = 0


def q_filter(q_form: str, k: float, tau: float) -> tuple[float, float]:
    """(q0, tau_Q) of Q(s) = q0 / (tau_Q s + 1): eq. (22) for limited, eq. (17) for standard."""
    tau_q = tau / (1.0 + k)
    q0 = k / (1.0 + k) if q_form == Q_LIMITED else 1.0
    return q0, tau_q


def _law_coefficients(cfg: ControllerConfig, k: float, tau: float, tau_n: float) -> LawPoint:
    q0, tau_q = q_filter(cfg.q_form, k, tau)
    ts = cfg.ts
    if cfg.method == METHOD_TUSTIN:
        den = 2.0 * tau_q + ts
        a = (2.0 * tau_q - ts) / den
        bw0 = bw1 = ts / den
        br0 = (2.0 * tau_n + ts) / den
        br1 = (ts - 2.0 * tau_n) / den
    else:  # ZOH: Q -> (1-a)/(z-a); (tau_n s+1)/(tau_Q s+1) = c + (1-c) Q/q0 -> c + (1-c)(1-a)/(z-a)
        a = math.exp(-ts / tau_q)
        c = tau_n / tau_q
        bw0, bw1 = 0.0, 1.0 - a
        br0, br1 = c, 1.0 - a - c
    return LawPoint(a, q0 * bw0, q0 * bw1, q0 * br0, q0 * br1, q0)


def butterworth2(f_c: float, ts: float) -> tuple[float, float, float, float, float]:
    """(b0, b1, b2, a1, a2) of the 2nd-order Butterworth low-pass at f_c, Tustin with the
    cut-off pre-warped (what scipy.signal.butter(2, f_c, fs=1/ts) gives)."""
    w = math.tan(math.pi * f_c * ts)
    n = 1.0 / (1.0 + math.sqrt(2.0) * w + w * w)
    b0 = w * w * n
    return b0, 2.0 * b0, b0, 2.0 * (w * w - 1.0) * n, (1.0 - math.sqrt(2.0) * w + w * w) * n


def configure(cfg: ControllerConfig) -> Coefficients:
    """Validate the calibration and compute the coefficients (the model_initialize step)."""
    validate(cfg)
    points = [_law_coefficients(cfg, k, tau, tau_n) for k, tau, tau_n in cfg.gain_points()]
    speeds = cfg.schedule_speed if cfg.scheduled else (0.0,)
    g_w0 = points[0].g_w0
    act_a = math.exp(-cfg.ts / cfg.model_actuator_tau) if cfg.model_actuator_tau > 0.0 else 0.0
    flt = butterworth2(cfg.model_filter_hz, cfg.ts) if cfg.model_filter_hz > 0.0 else (1.0, 0.0, 0.0, 0.0, 0.0)
    l_f, l_r, m = cfg.nominal_l_f, cfg.nominal_l_r, cfg.nominal_mass
    c_f, c_r = cfg.nominal_c_f, cfg.nominal_c_r
    wheelbase = l_f + l_r
    # 1/K_n(v) = a0/b0 of eq. (14) at mu = 1: L/v + (c_r l_r - c_f l_f) m v / (c_f c_r L).
    k_us = (c_r * l_r - c_f * l_f) * m / (c_f * c_r * wheelbase)
    ts = cfg.ts
    return Coefficients(
        n_sched=len(points),
        sched_v=tuple(speeds),
        sched_inv_dv=tuple(1.0 / (b - a) for a, b in zip(speeds, speeds[1:])),
        sched_a=tuple(p.a for p in points),
        sched_g_w0=tuple(p.g_w0 for p in points),
        sched_g_w1=tuple(p.g_w1 for p in points),
        sched_g_r0=tuple(p.g_r0 for p in points),
        sched_g_r1=tuple(p.g_r1 for p in points),
        sched_q0=tuple(p.q0 for p in points),
        inv_one_minus_g_w0=1.0 / (1.0 - g_w0),
        model_delay=cfg.model_delay_steps,
        act_a=act_a,
        act_b=1.0 - act_a,
        flt_b0=flt[0], flt_b1=flt[1], flt_b2=flt[2], flt_a1=flt[3], flt_a2=flt[4],
        wheelbase=wheelbase,
        k_us=k_us,
        u_max=cfg.aux_limit,
        du_max=cfg.rate_limit * ts if cfg.rate_limit > 0.0 else math.inf,
        fade_step=cfg.fade_rate * ts,
        speed_active_min=cfg.speed_active_min,
        speed_max=cfg.speed_max,
        driver_angle_max=cfg.driver_angle_max,
        yaw_rate_max=cfg.yaw_rate_max,
        ts=ts,
    )


def law_at(c: Coefficients, speed: float) -> LawPoint:
    """The coefficient set step() uses at ``speed``, by step()'s own units (for analysis)."""
    j = schedule_index(c, speed)
    j1 = schedule_upper(c, speed, j)
    f = schedule_fraction(c, speed, j)
    return LawPoint(*(interpolate(t, j, j1, f) for t in (c.sched_a, c.sched_g_w0, c.sched_g_w1, c.sched_g_r0,
                                                         c.sched_g_r1, c.sched_q0)))


def reset(s: State) -> None:
    """Back to power-on: command 0, state re-initialised on the next valid step."""
    s.z = 0.0
    s.u_prev = 0.0
    for i in range(MAX_MODEL_DELAY):
        s.u_hist[i] = 0.0
    s.hist_idx = 0
    s.p_n = 0.0
    s.f_s1 = 0.0
    s.f_s2 = 0.0
    s.needs_init = True
    s.recovering = False
    s.status = STATUS_INACTIVE
    s.fault_flags = 0


# The law's units, in the order step() runs them; mrs_controller.c's mrs_step() has the same
# units under the same names, statement for statement.
def input_faults(c: Coefficients, delta_driver: float, yaw_rate: float, speed: float) -> int:
    """The FAULT_* flags of the inputs out of range.  A NaN fails every range comparison, so
    non-finite inputs are caught by the same checks."""
    flags = 0
    if not (-c.driver_angle_max <= delta_driver <= c.driver_angle_max):
        flags |= FAULT_DRIVER_ANGLE
    if not (-c.yaw_rate_max <= yaw_rate <= c.yaw_rate_max):
        flags |= FAULT_YAW_RATE
    if not (0.0 <= speed <= c.speed_max):
        flags |= FAULT_SPEED
    return flags


def fade_out(c: Coefficients, s: State, flags: int) -> float:
    """Invalid input or too slow to schedule K_n(v): the state is not touched by the inputs, the
    command fades to zero, and the next valid step re-initialises."""
    u = s.u_prev
    if u > c.fade_step:
        u -= c.fade_step
    elif u < -c.fade_step:
        u += c.fade_step
    else:
        u = 0.0
    s.u_prev = u
    s.status = STATUS_FAULT if flags != 0 else STATUS_INACTIVE
    s.needs_init = True
    return u


def schedule_interior(c: Coefficients, speed: float) -> bool:
    """The speed strictly between the first and the last breakpoint: the gains interpolate."""
    n = c.n_sched
    return n > 1 and c.sched_v[0] < speed < c.sched_v[n - 1]


def schedule_index(c: Coefficients, speed: float) -> int:
    """The last breakpoint at or below the speed (ascending); 0 below the first."""
    j = 0
    n = c.n_sched
    if n > 1 and speed > c.sched_v[0]:
        if speed >= c.sched_v[n - 1]:
            j = n - 1
        else:
            for i in range(1, n - 1):
                if speed >= c.sched_v[i]:
                    j = i
    return j


def schedule_upper(c: Coefficients, speed: float, j: int) -> int:
    """The breakpoint the gains interpolate toward: the next one inside the schedule, else ``j``."""
    return j + 1 if schedule_interior(c, speed) else j


def schedule_fraction(c: Coefficients, speed: float, j: int) -> float:
    """How far the speed is from breakpoint ``j`` toward the next one: 0 outside the schedule."""
    return (speed - c.sched_v[j]) * c.sched_inv_dv[j] if schedule_interior(c, speed) else 0.0


def interpolate(table: tuple[float, ...], j: int, j1: int, f: float) -> float:
    """The coefficient of ``table`` a fraction ``f`` of the way from breakpoint ``j`` to ``j1``."""
    return table[j] + f * (table[j1] - table[j])


def restart(c: Coefficients, s: State, delta_driver: float, rho: float, q0: float, g_w0: float,
            g_r0: float) -> None:
    """Start every filter at its steady state for the present inputs with the command held, so
    a restart does not excite the large high-frequency gain on rho."""
    w0 = delta_driver + s.u_prev
    s.z = q0 * (w0 - rho) - (g_w0 * w0 - g_r0 * rho)
    for i in range(c.model_delay):
        s.u_hist[i] = s.u_prev
    s.hist_idx = 0
    s.p_n = s.u_prev
    s.f_s1 = (1.0 - c.flt_b0) * w0
    s.f_s2 = (c.flt_b2 - c.flt_a2) * w0
    s.needs_init = False
    s.recovering = True


def slew_step(c: Coefficients, s: State) -> float:
    """The most the command may move this period: the rate limit, the fade step while it
    recovers."""
    du = c.du_max
    if s.recovering and c.fade_step < du:
        du = c.fade_step
    return du


def window_low(c: Coefficients, s: State, lo_slew: float, hold: bool) -> float:
    """The admissible window's lower end: the actuator's range intersected with the slew window;
    on ``hold`` (lo <= u_prev already) it keeps u_prev and 0's side of it."""
    lo = lo_slew
    if lo < -c.u_max:
        lo = -c.u_max
    if hold:
        if s.u_prev > 0.0:
            lo = lo if lo > 0.0 else 0.0
        else:
            lo = s.u_prev if s.u_prev > lo else lo
    return lo


def window_high(c: Coefficients, s: State, hi_slew: float, hold: bool) -> float:
    """The admissible window's upper end (as ``window_low``)."""
    hi = hi_slew
    if hi > c.u_max:
        hi = c.u_max
    if hold:
        if s.u_prev > 0.0:
            hi = s.u_prev if s.u_prev < hi else hi
        else:
            hi = hi if hi < 0.0 else 0.0
    return hi


def clamp(u: float, lo: float, hi: float) -> float:
    """u within [lo, hi]."""
    return lo if u < lo else (hi if u > hi else u)


def constant_law(c: Coefficients, s: State, delta_driver: float, rho: float, a: float, g_w0: float, g_w1: float,
                 g_r0: float, g_r1: float, lo: float, hi: float) -> float:
    """Constant law only (configure() checks it). y = p + g_w0 * u_a with u_a = clamp(y, lo, hi):
    since 0 <= g_w0 < 1 the unique solution is u_a = clamp(p / (1 - g_w0), lo, hi)."""
    p = g_w0 * delta_driver - g_r0 * rho + s.z
    u = clamp(p * c.inv_one_minus_g_w0, lo, hi)
    y = p + g_w0 * u
    w = delta_driver + u
    s.z = g_w1 * w - g_r1 * rho + a * y
    return u


def delayed_law(c: Coefficients, s: State, delta_driver: float, rho: float, a: float, g_w0: float, g_w1: float,
                g_r0: float, g_r1: float, lo: float, hi: float) -> float:
    """The yaw rate measured now answers the command issued M steps ago, through the actuator and
    the sensor filter: compare it with the nominal model's answer to that command (past commands
    only, so no algebraic loop)."""
    i = s.hist_idx
    s.p_n = c.act_a * s.p_n + c.act_b * s.u_hist[i]
    x = delta_driver + s.p_n
    w = c.flt_b0 * x + s.f_s1
    s.f_s1 = c.flt_b1 * x - c.flt_a1 * w + s.f_s2
    s.f_s2 = c.flt_b2 * x - c.flt_a2 * w
    y = g_w0 * w - g_r0 * rho + s.z
    u = clamp(y, lo, hi)
    s.u_hist[i] = u
    i += 1
    if i >= c.model_delay:
        i = 0
    s.hist_idx = i
    s.z = g_w1 * w - g_r1 * rho + a * y
    return u


def step(c: Coefficients, s: State, delta_driver: float, yaw_rate: float, speed: float,
         hold: bool = False) -> float:
    """One control period. Returns the auxiliary front-wheel angle command in rad.

    Inputs: driver's front-wheel angle (rad), measured yaw rate (rad/s), speed (m/s); ``hold``
    (the plausibility monitor's suspicion of the yaw rate, not yet confirmed): the command may
    move toward zero but no further from it than it is, inside the law's own clamp, so that
    the state follows the command it held: no windup, so the release does not jump to a request
    that grew meanwhile (and a calibrated rate limit still bounds it).
    ``s.status`` and ``s.fault_flags`` tell what happened.
    """
    flags = input_faults(c, delta_driver, yaw_rate, speed)
    s.fault_flags = flags
    if flags != 0 or speed < c.speed_active_min:
        return fade_out(c, s, flags)
    inv_kn = c.wheelbase / speed + c.k_us * speed
    rho = inv_kn * yaw_rate  # yaw rate expressed as the wheel angle the nominal car needs for it
    # The coefficient set at this speed: linear between breakpoints, held outside them.
    j = schedule_index(c, speed)
    j1 = schedule_upper(c, speed, j)
    f = schedule_fraction(c, speed, j)
    a = interpolate(c.sched_a, j, j1, f)
    g_w0 = interpolate(c.sched_g_w0, j, j1, f)
    g_w1 = interpolate(c.sched_g_w1, j, j1, f)
    g_r0 = interpolate(c.sched_g_r0, j, j1, f)
    g_r1 = interpolate(c.sched_g_r1, j, j1, f)
    if s.needs_init:
        restart(c, s, delta_driver, rho, interpolate(c.sched_q0, j, j1, f), g_w0, g_r0)
    # Admissible command window: actuator range, intersected with the slew window.
    du = slew_step(c, s)
    lo_slew = s.u_prev - du
    hi_slew = s.u_prev + du
    lo = window_low(c, s, lo_slew, hold)
    hi = window_high(c, s, hi_slew, hold)
    if c.model_delay == 0:
        u = constant_law(c, s, delta_driver, rho, a, g_w0, g_w1, g_r0, g_r1, lo, hi)
    else:
        u = delayed_law(c, s, delta_driver, rho, a, g_w0, g_w1, g_r0, g_r1, lo, hi)
    if s.recovering and not hold and lo_slew < u < hi_slew:
        s.recovering = False  # the slew no longer binds: caught up with the control law
    s.u_prev = u
    s.status = STATUS_SATURATED if (u >= c.u_max or u <= -c.u_max) else STATUS_ACTIVE
    return u


def reported_state(status: int, plausibility: int, starting: bool) -> int:
    """The state the controller node sends (``AuxSteerCmd_State``, ``CtrlStatus_State``) for
    step()'s ``status`` and the plausibility monitor's ``CtrlStatus_Plausibility`` bits: FAULT on
    a plausibility fault; else STARTING while the node is ``starting`` (its inputs not all
    received yet: what they give, FAULT or DEGRADED, is theirs); else FAULT when step() faulted,
    DEGRADED when the monitor is degraded, else step()'s status.  ports/c/mrs_controller.c's
    mrs_reported_state is its port."""
    if plausibility & PLAUS_FAULT:
        return STATUS_FAULT
    if starting:
        return STATUS_STARTING
    if status == STATUS_FAULT:
        return STATUS_FAULT
    if plausibility & PLAUS_DEGRADED:
        return STATUS_DEGRADED
    return status


class ModelRegulator:
    """Convenience owner of one configured controller instance."""

    def __init__(self, config: ControllerConfig | None = None) -> None:
        self.config = config if config is not None else ControllerConfig()
        self.coefficients = configure(self.config)
        self.state = State()

    def step(self, delta_driver: float, yaw_rate: float, speed: float, hold: bool = False) -> float:
        return step(self.coefficients, self.state, delta_driver, yaw_rate, speed, hold)

    def reset(self) -> None:
        reset(self.state)
