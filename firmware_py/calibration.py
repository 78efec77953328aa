"""The model regulator's calibration: what an ECU holds in flash, and the checks on it.

``ControllerConfig`` is read by ``model_regulator.configure()``, which turns it into the
coefficients ``step()`` runs on.  Standard library only, like the porting reference itself.

The shipped calibration (issue 15, docs/design.md) is designed on the *reference loop*: 500 Hz,
one sample of loop delay, the paper's car, a first-order 20 ms actuator within +-3 deg and a
2nd-order 30 Hz Butterworth low-pass on the measured yaw rate.  Its nominal model holds that
actuator and that filter (``model_actuator_tau``, ``model_filter_hz``), and K, tau and tau_n of
eqs. (18) and (22) are scheduled over speed (``schedule_*``): the coefficient sets are computed
at the breakpoints here, once, and ``step()`` interpolates them linearly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

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

#: tau_n of eq. (18) that reproduces the paper's numbers (docs/paper-reproduction.md).
DEFAULT_TAU_N = 0.02
#: Longest command delay the nominal model can hold (size of the state's ring buffer).
MAX_MODEL_DELAY = 8
#: Most speed breakpoints a schedule can have (size of the coefficient tables).
MAX_SCHEDULE = 8
#: The control period of the shipped calibration, s: the law's, the monitor's and the limiter's step.
SHIPPED_TS = 0.002
#: The paper's continuous-time tuning of eq. (22), section 4.
PAPER_K = 10.0
PAPER_TAU = 0.006
#: The auxiliary actuator's range, +- rad of front-wheel angle (paper, sec. 4.1: +-3 deg).
AUX_LIMIT = math.radians(3.0)

#: The shipped schedule (docs/design.md, "The shipped law"): speed breakpoints in m/s, and
#: K, tau = tau_Q (1 + K) of eq. (22) and tau_n of eq. (18) at each.  The search that found it
#: worked in tau_Q (4.8, 9.0, 5.6, 13.6, 12.8, 14.1 ms).
SHIPPED_SPEED = (5.0, 10.0, 20.0, 30.0, 40.0, 50.0)
SHIPPED_K = (10.4, 27.0, 10.0, 10.0, 6.3, 4.5)
SHIPPED_TAU = (0.05472, 0.252, 0.0616, 0.1496, 0.09344, 0.07755)
SHIPPED_TAU_N = (0.034, 0.089, 0.12, 0.255, 0.275, 0.305)
#: The nominal actuator and yaw-rate filter of the shipped law: the reference loop's.
SHIPPED_MODEL_ACTUATOR_TAU = 0.020
SHIPPED_MODEL_FILTER_HZ = 30.0


@dataclass(frozen=True)
class ControllerConfig:
    """Calibration of the model regulator. Angles in rad (front wheel), times in s.

    The gains are either a speed schedule (``schedule_speed`` and the three ``schedule_*``
    tables of the same length) or constant (``k``, ``tau``, ``tau_n``, with the schedule
    empty); giving both is an error, so a constant gain cannot be silently overridden.
    ``constant_gains()`` turns any calibration into a constant-gain one.
    """

    q_form: str = Q_LIMITED
    k: float | None = None  # eq. (22) limited-integrator gain K (constant law)
    tau: float | None = None  # eq. (22) time constant tau, s (constant law)
    tau_n: float | None = None  # eq. (18) desired-model time constant, s (constant law)
    schedule_speed: tuple[float, ...] = SHIPPED_SPEED  # breakpoints, m/s, ascending
    schedule_k: tuple[float, ...] = SHIPPED_K
    schedule_tau: tuple[float, ...] = SHIPPED_TAU
    schedule_tau_n: tuple[float, ...] = SHIPPED_TAU_N
    model_actuator_tau: float = SHIPPED_MODEL_ACTUATOR_TAU  # nominal actuator lag, s (0: none)
    model_filter_hz: float = SHIPPED_MODEL_FILTER_HZ  # nominal yaw-rate low-pass, Hz (0: none)
    ts: float = SHIPPED_TS  # fixed step, s: 500 Hz keeps a 500 kbit/s bus under 40 % worst-case load
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

    @property
    def scheduled(self) -> bool:
        return len(self.schedule_speed) > 0

    def gain_points(self) -> tuple[tuple[float, float, float], ...]:
        """(K, tau, tau_n) at each breakpoint; one point for a constant law."""
        if self.scheduled:
            return tuple(zip(self.schedule_k, self.schedule_tau, self.schedule_tau_n))
        return ((self.k, self.tau, self.tau_n),)  # type: ignore[return-value]


def constant_gains(cfg: ControllerConfig, k: float, tau: float, tau_n: float) -> ControllerConfig:
    """``cfg`` with one K, tau, tau_n at every speed (the schedule removed)."""
    return replace(cfg, k=k, tau=tau, tau_n=tau_n, schedule_speed=(), schedule_k=(), schedule_tau=(),
                   schedule_tau_n=())


def plain_law(cfg: ControllerConfig, k: float, tau: float, tau_n: float) -> ControllerConfig:
    """The law of the paper's Figure 6 with constant gains: no actuator or filter in the
    nominal model (what gains given by hand, such as the paper's, were designed for)."""
    return replace(constant_gains(cfg, k, tau, tau_n), model_actuator_tau=0.0, model_filter_hz=0.0)


def describe_gains(cfg: ControllerConfig) -> dict[str, object]:
    """The law's gains for a summary: the schedule or the constant K, tau, tau_n."""
    out: dict[str, object] = {"q_form": cfg.q_form, "model_delay_steps": cfg.model_delay_steps,
                              "model_actuator_tau_s": cfg.model_actuator_tau, "model_filter_hz": cfg.model_filter_hz}
    if cfg.scheduled:
        out["schedule"] = {"speed_m_s": list(cfg.schedule_speed), "k": list(cfg.schedule_k),
                           "tau_s": list(cfg.schedule_tau), "tau_n_s": list(cfg.schedule_tau_n)}
    else:
        out.update(k=cfg.k, tau=cfg.tau, tau_n=cfg.tau_n)
    return out


def format_gains(desc: Mapping[str, object]) -> str:
    """``describe_gains``' dict (or a summary holding its keys) in words, for a printed table:
    the schedule breakpoint by breakpoint or the constant K, tau, tau_n, and the nominal
    actuator and filter where the law models them."""

    def ms(values: object) -> str:
        return "/".join(f"{1e3 * x:.4g}" for x in values)  # type: ignore[attr-defined]

    sched = desc.get("schedule")
    if isinstance(sched, Mapping):
        text = (f"scheduled over v {'/'.join(f'{x:g}' for x in sched['speed_m_s'])} m/s: "
                f"K {'/'.join(f'{x:.4g}' for x in sched['k'])}, tau {ms(sched['tau_s'])} ms, "
                f"tau_n {ms(sched['tau_n_s'])} ms")
    else:
        text = f"K {desc['k']:.4g}, tau {ms((desc['tau'],))} ms, tau_n {ms((desc['tau_n'],))} ms"
    nominal = [f"actuator {ms((desc['model_actuator_tau_s'],))} ms"] if desc.get("model_actuator_tau_s") else []
    nominal += [f"filter {desc['model_filter_hz']:g} Hz"] if desc.get("model_filter_hz") else []
    return text + (f"; nominal {', '.join(nominal)}" if nominal else "")


#: The calibration shipped before issue 15 (tuned on the ideal loop; unstable on the reference loop).
PREVIOUS_CONFIG = plain_law(ControllerConfig(), 43.0, 0.0212, DEFAULT_TAU_N)
#: The paper's tuning as the firmware runs it at 1 kHz without modelled delay (docs/paper-reproduction.md).
PAPER_CONFIG = replace(plain_law(ControllerConfig(), PAPER_K, PAPER_TAU, DEFAULT_TAU_N), ts=0.001,
                       model_delay_steps=0)


def _tuned(rate_hz: float, k: float, tau: float, tau_n: float) -> ControllerConfig:
    return replace(plain_law(ControllerConfig(), k, tau, tau_n), ts=1.0 / rate_hz, model_delay_steps=1)


#: The calibration of each control rate that has one (Hz: calibration): the shipped one at
#: 500 Hz; at the other rates the paper's plain law tuned for that rate on the ideal loop
#: (docs/design.md, `mrsteer design tune --ts T`: 6 dB / 45 deg over the envelope, one sample
#: modelled).  A command given no calibration runs at one of these rates or refuses
#: (``firmware_py.controller.options.calibration_for_rate``).
RATE_CALIBRATIONS: dict[float, ControllerConfig] = {
    1000.0: _tuned(1000.0, 50.0, 0.012, 0.02),
    500.0: ControllerConfig(),
    200.0: _tuned(200.0, 14.2, 0.0161, 0.02),
    100.0: _tuned(100.0, 4.52, 0.0075, 0.02),
}


_POSITIVE = ("ts", "aux_limit", "fade_rate", "speed_active_min", "speed_max", "driver_angle_max",
             "yaw_rate_max", "nominal_l_f", "nominal_l_r", "nominal_mass", "nominal_c_f", "nominal_c_r")


def validate(cfg: ControllerConfig) -> None:
    """Raise ValueError naming the first field that is out of range."""
    if cfg.q_form not in (Q_LIMITED, Q_STANDARD):
        raise ValueError(f"q_form must be '{Q_LIMITED}' or '{Q_STANDARD}', got {cfg.q_form!r}")
    if cfg.method not in (METHOD_TUSTIN, METHOD_ZOH):
        raise ValueError(f"method must be '{METHOD_TUSTIN}' or '{METHOD_ZOH}', got {cfg.method!r}")
    _validate_numbers(cfg)
    for name in _POSITIVE:
        if getattr(cfg, name) <= 0.0:
            raise ValueError(f"{name} must be positive, got {getattr(cfg, name)}")
    _validate_gains(cfg)
    _validate_model(cfg)
    if cfg.speed_active_min >= cfg.speed_max:
        raise ValueError("speed_active_min must be below speed_max")


def _validate_numbers(cfg: ControllerConfig) -> None:
    """Every field a finite number (or a string or None where the field is one)."""
    for name, value in vars(cfg).items():
        values = value if isinstance(value, tuple) else (value,)
        for x in values:
            if isinstance(x, bool) or not isinstance(x, float | int | str | None):
                raise ValueError(f"{name} must be a number, got {x!r}")
            if isinstance(x, float | int) and not math.isfinite(x):
                raise ValueError(f"{name} must be finite, got {value!r}")


def _validate_model(cfg: ControllerConfig) -> None:
    """The law's internal model: its delay, actuator lag, sensor filter and rate limit."""
    if not (isinstance(cfg.model_delay_steps, int) and 0 <= cfg.model_delay_steps <= MAX_MODEL_DELAY):
        raise ValueError(f"model_delay_steps must be a whole number in 0..{MAX_MODEL_DELAY}, "
                         f"got {cfg.model_delay_steps!r}")
    for name in ("model_actuator_tau", "model_filter_hz", "rate_limit"):
        if getattr(cfg, name) < 0.0:
            raise ValueError(f"{name} must be >= 0 (0 disables), got {getattr(cfg, name)}")
    if cfg.model_filter_hz >= 0.5 / cfg.ts:
        raise ValueError(f"model_filter_hz must be below the Nyquist frequency {0.5 / cfg.ts:g} Hz, "
                         f"got {cfg.model_filter_hz}")
    extended = cfg.scheduled or cfg.model_actuator_tau > 0.0 or cfg.model_filter_hz > 0.0
    if extended and cfg.model_delay_steps == 0:
        # w must depend on past commands only: with M = 0 these would close an algebraic loop
        # that step() does not solve.
        raise ValueError("a gain schedule, model_actuator_tau or model_filter_hz needs model_delay_steps >= 1")


def _validate_gains(cfg: ControllerConfig) -> None:
    constant = (cfg.k, cfg.tau, cfg.tau_n)
    if cfg.scheduled:
        if any(x is not None for x in constant):
            raise ValueError("give either a gain schedule or constant k, tau, tau_n, not both "
                             "(constant_gains() removes the schedule)")
        _validate_schedule(cfg)
    else:
        if any(x is None for x in constant):
            raise ValueError("without a gain schedule, k, tau and tau_n must all be given")
        if any(len(getattr(cfg, name)) for name in ("schedule_k", "schedule_tau", "schedule_tau_n")):
            raise ValueError("schedule_k, schedule_tau and schedule_tau_n need schedule_speed")
    for k, tau, tau_n in cfg.gain_points():
        for name, x in (("k", k), ("tau", tau), ("tau_n", tau_n)):
            if x <= 0.0:
                raise ValueError(f"{name} must be positive, got {x}")


def _validate_schedule(cfg: ControllerConfig) -> None:
    """A gain schedule: at most MAX_SCHEDULE breakpoints, one gain of each per breakpoint, the
    speeds positive and strictly ascending."""
    n = len(cfg.schedule_speed)
    if n > MAX_SCHEDULE:
        raise ValueError(f"schedule_speed has {n} breakpoints, at most {MAX_SCHEDULE}")
    for name in ("schedule_k", "schedule_tau", "schedule_tau_n"):
        if len(getattr(cfg, name)) != n:
            raise ValueError(f"{name} must have one value per breakpoint ({n}), got {len(getattr(cfg, name))}")
    v = cfg.schedule_speed
    if any(b <= a for a, b in zip(v, v[1:])) or v[0] <= 0.0:
        raise ValueError(f"schedule_speed must be positive and strictly ascending, got {v}")
