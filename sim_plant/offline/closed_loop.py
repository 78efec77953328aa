"""Closed loop of the single-track model with the model regulator (paper Figure 6).

Two solvers of the same experiment (driver's front-wheel angle and yaw moment stepped at t = 0
from rest, speed constant):

* ``simulate_continuous`` -- the paper's reference: the continuous-time controller of
  eqs. (6), (17)/(22), (18) with the actuator limit.  Between saturation events the loop is
  LTI, so it is propagated exactly with the matrix exponential; the instants where the
  command reaches or leaves the limit are located by bisection on the exact solution.
* ``simulate_discrete`` -- the *firmware's own* ``step()`` at a fixed step ``ts`` against
  the exactly (ZOH) discretised plant, with ``delay_steps`` samples between measurement
  and applied command.

``discrete_loop_poles`` and ``continuous_loop_poles`` give the linear (unsaturated) loop's
poles, from which the ``stable`` verdicts come.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import expm

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import VehicleParams, state_space, zoh_discretize

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
    stable: bool

    def summary(self) -> dict[str, float | bool]:
        return {
            "peak_aux_steer_deg": math.degrees(float(np.max(np.abs(self.aux)))),
            "final_aux_steer_deg": math.degrees(float(self.aux[-1])),
            "peak_yaw_rate_rad_s": float(np.max(np.abs(self.yaw_rate))),
            "final_yaw_rate_rad_s": float(self.yaw_rate[-1]),
            "saturated": bool(self.saturated),
            "stable": bool(self.stable),
        }


def inverse_nominal_gain(cfg: mr.ControllerConfig, v: float) -> float:
    """1 / K_n(v) exactly as the firmware schedules it (eq. 15 of its nominal car)."""
    coeffs = mr.configure(cfg)
    return coeffs.wheelbase / v + coeffs.k_us * v


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
    q0, tau_q = mr.q_filter(cfg)
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


def simulate_discrete(exp: Experiment, ts: float, delay_steps: int = 1) -> Trace:
    """The firmware's step() in closed loop with the exactly discretised plant.

    At sample k the sensors read the plant, the firmware computes a command, and that command
    reaches the wheels ``delay_steps`` samples later, held for one sample.
    """
    if not (math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"ts must be positive and finite, got {ts!r}")
    if delay_steps < 0:
        raise ValueError(f"delay_steps must be >= 0, got {delay_steps}")
    if not exp.saturate:
        raise ValueError("the firmware always applies its actuator limit; saturate=False is continuous-only")
    ss = state_space(exp.params)
    phi, gamma = zoh_discretize(ss.A, ss.B, ts)
    p00, p01, p10, p11 = phi[0, 0], phi[0, 1], phi[1, 0], phi[1, 1]
    gm0 = gamma[0, 1] * exp.m_z
    gm1 = gamma[1, 1] * exp.m_z
    gd0, gd1 = gamma[0, 0], gamma[1, 0]

    use_controller = exp.controller != "none"
    if use_controller:
        cfg = replace(exp.config, q_form=exp.controller, ts=ts)
        coeffs = mr.configure(cfg)
        state = mr.State()
        # At rest before t = 0, as the continuous reference is: one sample with zero inputs
        # takes the firmware out of its power-on (inactive) state without a command.
        mr.step(coeffs, state, 0.0, 0.0, exp.params.v)
    n = int(round(exp.duration / ts)) + 1
    beta_hist = np.empty(n)
    r_hist = np.empty(n)
    aux_hist = np.empty(n)
    applied_hist = np.empty(n)
    pipeline: deque[float] = deque([0.0] * delay_steps)
    beta = r = 0.0
    v = exp.params.v
    dd = exp.delta_driver
    saturated = False
    for k in range(n):
        beta_hist[k] = beta
        r_hist[k] = r
        if use_controller:
            u = mr.step(coeffs, state, dd, r, v)
            saturated = saturated or state.status == mr.STATUS_SATURATED
        else:
            u = 0.0
        aux_hist[k] = u
        pipeline.append(u)
        applied = pipeline.popleft()
        applied_hist[k] = applied
        d = dd + applied
        beta, r = (p00 * beta + p01 * r + gd0 * d + gm0,
                   p10 * beta + p11 * r + gd1 * d + gm1)
    t = np.arange(n) * ts
    delta_f = dd + applied_hist
    out = ss.C @ np.vstack([beta_hist, r_hist]) + ss.D @ np.vstack([delta_f, np.full(n, exp.m_z)])
    if use_controller:
        poles = discrete_loop_poles(exp.params, coeffs, delay_steps)
    else:
        poles = np.linalg.eigvals(phi)
    stable = bool(np.all(np.abs(poles) < 1.0))
    return Trace(t, r_hist, beta_hist, out[2], aux_hist, saturated, stable)


def discrete_loop_poles(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                        loop_gain: complex = 1.0, extra_delay: float = 0.0) -> np.ndarray:
    """Poles of the sampled loop (ZOH plant, firmware law unsaturated, N samples of delay, and
    ``extra_delay`` samples of further continuous-time delay)."""
    return np.linalg.eigvals(discrete_loop_matrix(params, coeffs, delay_steps, loop_gain, extra_delay)[0])


@functools.lru_cache(maxsize=1024)
def _sampled_plant(params: VehicleParams, ts: float, frac: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(Phi, Gamma, Gamma_late, Gamma_early) of the ZOH plant with a delay of ``frac`` of a
    sample before it (steering columns; Gamma_late = Gamma and Gamma_early = 0 at frac = 0).
    Cached: a margin search asks for the same few fractions at one operating point many times.
    The arrays are shared between callers and must not be written to."""
    ss = state_space(params)
    phi, gamma = zoh_discretize(ss.A, ss.B, ts)
    if frac == 0.0:
        return phi, gamma, gamma[:, 0], np.zeros(2)
    phi_late, gamma_late = zoh_discretize(ss.A, ss.B[:, :1], (1.0 - frac) * ts)
    gamma_early = phi_late @ zoh_discretize(ss.A, ss.B[:, :1], frac * ts)[1]
    return phi, gamma, gamma_late[:, 0], gamma_early[:, 0]


