"""Fixed-step limited-integrator model regulator (paper Figure 6) -- the porting reference.

Structure, in the style of generated embedded code:

* ``ControllerConfig``  -- calibration (what an ECU would hold in flash);
* ``configure(cfg)``    -- computes every coefficient once (``Coefficients``), like
  ``model_initialize``; this is the only place with divisions by configuration values,
  ``exp`` or validation of the calibration;
* ``State``             -- the preallocated mutable state (a C struct);
* ``step(c, s, ...)``   -- one control period: scalar float arithmetic on ``c`` and ``s``
  only: no allocation, no numpy, no I/O, no clock reads, no library calls.

The control law (derivation in docs/controller.md). With Q(s) = q0 / (tau_Q s + 1) and the
desired model G_n(s) = K_n(v) / (tau_n s + 1) of eq. (18), eq. (6) gives the auxiliary
steering angle

    delta_mr = Q [delta_d + u_a] - q0 (tau_n s + 1) / (tau_Q s + 1) [rho],   rho = r / K_n(v)

where u_a is the auxiliary command actually applied (after saturation and rate limit) and
delta_d the driver's front-wheel angle.  Limited integrator, eq. (22): q0 = K / (1 + K),
tau_Q = tau / (1 + K); standard, eq. (17): q0 = 1, tau_Q = tau / (1 + K).  Feeding the
*applied* command back through Q is what makes this form windup-free: Q is a stable
filter of bounded signals, so the state stays bounded while the output is clamped, and the
output leaves saturation as soon as the unclamped law does.

Both filters share the pole of Q, so the discrete law is one first-order recursion
(direct form II transposed, one state z):

    y[k]   = g_w0 w[k] - g_r0 rho[k] + z[k]         w[k] = delta_d[k] + u_a[k]
    z[k+1] = g_w1 w[k] - g_r1 rho[k] + a y[k]
    u_a[k] = clamp(y[k], lo[k], hi[k])

With Tustin g_w0 != 0, so y[k] depends on u_a[k]; the loop is solved exactly (see step()).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# Controller status, as sent on the bus.
STATUS_INACTIVE = 0  # below activation speed, or not yet run: command held at / faded to 0
STATUS_ACTIVE = 1
STATUS_SATURATED = 2  # command clamped at the actuator limit
STATUS_FAULT = 3  # an input was non-finite or out of range: command fades to 0

# Fault flags (bit set), which input caused STATUS_FAULT.
FAULT_DRIVER_ANGLE = 0x01
FAULT_YAW_RATE = 0x02
FAULT_SPEED = 0x04

Q_LIMITED = "limited"
Q_STANDARD = "standard"
METHOD_TUSTIN = "tustin"
METHOD_ZOH = "zoh"

# Nominal vehicle of section 3 (mu_n = 1): the controller's own model of the car, from which
# K_n(v) of eq. (15) is scheduled.  A port calibrates these for its vehicle.
NOMINAL_L_F = 1.25
NOMINAL_L_R = 1.32
NOMINAL_MASS = 1296.0
NOMINAL_C_F = 84000.0
NOMINAL_C_R = 96000.0

#: tau_n of eq. (18), chosen to reproduce the paper's numbers (docs/paper-reproduction.md).
DEFAULT_TAU_N = 0.02
#: Longest command delay the nominal model can hold (size of the state's ring buffer).
MAX_MODEL_DELAY = 8
#: The paper's continuous-time tuning of eq. (22), section 4.
PAPER_K = 10.0
PAPER_TAU = 0.006
#: The auxiliary actuator's range, +- rad of front-wheel angle (paper, sec. 4.1: +-3 deg).
AUX_LIMIT = math.radians(3.0)


@dataclass(frozen=True)
class ControllerConfig:
    """Calibration of the model regulator. Angles in rad (front wheel), times in s."""

    # Shipped calibration: `mrsteer design tune --ts 0.002 --delay-steps 1` (K 43.57, tau
    # 21.25 ms), rounded; GM >= 6 dB and PM >= 45 deg over the envelope (docs/design.md).
    q_form: str = Q_LIMITED
    k: float = 43.0  # eq. (22) limited-integrator gain K
    tau: float = 0.0212  # eq. (22) time constant tau, s
    tau_n: float = DEFAULT_TAU_N  # eq. (18) desired-model time constant, s
    ts: float = 0.002  # fixed step, s: 500 Hz keeps a 500 kbit/s bus under 40 % worst-case load
    method: str = METHOD_TUSTIN
    aux_limit: float = AUX_LIMIT  # actuator range, +- rad of wheel angle
    rate_limit: float = 0.0  # max |d u/dt| in rad/s; 0 disables
    model_delay_steps: int = 1  # whole samples from command to effect, modelled in w (0: none)
    fade_rate: float = math.radians(6.0)  # rad/s toward 0 on fault/inactive, and on recovery
    speed_active_min: float = 3.0  # m/s; below this the controller is inactive
    speed_max: float = 70.0  # m/s; above this the speed input is invalid
    driver_angle_max: float = 0.7  # rad of front-wheel angle
    yaw_rate_max: float = 3.0  # rad/s
    nominal_l_f: float = NOMINAL_L_F
    nominal_l_r: float = NOMINAL_L_R
    nominal_mass: float = NOMINAL_MASS
    nominal_c_f: float = NOMINAL_C_F
    nominal_c_r: float = NOMINAL_C_R


@dataclass(frozen=True, slots=True)
class Coefficients:
    """Everything step() needs, computed once by configure()."""

    a: float  # pole of Q in z
    g_w0: float  # w = delta_d + u_a path (q0 * Q numerator)
    g_w1: float
    g_r0: float  # rho path (q0 * lead-lag numerator)
    g_r1: float
    q0: float  # d.c. gain of Q
    inv_one_minus_g_w0: float  # 1 / (1 - g_w0), algebraic loop of the Tustin form
    model_delay: int  # M: w uses the command issued M steps ago (0: this step's)
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


class State:
    """Preallocated controller state. ``needs_init`` forces a bumpless re-start."""

    __slots__ = ("z", "u_prev", "u_hist", "hist_idx", "needs_init", "recovering", "status", "fault_flags")

    def __init__(self) -> None:
        self.z = 0.0
        self.u_prev = 0.0
        self.u_hist = [0.0] * MAX_MODEL_DELAY  # ring buffer of the last M commands (C: float[8])
        self.hist_idx = 0
        self.needs_init = True
        self.recovering = False
        self.status = STATUS_INACTIVE
        self.fault_flags = 0


def q_filter(cfg: ControllerConfig) -> tuple[float, float]:
    """(q0, tau_Q) of Q(s) = q0 / (tau_Q s + 1): eq. (22) for limited, eq. (17) for standard."""
    tau_q = cfg.tau / (1.0 + cfg.k)
    q0 = cfg.k / (1.0 + cfg.k) if cfg.q_form == Q_LIMITED else 1.0
    return q0, tau_q


def configure(cfg: ControllerConfig) -> Coefficients:
    """Validate the calibration and compute the coefficients (the model_initialize step)."""
    _validate(cfg)
    q0, tau_q = q_filter(cfg)
    ts = cfg.ts
    if cfg.method == METHOD_TUSTIN:
        den = 2.0 * tau_q + ts
        a = (2.0 * tau_q - ts) / den
        bw0 = bw1 = ts / den
        br0 = (2.0 * cfg.tau_n + ts) / den
        br1 = (ts - 2.0 * cfg.tau_n) / den
    else:  # ZOH: Q -> (1-a)/(z-a); (tau_n s+1)/(tau_Q s+1) = c + (1-c) Q/q0 -> c + (1-c)(1-a)/(z-a)
        a = math.exp(-ts / tau_q)
        c = cfg.tau_n / tau_q
        bw0, bw1 = 0.0, 1.0 - a
        br0, br1 = c, 1.0 - a - c
    g_w0 = q0 * bw0
    l_f, l_r, m = cfg.nominal_l_f, cfg.nominal_l_r, cfg.nominal_mass
    c_f, c_r = cfg.nominal_c_f, cfg.nominal_c_r
    wheelbase = l_f + l_r
    # 1/K_n(v) = a0/b0 of eq. (14) at mu = 1: L/v + (c_r l_r - c_f l_f) m v / (c_f c_r L).
    k_us = (c_r * l_r - c_f * l_f) * m / (c_f * c_r * wheelbase)
    return Coefficients(
        a=a,
        g_w0=g_w0,
        g_w1=q0 * bw1,
        g_r0=q0 * br0,
        g_r1=q0 * br1,
        q0=q0,
        inv_one_minus_g_w0=1.0 / (1.0 - g_w0),
        model_delay=cfg.model_delay_steps,
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


def _validate(cfg: ControllerConfig) -> None:
    if cfg.q_form not in (Q_LIMITED, Q_STANDARD):
        raise ValueError(f"q_form must be '{Q_LIMITED}' or '{Q_STANDARD}', got {cfg.q_form!r}")
    if cfg.method not in (METHOD_TUSTIN, METHOD_ZOH):
        raise ValueError(f"method must be '{METHOD_TUSTIN}' or '{METHOD_ZOH}', got {cfg.method!r}")
    for name, value in vars(cfg).items():
        if isinstance(value, float | int) and not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value!r}")
    positive = ("k", "tau", "tau_n", "ts", "aux_limit", "fade_rate", "speed_active_min",
                "speed_max", "driver_angle_max", "yaw_rate_max", "nominal_l_f", "nominal_l_r",
                "nominal_mass", "nominal_c_f", "nominal_c_r")
    for name in positive:
        if getattr(cfg, name) <= 0.0:
            raise ValueError(f"{name} must be positive, got {getattr(cfg, name)}")
    if not (isinstance(cfg.model_delay_steps, int) and 0 <= cfg.model_delay_steps <= MAX_MODEL_DELAY):
        raise ValueError(f"model_delay_steps must be a whole number in 0..{MAX_MODEL_DELAY}, "
                         f"got {cfg.model_delay_steps!r}")
    if cfg.rate_limit < 0.0:
        raise ValueError(f"rate_limit must be >= 0 (0 disables), got {cfg.rate_limit}")
    if cfg.speed_active_min >= cfg.speed_max:
        raise ValueError("speed_active_min must be below speed_max")


def reset(s: State) -> None:
    """Back to power-on: command 0, state re-initialised on the next valid step."""
    s.z = 0.0
    s.u_prev = 0.0
    for i in range(MAX_MODEL_DELAY):
        s.u_hist[i] = 0.0
    s.hist_idx = 0
    s.needs_init = True
    s.recovering = False
    s.status = STATUS_INACTIVE
    s.fault_flags = 0


# One function on purpose (about 90 lines): it is the body that ports/c/mrs_controller.c's
# mrs_step() transcribes statement for statement, and a port's mrs_step makes no calls.
def step(c: Coefficients, s: State, delta_driver: float, yaw_rate: float, speed: float) -> float:
    """One control period. Returns the auxiliary front-wheel angle command in rad.

    Inputs: driver's front-wheel angle (rad), measured yaw rate (rad/s), speed (m/s).
    ``s.status`` and ``s.fault_flags`` tell what happened.  A NaN fails every range
    comparison below, so non-finite inputs are caught by the same checks.
    """
    flags = 0
    if not (-c.driver_angle_max <= delta_driver <= c.driver_angle_max):
        flags |= FAULT_DRIVER_ANGLE
    if not (-c.yaw_rate_max <= yaw_rate <= c.yaw_rate_max):
        flags |= FAULT_YAW_RATE
    if not (0.0 <= speed <= c.speed_max):
        flags |= FAULT_SPEED
    s.fault_flags = flags

    if flags != 0 or speed < c.speed_active_min:
        # Invalid input or too slow to schedule K_n(v): the state is not touched by the
        # inputs, the command fades to zero, and the next valid step re-initialises.
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

    inv_kn = c.wheelbase / speed + c.k_us * speed
    rho = inv_kn * yaw_rate  # yaw rate expressed as the wheel angle the nominal car needs for it

    if s.needs_init:
        # Start the filter at its steady state for the present inputs with the command held,
        # so a restart does not excite the large high-frequency gain on rho.
        w0 = delta_driver + s.u_prev
        s.z = c.q0 * (w0 - rho) - (c.g_w0 * w0 - c.g_r0 * rho)
        for i in range(c.model_delay):
            s.u_hist[i] = s.u_prev
        s.hist_idx = 0
        s.needs_init = False
        s.recovering = True

    # Admissible command window: actuator range, intersected with the slew window.
    du = c.du_max
    if s.recovering and c.fade_step < du:
        du = c.fade_step
    lo_slew = s.u_prev - du
    hi_slew = s.u_prev + du
    lo = lo_slew
    hi = hi_slew
    if lo < -c.u_max:
        lo = -c.u_max
    if hi > c.u_max:
        hi = c.u_max

    if c.model_delay == 0:
        # y = p + g_w0 * u_a with u_a = clamp(y, lo, hi): since 0 <= g_w0 < 1 the unique
        # solution is u_a = clamp(p / (1 - g_w0), lo, hi).
        p = c.g_w0 * delta_driver - c.g_r0 * rho + s.z
        u = p * c.inv_one_minus_g_w0
        if u < lo:
            u = lo
        elif u > hi:
            u = hi
        y = p + c.g_w0 * u
        w = delta_driver + u
    else:
        # The yaw rate measured now answers the command issued M steps ago: compare it
        # with that one, not with the command being computed (no algebraic loop either).
        i = s.hist_idx
        w = delta_driver + s.u_hist[i]
        y = c.g_w0 * w - c.g_r0 * rho + s.z
        u = y
        if u < lo:
            u = lo
        elif u > hi:
            u = hi
        s.u_hist[i] = u
        i += 1
        if i >= c.model_delay:
            i = 0
        s.hist_idx = i

    s.z = c.g_w1 * w - c.g_r1 * rho + c.a * y
    if s.recovering and lo_slew < u < hi_slew:
        s.recovering = False  # the slew no longer binds: caught up with the control law
    s.u_prev = u
    s.status = STATUS_SATURATED if (u >= c.u_max or u <= -c.u_max) else STATUS_ACTIVE
    return u


class ModelRegulator:
    """Convenience owner of one configured controller instance."""

    def __init__(self, config: ControllerConfig | None = None) -> None:
        self.config = config if config is not None else ControllerConfig()
        self.coefficients = configure(self.config)
        self.state = State()

    def step(self, delta_driver: float, yaw_rate: float, speed: float) -> float:
        return step(self.coefficients, self.state, delta_driver, yaw_rate, speed)

    def reset(self) -> None:
        reset(self.state)
