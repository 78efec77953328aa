"""Closed loop of the single-track model with the model regulator (paper Figure 6).

Two solvers of the same experiment (driver's front-wheel angle and yaw moment stepped at t = 0
from rest, speed constant):

* ``simulate_continuous`` -- the paper's reference: the continuous-time controller of
  eqs. (6), (17)/(22), (18) with the actuator limit.  Between saturation events the loop is
  LTI, so it is propagated exactly with the matrix exponential; the instants where the
  command reaches or leaves the limit are located by bisection on the exact solution.
* ``simulate_discrete`` -- the *firmware's own* ``step()`` at a fixed step ``ts`` against
  the exactly (ZOH) discretised plant, with ``delay_steps`` samples between measurement
  and applied command; or against the nonlinear car of the bus runs (``plants.Car``:
  magic-formula tyres, the speed a state), stepped as the plant node steps it.

``discrete_loop_poles`` (``discrete_loop``, re-exported here) and ``continuous_loop_poles``
give the linear (unsaturated) loop's poles, from which the ``stable`` verdicts come.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from firmware_py import model_regulator as mr
from sim_plant.car.actuator_dynamics import PositionActuator
from sim_plant.car.plants import LINEAR, NONLINEAR, PLANTS, Car
from sim_plant.car.nonlinear import spun, wrap_angle
from sim_plant.car.sensors import SensorConfig, Sensors
from sim_plant.car.vehicle import VehicleParams, state_space, zoh_discretize
from sim_plant.offline.discrete_loop import IDEAL, discrete_loop_matrix, discrete_loop_poles, inverse_kn
from sim_plant.offline.loop_plant import LoopModels, sampled_plant


# scipy.linalg on first use, not at import: the command line imports this module for its names
# (see sim_plant.car.vehicle.zoh_discretize).
def expm(a: np.ndarray) -> np.ndarray:
    from scipy.linalg import expm as scipy_expm

    return scipy_expm(a)


__all__ = ["CONTROLLERS", "Experiment", "Trace", "continuous_loop_poles", "discrete_loop_matrix",
           "discrete_loop_poles", "inverse_nominal_gain", "simulate_continuous", "simulate_discrete"]

CONTROLLERS = ("none", mr.Q_STANDARD, mr.Q_LIMITED)

_CONTINUOUS_DT = 5e-5  # output grid of the continuous reference, s
_BLOCK = 200  # grid points propagated at once between event checks


@dataclass(frozen=True)
class Experiment:
    """A step experiment: what is applied at t = 0 and how long to watch."""

    params: VehicleParams
    controller: str = mr.Q_LIMITED
    config: mr.ControllerConfig = mr.ControllerConfig()
    m_z: float = 0.0  # yaw moment step, Nm
    delta_driver: float = 0.0  # driver's front-wheel angle step, rad
    duration: float = 3.0
    saturate: bool = True  # False: no actuator limit (continuous reference only), as in the paper's linear runs

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}; got {self.controller!r}")
        for name in ("m_z", "delta_driver", "duration"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite")
        if self.duration <= 0.0:
            raise ValueError(f"duration must be positive, got {self.duration}")


@dataclass(frozen=True)
class Trace:
    """Time histories: t (s), yaw rate r (rad/s), side-slip beta (rad), lateral acceleration
    a_y (m/s^2), auxiliary steering command aux (rad), and whether it was saturated."""

    t: np.ndarray
    yaw_rate: np.ndarray
    beta: np.ndarray
    lat_accel: np.ndarray
    aux: np.ndarray
    saturated: bool
    stable: bool | None
    applied: np.ndarray | None = None  # the angle the actuator applied (rad); None: the command itself
    plant: str = LINEAR  # the car: ``plants.LINEAR`` or ``plants.NONLINEAR``
    speed: np.ndarray | None = None  # the nonlinear car's speed (m/s); None: constant, the experiment's
    spin_time: float | None = None  # s: the nonlinear car spun (``nonlinear.spun``) and the run ended there

    def applied_summary(self) -> dict[str, float]:
        """Peak and final applied auxiliary angle (deg), beside the command's in ``summary``."""
        applied = self.aux if self.applied is None else self.applied
        return {"peak_applied_aux_deg": math.degrees(float(np.max(np.abs(applied)))),
                "final_applied_aux_deg": math.degrees(float(applied[-1]))}

    def summary(self) -> dict[str, float | bool | None]:
        """The run's figures; ``stable`` is None on the nonlinear car (the poles are the linear loop's)."""
        return {
            "peak_aux_steer_deg": math.degrees(float(np.max(np.abs(self.aux)))),
            "final_aux_steer_deg": math.degrees(float(self.aux[-1])),
            "peak_yaw_rate_rad_s": float(np.max(np.abs(self.yaw_rate))),
            "final_yaw_rate_rad_s": float(self.yaw_rate[-1]),
            "saturated": bool(self.saturated),
            "stable": None if self.stable is None else bool(self.stable),
        }

    def car_summary(self) -> dict[str, float | str]:
        """Which car ran, and on the nonlinear one what the tyres did: the peak side slip (wrapped
        to +-180 deg), the final speed, and whether the car spun (its side slip past
        ``nonlinear.SPIN_SIDE_SLIP``, where the run ended: the figures are those up to it, as a
        campaign's)."""
        out: dict[str, float | str | bool | None] = {"plant": self.plant}
        if self.plant == NONLINEAR:
            out["peak_side_slip_deg"] = math.degrees(float(np.max(np.abs(wrap_angle(self.beta)))))
            out["final_speed_m_s"] = float(self.speed[-1]) if self.speed is not None else math.nan
            out["spun"] = self.spin_time is not None
            out["spin_time_s"] = self.spin_time
        return out