def discrete_loop_matrix(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                         loop_gain: complex = 1.0, extra_delay: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(F, g): the sampled loop x+ = F x + g M_z, delta_d = 0, the firmware law unsaturated.

    State: [beta, r, z, q_1 .. q_D] with q_i the command computed i samples ago and
    D = max(N, M), M the firmware's modelled delay.  At speed v (constant), delta_d = 0:
    M = 0: u = (z - g_r0 rho) / (1 - g_w0), w = u;   M >= 1: u = z - g_r0 rho + g_w0 q_M, w = q_M;
    z+ = g_w1 w - g_r1 rho + a u, rho = r / K_n(v); the plant gets q_N (u itself when N = 0).
    ``loop_gain`` multiplies the command on its way into the plant (a real or complex
    perturbation of the loop, for checking margins).  ``extra_delay`` (in samples, >= 0, any
    real value) is a further pure delay in continuous time between the hold and the plant: with
    k + f samples of it (0 <= f < 1) a command acts for the last (1 - f) T of the sample
    k samples after the nominal one and for the first f T of the next, so the plant's input
    matrix splits into Gamma_late = int_0^{(1-f)T} e^{As} ds B and
    Gamma_early = e^{A(1-f)T} int_0^{fT} e^{As} ds B (the modified z-transform).
    """
    if not (math.isfinite(extra_delay) and extra_delay >= 0.0):
        raise ValueError(f"extra_delay must be >= 0 samples, got {extra_delay!r}")
    whole, frac = divmod(extra_delay, 1.0)
    phi, gamma, late, early = _sampled_plant(params, coeffs.ts, frac)
    applied_at = delay_steps + int(whole)  # the queue slot whose command acts over the sample's end
    parts = [(applied_at, late)] if frac == 0.0 else [(applied_at, late), (applied_at + 1, early)]
    ikn = coeffs.wheelbase / params.v + coeffs.k_us * params.v
    m = coeffs.model_delay
    depth = max(parts[-1][0], m)
    n = 3 + depth
    u_row = np.zeros(n)  # u[k] as a function of the state
    w_row = np.zeros(n)  # w[k] (the command the law compares the yaw rate with)
    if m == 0:
        g = coeffs.inv_one_minus_g_w0
        u_row[1] = -coeffs.g_r0 * ikn * g
        u_row[2] = g
        w_row[:] = u_row
    else:
        u_row[1] = -coeffs.g_r0 * ikn
        u_row[2] = 1.0
        u_row[2 + m] = coeffs.g_w0
        w_row[2 + m] = 1.0
    F = np.zeros((n, n), dtype=complex if isinstance(loop_gain, complex) else float)
    F[:2, :2] = phi
    for slot, column in parts:
        b = column * loop_gain
        if slot == 0:
            F[:2, :] += np.outer(b, u_row)
        else:
            F[:2, 2 + slot] += b  # the command queued this many samples ago is applied now
    if depth > 0:
        F[3, :] = u_row  # newest queue slot gets this sample's command
        for i in range(1, depth):
            F[3 + i, 2 + i] = 1.0
    z_row = coeffs.g_w1 * w_row + coeffs.a * u_row
    z_row[1] -= coeffs.g_r1 * ikn
    F[2, :] = z_row
    g = np.zeros(n)
    g[:2] = gamma[:, 1]
    return F, g
