"""Many operating points at once: the firmware's law in closed loop, vectorised over points.

``simulate_discrete`` runs the firmware's own ``step()`` for one operating point; a design
sweep needs thousands.  ``sweep`` runs the same experiment (yaw-moment step at t = 0, driver's
wheel held, ``delay_steps`` samples of loop delay) for every point of arrays v, mu, mass with
one numpy operation per time step across all points.  The law is the firmware's recursion
(docs/controller.md) with its actuator clamp; the firmware's fault, fade and rate-limit logic
is not exercised by this experiment and is not reproduced (``rate_limit`` must be 0).  A test
holds it equal to ``simulate_discrete`` point by point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import VehicleParams


@dataclass(frozen=True)
class SweepResult:
    v: np.ndarray
    mu: np.ndarray
    mass: np.ndarray
    peak_yaw_rate: np.ndarray  # rad/s
    final_yaw_rate: np.ndarray
    peak_aux: np.ndarray  # rad
    final_aux: np.ndarray
    saturated: np.ndarray  # bool


def _zoh_batch(v: np.ndarray, mu: np.ndarray, mass: np.ndarray, base: VehicleParams, ts: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Phi (P, 2, 2) and Gamma (P, 2, 2) of the single-track model at every point (eq. 14/16 model)."""
    c_f, c_r = mu * base.c_f0, mu * base.c_r0
    l_f, l_r, J = base.l_f, base.l_r, base.inertia
    n = v.size
    aug = np.zeros((n, 4, 4))
    aug[:, 0, 0] = -(c_f + c_r) / (mass * v)
    aug[:, 0, 1] = (c_r * l_r - c_f * l_f) / (mass * v**2) - 1.0
    aug[:, 1, 0] = (c_r * l_r - c_f * l_f) / J
    aug[:, 1, 1] = -(c_f * l_f**2 + c_r * l_r**2) / (J * v)
    aug[:, 0, 2] = c_f / (mass * v)
    aug[:, 1, 2] = c_f * l_f / J
    aug[:, 1, 3] = 1.0 / J
    e = expm(aug * ts)  # batched over the leading axis
    return e[:, :2, :2], e[:, :2, 2:]


def sweep(v: np.ndarray, mu: np.ndarray, mass: np.ndarray, config: mr.ControllerConfig, m_z: float,
          duration: float, delay_steps: int = 1, base: VehicleParams = VehicleParams()) -> SweepResult:
    """The yaw-moment step at every (v, mu, mass), the firmware law at ``config.ts``."""
    v, mu, mass = (np.asarray(a, dtype=float).ravel() for a in (v, mu, mass))
    if not (v.shape == mu.shape == mass.shape):
        raise ValueError("v, mu and mass must have the same number of points")
    if config.rate_limit != 0.0:
        raise ValueError("sweep reproduces the law without a rate limit; use simulate_discrete for that")
    if np.any(v < config.speed_active_min):
        raise ValueError("every speed must be at or above the controller's activation speed")
    c = mr.configure(config)
    ts = c.ts
    phi, gam = _zoh_batch(v, mu, mass, base, ts)
    p00, p01, p10, p11 = phi[:, 0, 0], phi[:, 0, 1], phi[:, 1, 0], phi[:, 1, 1]
    gd0, gd1 = gam[:, 0, 0], gam[:, 1, 0]
    gm0, gm1 = gam[:, 0, 1] * m_z, gam[:, 1, 1] * m_z
    ikn = c.wheelbase / v + c.k_us * v
    n_pts = v.size
    n = int(round(duration / ts)) + 1
    m = c.model_delay

    law = [mr.law_at(c, float(x)) for x in v]  # the coefficient set of each point's speed
    a, g_w0, g_w1, g_r0, g_r1 = (np.array([getattr(p, f) for p in law]) for f in ("a", "g_w0", "g_w1", "g_r0",
                                                                                   "g_r1"))
    beta = np.zeros(n_pts)
    r = np.zeros(n_pts)
    z = np.zeros(n_pts)  # the firmware starts at rest at its steady state for zero inputs
    p_n = np.zeros(n_pts)  # the nominal actuator and filter states, also at rest
    s1 = np.zeros(n_pts)
    s2 = np.zeros(n_pts)
    queue = np.zeros((max(delay_steps, 1), n_pts))  # commands in flight, oldest at index head
    hist = np.zeros((max(m, 1), n_pts))  # the firmware's own ring buffer of past commands
    head = hidx = 0
    peak_r = np.zeros(n_pts)
    peak_u = np.zeros(n_pts)
    saturated = np.zeros(n_pts, dtype=bool)
    u = np.zeros(n_pts)
    r_now = r
    for _ in range(n):
        r_now = r
        np.maximum(peak_r, np.abs(r), out=peak_r)
        rho = ikn * r
        if m == 0:
            p = z - g_r0 * rho
            u = np.clip(p * c.inv_one_minus_g_w0, -c.u_max, c.u_max)
            y = p + g_w0 * u
            w = u
        else:
            p_n = c.act_a * p_n + c.act_b * hist[hidx]
            w = c.flt_b0 * p_n + s1
            s1 = c.flt_b1 * p_n - c.flt_a1 * w + s2
            s2 = c.flt_b2 * p_n - c.flt_a2 * w
            y = g_w0 * w - g_r0 * rho + z
            u = np.clip(y, -c.u_max, c.u_max)
            hist[hidx] = u
            hidx = (hidx + 1) % m
        z = g_w1 * w - g_r1 * rho + a * y
        saturated |= np.abs(u) >= c.u_max
        np.maximum(peak_u, np.abs(u), out=peak_u)
        if delay_steps == 0:
            applied = u
        else:
            applied = queue[head].copy()
            queue[head] = u
            head = (head + 1) % delay_steps
        beta, r = (p00 * beta + p01 * r + gd0 * applied + gm0,
                   p10 * beta + p11 * r + gd1 * applied + gm1)
    return SweepResult(v, mu, mass, peak_r, r_now, peak_u, u, saturated)