def inverse_nominal_gain(cfg: mr.ControllerConfig, v: float) -> float:
    """1 / K_n(v) exactly as the firmware schedules it (eq. 15 of its nominal car)."""
    return inverse_kn(mr.configure(cfg), v)


# --------------------------------------------------------------------------- continuous


def _continuous_matrices(exp: Experiment) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Closed loop as Z' = M_mode Z with Z = [beta, r, x_c, 1] (inputs folded in).

    Controller realisation: delta_mr = q0 x_c - q0 c rho with
    tau_Q x_c' = -x_c + (delta_d + u_a) - (1 - c) rho,  c = tau_n / tau_Q,  rho = r / K_n(v).
    Returns (M_linear, M_saturated_without_u, column_of_u, q0*c*invKn) so that the saturated
    modes are M_sat + s * U * col.
    """
    ss = state_space(exp.params)
    A, B = ss.A, ss.B
    cfg = exp.config
    if cfg.scheduled or cfg.model_actuator_tau > 0.0 or cfg.model_filter_hz > 0.0:
        raise ValueError("the continuous reference runs the paper's plain law with constant gains (give --k, "
                         "--tau, --tau-n); give --ts T > 0 to run the firmware's law")
    q0, tau_q = mr.q_filter(cfg.q_form, cfg.k, cfg.tau)
    c = cfg.tau_n / tau_q
    ikn = inverse_nominal_gain(cfg, exp.params.v)
    const = np.zeros(4)
    const[:2] = B[:, 0] * exp.delta_driver + B[:, 1] * exp.m_z
    const[2] = exp.delta_driver / tau_q
    base = np.zeros((4, 4))
    base[:2, :2] = A
    base[2, 1] = -(1.0 - c) * ikn / tau_q
    base[2, 2] = -1.0 / tau_q
    base[:, 3] = const
    col_u = np.zeros(4)  # where u_a enters: the plant's steering input and the Q filter
    col_u[:2] = B[:, 0]
    col_u[2] = 1.0 / tau_q
    y_row = np.array([0.0, -q0 * c * ikn, q0, 0.0])  # controller output y = y_row @ Z
    linear = base + np.outer(col_u, y_row)
    return linear, base, col_u, y_row


def continuous_loop_poles(exp: Experiment) -> np.ndarray:
    if exp.controller == "none":
        return np.linalg.eigvals(state_space(exp.params).A)
    linear, _, _, _ = _continuous_matrices(exp)
    return np.linalg.eigvals(linear[:3, :3])


def simulate_continuous(exp: Experiment) -> Trace:
    """Exact piecewise-LTI solution of the continuous closed loop with saturation."""
    n = int(round(exp.duration / _CONTINUOUS_DT)) + 1
    t = np.arange(n) * _CONTINUOUS_DT
    ss = state_space(exp.params)
    if exp.controller == "none":
        linear = np.zeros((4, 4))
        linear[:2, :2] = ss.A
        linear[:2, 3] = ss.B[:, 0] * exp.delta_driver + ss.B[:, 1] * exp.m_z
        modes = {0: linear}
        y_row = np.zeros(4)
        limit = math.inf
        stable = bool(np.all(np.linalg.eigvals(ss.A).real < 0))
    else:
        linear, base, col_u, y_row = _continuous_matrices(exp)
        limit = exp.config.aux_limit if exp.saturate else math.inf
        modes = {0: linear}
        if math.isfinite(limit):
            # Saturated: u_a = +-U is a constant, i.e. a column on the constant state Z[3] = 1.
            modes[1] = base + np.outer(col_u, np.eye(4)[3]) * limit
            modes[-1] = base - np.outer(col_u, np.eye(4)[3]) * limit
        stable = bool(np.all(np.linalg.eigvals(linear[:3, :3]).real < 0))

    # Powers Phi^1..Phi^BLOCK of each mode's one-grid-step transition, for block propagation.
    powers = {m: _power_stack(expm(M * _CONTINUOUS_DT), _BLOCK) for m, M in modes.items()}
    Z = np.zeros((n, 4))
    Z[0, 3] = 1.0
    mode = 0
    saturated = False
    k = 0
    while k < n - 1:
        nb = min(_BLOCK, n - 1 - k)
        block = powers[mode][:nb] @ Z[k]
        y = block @ y_row
        bad = np.flatnonzero(np.abs(y) > limit) if mode == 0 else np.flatnonzero(mode * y < limit)
        if bad.size == 0:
            Z[k + 1:k + 1 + nb] = block
            k += nb
            continue
        j = int(bad[0])
        Z[k + 1:k + 1 + j] = block[:j]
        k += j
        # The event lies in (t_k, t_k + dt]: find it, switch, and finish the grid step.
        new_mode = (1 if y[j] > 0 else -1) if mode == 0 else 0
        h = _bisect_event(modes[mode], Z[k], y_row, limit, mode)
        z_event = expm(modes[mode] * h) @ Z[k]
        Z[k + 1] = expm(modes[new_mode] * (_CONTINUOUS_DT - h)) @ z_event
        mode = new_mode
        saturated = saturated or mode != 0
        k += 1

    y = Z @ y_row
    aux = np.clip(y, -limit, limit) if exp.controller != "none" else np.zeros(n)
    delta_f = exp.delta_driver + aux
    out = ss.C @ Z[:, :2].T + ss.D @ np.vstack([delta_f, np.full(n, exp.m_z)])
    return Trace(t, out[0], out[1], out[2], aux, saturated, stable)


def _power_stack(phi: np.ndarray, count: int) -> np.ndarray:
    stack = np.empty((count, *phi.shape))
    acc = np.eye(phi.shape[0])
    for i in range(count):
        acc = phi @ acc
        stack[i] = acc
    return stack


def _bisect_event(M: np.ndarray, z0: np.ndarray, y_row: np.ndarray, limit: float, mode: int) -> float:
    """Time in (0, dt] at which the mode's guard is first crossed (40 halvings: < 1e-16 s)."""

    def violated(h: float) -> bool:
        y = y_row @ (expm(M * h) @ z0)
        return abs(y) > limit if mode == 0 else mode * y < limit

    lo, hi = 0.0, _CONTINUOUS_DT
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if violated(mid):
            hi = mid
        else:
            lo = mid
    return hi


# ----------------------------------------------------------------------------- discrete


def simulate_discrete(exp: Experiment, ts: float, delay_steps: int = 1, models: LoopModels = IDEAL,
                      plant: str = LINEAR) -> Trace:
    """The firmware's step() in closed loop with the exactly discretised plant, or with the
    nonlinear car (``plant``).

    At sample k the sensors read the plant (``Sensors``: exact for ideal sensors), the firmware
    computes a command, and that command reaches the actuator ``delay_steps`` samples later;
    the actuator (``PositionActuator``: its dead time, range, lag and rate limit; ideal = the
    command clamped to its range) gives the angle the car gets over that sample.
    """
    if not (math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"ts must be positive and finite, got {ts!r}")
    if delay_steps < 0:
        raise ValueError(f"delay_steps must be >= 0, got {delay_steps}")
    if not exp.saturate:
        raise ValueError("the firmware always applies its actuator limit; saturate=False is continuous-only")
    if plant not in PLANTS:
        raise ValueError(f"plant must be one of {', '.join(PLANTS)}, got {plant!r}")
    car = _CarStep(exp, ts, models) if plant == LINEAR else _NonlinearCarStep(exp, ts, models)
    sensors = Sensors(models.sensors, ts)

    use_controller = exp.controller != "none"
    if use_controller:
        cfg = replace(exp.config, q_form=exp.controller, ts=ts)
        coeffs = mr.configure(cfg)
        state = mr.State()
        # At rest before t = 0, as the continuous reference is: one sample with zero inputs
        # takes the firmware out of its power-on (inactive) state without a command.
        mr.step(coeffs, state, 0.0, 0.0, exp.params.v)
    n = int(round(exp.duration / ts)) + 1
    hist = {key: np.empty(n) for key in ("beta", "r", "aux", "applied", "a_y", "v")}
    pipeline: deque[float] = deque([0.0] * (delay_steps + models.actuator.dead_time_samples))
    dd = exp.delta_driver
    saturated = False
    spin_time = None
    for k in range(n):
        hist["beta"][k], hist["r"][k], hist["v"][k] = car.beta, car.r, car.v
        if spin_time is None and plant != LINEAR and spun(car.beta):
            spin_time = k * ts  # the car left the tyre model's validity: this step is the run's last
        if use_controller:
            u = mr.step(coeffs, state, sensors.steer(dd), sensors.yaw_rate(car.r), sensors.speed(car.v))
            saturated = saturated or state.status == mr.STATUS_SATURATED
        else:
            u = 0.0
        hist["aux"][k] = u
        pipeline.append(u)
        hist["applied"][k] = car.step(pipeline.popleft())
        hist["a_y"][k] = car.a_y
        if spin_time is not None:
            n = k + 1
            hist = {key: values[:n] for key, values in hist.items()}
            break
    t = np.arange(n) * ts
    if plant == LINEAR:
        ss = state_space(exp.params)
        out = ss.C @ np.vstack([hist["beta"], hist["r"]]) + ss.D @ np.vstack([dd + hist["applied"],
                                                                             np.full(n, exp.m_z)])
        hist["a_y"] = out[2]
    stable = _linear_loop_stable(exp, ts, delay_steps, models, coeffs if use_controller else None) \
        if plant == LINEAR else None
    return Trace(t, hist["r"], hist["beta"], hist["a_y"], hist["aux"], saturated, stable, hist["applied"], plant,
                 None if plant == LINEAR else hist["v"], spin_time)


def _linear_loop_stable(exp: Experiment, ts: float, delay_steps: int, models: LoopModels,
                        coeffs: mr.Coefficients | None) -> bool:
    """Whether the linear (unsaturated) loop's poles are inside the unit circle."""
    if coeffs is not None:
        poles = discrete_loop_poles(exp.params, coeffs, delay_steps, models=models)
    else:
        ss = state_space(exp.params)
        poles = np.linalg.eigvals(zoh_discretize(ss.A, ss.B, ts)[0])
    return bool(np.all(np.abs(poles) < 1.0))


class _CarStep:
    """The car (and actuator) over one sample of the firmware's loop.

    Ideal actuator: the command clamped to the range (``PositionActuator``) steers the ZOH car,
    today's arithmetic exactly.  Otherwise the car and the actuator's linear response are the
    exact ZOH cascade of ``loop_plant`` (the car sees the position move within the sample), and
    the position is then taken from ``PositionActuator`` (range, rate limit, end stop), so the
    limits hold; within a sample where the rate limit acts, the car sees the linear response.
    The actuator's dead time is in the caller's queue.
    """

    def __init__(self, exp: Experiment, ts: float, models: LoopModels) -> None:
        act = replace(models.actuator, dead_time_samples=0)
        self.actuator = PositionActuator(act, ts)
        self.order = act.order
        self.dd = exp.delta_driver
        self.beta = self.r = 0.0
        self.v = exp.params.v
        self.a_y = math.nan  # the caller computes the linear car's a_y from its states, vectorised
        if self.order == 0:
            ss = state_space(exp.params)
            phi, gamma = zoh_discretize(ss.A, ss.B, ts)
            self._p = (phi[0, 0], phi[0, 1], phi[1, 0], phi[1, 1])
            self._g = (gamma[0, 0], gamma[1, 0], gamma[0, 1] * exp.m_z, gamma[1, 1] * exp.m_z)
        else:
            plant = sampled_plant(exp.params, ts, LoopModels(act, SensorConfig.ideal()))
            self._a, self._b = plant.a, plant.b
            self._const = plant.g * exp.m_z + plant.g_driver * exp.delta_driver  # both steps held
            self._x = np.zeros(plant.order)

    def step(self, command: float) -> float:
        """The command reaching the actuator this sample; returns the applied angle at its start."""
        if self.order == 0:
            applied = self.actuator.step(command)
            p00, p01, p10, p11 = self._p
            gd0, gd1, gm0, gm1 = self._g
            d = self.dd + applied
            self.beta, self.r = (p00 * self.beta + p01 * self.r + gd0 * d + gm0,
                                 p10 * self.beta + p11 * self.r + gd1 * d + gm1)
            return applied
        x = self._x
        applied = float(x[2])
        lim = self.actuator.limit
        held = min(lim, max(-lim, command))
        x = self._a @ x + self._b * held + self._const
        x[2] = self.actuator.step(command)
        self._x = x
        self.beta, self.r = float(x[0]), float(x[1])
        return applied


class _NonlinearCarStep:
    """The nonlinear car (``plants.Car``) and the actuator over one sample, as the plant node
    steps them (``sim_plant.nodes.plant.PlantNode.step``): the outputs at the position as the
    sample begins, then ``PositionActuator`` moves and the car advances with its mean position
    over the sample (the ideal actuator: the clamped command itself).  The actuator's dead
    time is in the caller's queue."""

    def __init__(self, exp: Experiment, ts: float, models: LoopModels) -> None:
        self.car = Car(NONLINEAR, exp.params, ts)
        self.actuator = PositionActuator(replace(models.actuator, dead_time_samples=0), ts)
        self.ideal = models.actuator.order == 0
        self.dd, self.m_z = exp.delta_driver, exp.m_z
        self.beta = self.r = self.a_y = 0.0
        self.v = self.car.v

    def step(self, command: float) -> float:
        """The command reaching the actuator this sample; returns the applied angle at its start."""
        act = self.actuator
        if self.ideal:
            act.step(command)
        applied = act.position
        self.a_y = float(self.car.outputs(self.dd + applied, self.m_z)[2])
        if not self.ideal:
            act.step(command)
        self.car.advance(self.dd + act.mean, self.m_z)
        self.beta, self.r = (float(x) for x in self.car.x)
        self.v = self.car.v
        return applied
