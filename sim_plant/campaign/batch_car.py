"""The realistic car, vectorised over a batch of samples: one numpy operation per time step
for all of them.

Each class is the batch twin of a scalar model of ``sim_plant.car`` and repeats its arithmetic
statement for statement (the same operations in the same order), so that a batch row equals the
scalar model up to the last bits of numpy's and libm's transcendental functions
(``tests/test_campaign_engine.py`` holds the closed loop to 1e-12):

* ``BatchCar``: ``nonlinear.NonlinearPlant`` (kinematic slip, no relaxation) with the
  magic-formula tyres of ``tyres``, RK4 in ``substeps()`` equal sub-steps, the speed a state
  that braking lowers down to ``STOP_SPEED``;
* ``BatchPositionActuator``: ``actuator_dynamics.PositionActuator`` of order 1 (no dead time):
  range, exact ZOH lag, rate limit, end stop, and the position's mean over the step;
* ``BatchSensors``: ``sensors.Sensors``: the yaw rate's noise (each sample's own seeded stream,
  drawn as the scalar draws it), bias, 2nd-order Butterworth and DBC quantisation; the
  steering angle and the speed quantised (their noise is 0 in a campaign).

A tyre axle is evaluated either as one axle on the road's mu (``tyres.AxleTyre.force``) or as
its two wheels (``AxleTyre.axle_force``).  With intact wheels on the road's mu the two-wheel
sum is bitwise the axle's value (the halving and doubling are exact in binary floating point),
so a batch whose rows may lose a wheel's grip evaluates the wheels throughout.
"""

from __future__ import annotations

import math

import numpy as np

from sim_plant.car.nonlinear import MAX_STEP_RATE, STOP_SPEED
from sim_plant.car.sensors import SensorConfig, dbc_resolution
from sim_plant.car.tyres import G, PACEJKA_CURVATURE, PACEJKA_SHAPE
from sim_plant.car.vehicle import MAX_SPEED, VehicleParams, zoh_discretize

BASE = VehicleParams()  # the car's data besides mass (inertia, axle positions, stiffnesses)


def magic_formula(alpha: np.ndarray, b: np.ndarray, peak: np.ndarray) -> np.ndarray:
    """``tyres.magic_formula`` with the car's shape and curvature, element-wise."""
    return peak * shape_sine(alpha, b)


def shape_sine(alpha: np.ndarray, b: np.ndarray) -> np.ndarray:
    """sin(C atan(B alpha - E (B alpha - atan(B alpha)))): the magic formula over its peak D.
    Two wheels of one B (split mu: the same tyre on two roads) share it."""
    ba = b * alpha
    return np.sin(PACEJKA_SHAPE * np.arctan(ba - PACEJKA_CURVATURE * (ba - np.arctan(ba))))


class BatchCar:
    """N nonlinear single-track cars: state beta, r, v (arrays of N)."""

    def __init__(self, v: np.ndarray, mu: np.ndarray, mass: np.ndarray, ts: float) -> None:
        p = BASE
        self.ts, self.mu, self.mass = ts, mu, mass
        self.l_f, self.l_r, self.inertia = p.l_f, p.l_r, p.inertia
        wheelbase = p.l_f + p.l_r
        # tyres.static_axle_loads and AxleTyre.stiffness_factor
        self.f_zf = mass * G * p.l_r / wheelbase
        self.f_zr = mass * G * p.l_f / wheelbase
        self.b_f = p.c_f0 / (PACEJKA_SHAPE * self.f_zf)
        self.b_r = p.c_r0 / (PACEJKA_SHAPE * self.f_zr)
        self.peak_f = mu * self.f_zf  # AxleTyre.force: D = mu F_z
        self.peak_r = mu * self.f_zr
        self.beta = np.zeros_like(v)
        self.r = np.zeros_like(v)
        self.v = v.astype(float).copy()
        self._fixed_substeps: np.ndarray | None = None

    def wheel(self, front: bool, stiffness: np.ndarray, peak: np.ndarray, mu: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """(B, D) of one wheel: ``AxleTyre.wheel_force``'s (B stiffness / peak, 0.5 peak mu F_z)."""
        b, f_z = (self.b_f, self.f_zf) if front else (self.b_r, self.f_zr)
        return b * stiffness / peak, 0.5 * peak * mu * f_z

    def substeps(self, mu_max: np.ndarray) -> np.ndarray:
        """``NonlinearPlant.substeps`` per row, with ``mu_max`` the largest mu on any wheel."""
        p, v, m = BASE, self.v, self.mass
        c_f, c_r = mu_max * p.c_f0, mu_max * p.c_r0
        moment = np.abs(c_r * p.l_r - c_f * p.l_f)
        row1 = (c_f + c_r) / (m * v) + np.abs(moment / (m * v * v) - 1.0)
        row2 = moment / p.inertia + (c_f * p.l_f**2 + c_r * p.l_r**2) / (p.inertia * v)
        return np.maximum(1, np.ceil(self.ts * np.maximum(row1, row2) / MAX_STEP_RATE)).astype(np.int64)

    def _derivative(self, beta, r, v, delta, m_z, f_y, a_x, wheels):
        l_f, l_r = self.l_f, self.l_r
        alpha_f = delta - beta - l_f * r / v
        alpha_r = -beta + l_r * r / v
        if wheels is None:
            f_front = magic_formula(alpha_f, self.b_f, self.peak_f)
            f_rear = magic_formula(alpha_r, self.b_r, self.peak_r)
        elif len(wheels) == 2:  # each axle's wheels share B: ((B, D_left, D_right), ...)
            (b_f, pfl, pfr), (b_r, prl, prr) = wheels
            s_f, s_r = shape_sine(alpha_f, b_f), shape_sine(alpha_r, b_r)
            f_front = pfl * s_f + pfr * s_f
            f_rear = prl * s_r + prr * s_r
        else:
            (bfl, pfl), (bfr, pfr), (brl, prl), (brr, prr) = wheels
            f_front = magic_formula(alpha_f, bfl, pfl) + magic_formula(alpha_f, bfr, pfr)
            f_rear = magic_formula(alpha_r, brl, prl) + magic_formula(alpha_r, brr, prr)
        total = f_front + f_rear
        if f_y is not None:
            total = total + f_y
        d_beta = total / (self.mass * v) - r
        d_r = (l_f * f_front - l_r * f_rear + m_z) / self.inertia
        d_v = None if a_x is None else np.where((a_x < 0.0) | (v > STOP_SPEED), -a_x, 0.0)
        return d_beta, d_r, d_v

    def advance(self, delta: np.ndarray, m_z: np.ndarray, f_y: np.ndarray | None, a_x: np.ndarray | None,
                wheels, mu_max: np.ndarray) -> None:
        """``NonlinearPlant.advance``: one step, inputs held.  ``f_y`` None: no side force;
        ``a_x`` None: the speed stays; ``wheels`` None: intact axles, else the four wheels' (B, D),
        or per axle (B, D_left, D_right) when its two wheels share B."""
        if a_x is None and wheels is None:  # speed and grip constant: so is the sub-step count
            if self._fixed_substeps is None:
                self._fixed_substeps = self.substeps(mu_max)
            n = self._fixed_substeps
        else:
            n = self.substeps(mu_max)
        n_max = int(n.max())
        h = self.ts / n if n_max > 1 else self.ts
        braking = (self.v > STOP_SPEED) & (a_x > 0.0) if a_x is not None else None
        for j in range(n_max):
            self._rk4(delta, m_z, f_y, a_x, wheels, h, braking, None if n_max == 1 else j < n)
        if a_x is not None:
            np.minimum(self.v, MAX_SPEED, out=self.v)

    def _rk4(self, delta, m_z, f_y, a_x, wheels, h, braking, active) -> None:
        b, r, v = self.beta, self.r, self.v
        d = self._derivative
        k1 = d(b, r, v, delta, m_z, f_y, a_x, wheels)
        half = 0.5 * h
        v2 = v if a_x is None else v + half * k1[2]
        k2 = d(b + half * k1[0], r + half * k1[1], v2, delta, m_z, f_y, a_x, wheels)
        v3 = v if a_x is None else v + half * k2[2]
        k3 = d(b + half * k2[0], r + half * k2[1], v3, delta, m_z, f_y, a_x, wheels)
        v4 = v if a_x is None else v + h * k3[2]
        k4 = d(b + h * k3[0], r + h * k3[1], v4, delta, m_z, f_y, a_x, wheels)
        sixth = h / 6.0
        nb = b + sixth * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        nr = r + sixth * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        nv = v
        if a_x is not None:
            nv = v + sixth * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
            nv = np.where(braking, np.maximum(nv, STOP_SPEED), nv)
        if active is not None:  # rows with fewer sub-steps than the most are done
            nb, nr, nv = (np.where(active, new, old) for new, old in ((nb, b), (nr, r), (nv, v)))
        self.beta, self.r, self.v = nb, nr, nv


class BatchPositionActuator:
    """``PositionActuator`` of order 1 per row: time constant and rate limit per row."""

    def __init__(self, time_constant: np.ndarray, rate_limit_deg_s: np.ndarray, limit_deg: float, ts: float) -> None:
        self.limit = math.radians(limit_deg)
        self.max_move = np.radians(rate_limit_deg_s) * ts
        inv = 1.0 / time_constant
        aug = np.zeros((time_constant.size, 2, 2))
        aug[:, 0, 0], aug[:, 0, 1] = -inv, inv
        # vehicle.zoh_discretize's expm, batched over rows (the scalar model's own discretisation)
        from scipy.linalg import expm

        e = expm(aug * ts)
        self.phi, self.gamma = e[:, 0, 0].copy(), e[:, 0, 1].copy()
        # PositionActuator's mean over a step of an unclipped first-order move: T/ts (1 - e^(-ts/T))
        self.mean_c = time_constant / ts * (1.0 - np.exp(-ts / time_constant))
        self.position = np.zeros(time_constant.size)
        self.mean = np.zeros(time_constant.size)

    def step(self, command: np.ndarray) -> np.ndarray:
        lim = self.limit
        u = np.minimum(lim, np.maximum(-lim, command))
        x = self.position
        nxt = self.phi * x + self.gamma * u
        move = nxt - x
        exact = np.abs(move) <= self.max_move
        nxt = np.where(exact, nxt, x + np.copysign(self.max_move, move))
        stopped = np.abs(nxt) > lim
        nxt = np.where(stopped, np.copysign(lim, nxt), nxt)
        # The position's mean over the step (what the car gets): exact for an unclipped move,
        # else the trapezoid, as PositionActuator.mean
        self.mean = np.where(exact & ~stopped, u + (x - u) * self.mean_c, 0.5 * (x + nxt))
        self.position = nxt
        return nxt


def zoh_first_order(time_constant: float, ts: float) -> tuple[float, float]:
    """(phi, gamma) of T y' + y = u, exactly as ``PositionActuator`` discretises it."""
    phi, gamma = zoh_discretize(np.array([[-1.0 / time_constant]]), np.array([[1.0 / time_constant]]), ts)
    return float(phi[0, 0]), float(gamma[0, 0])


class BatchSensors:
    """The yaw-rate, steering-angle and speed sensors per row (``sensors.Sensors``)."""

    BLOCK = 500  # noise drawn this many steps at a time per row (the scalar's stream, in blocks)

    def __init__(self, noise_density: np.ndarray, bias_deg_s: np.ndarray, seeds: np.ndarray, ts: float,
                 config: SensorConfig = SensorConfig()) -> None:
        fs = 1.0 / ts
        self.sigma = np.radians(noise_density) * math.sqrt(fs / 2.0)
        self.bias = np.radians(bias_deg_s)
        from scipy.signal import butter, lfilter_zi

        b, a = butter(2, config.yaw_rate.lowpass_hz, fs=fs)
        b, a = b / a[0], a / a[0]
        self.b, self.a = b.tolist(), a.tolist()
        self.zi = lfilter_zi(b, a).tolist()
        self.q_yaw, self.q_steer, self.q_speed = (dbc_resolution(q) for q in ("yaw_rate", "steer", "speed"))
        # Sensors.reset's SeedSequence(seed).spawn(3)[0], the yaw-rate stream, made directly
        self._rngs = [np.random.default_rng(np.random.SeedSequence(s, spawn_key=(0,))) for s in seeds.tolist()]
        self._noise = np.zeros((0, seeds.size))
        self._k = 0
        self._z: tuple[np.ndarray, np.ndarray] | None = None

    def _draw(self) -> np.ndarray:
        """This step's standard normal per row, from each row's stream in the scalar's order."""
        j = self._k % self.BLOCK
        if j == 0:
            self._noise = np.stack([g.standard_normal(self.BLOCK) for g in self._rngs], axis=1)
        self._k += 1
        return self._noise[j]

    def yaw_rate(self, r: np.ndarray) -> np.ndarray:
        noisy = r + self.bias + self.sigma * self._draw()
        b, a = self.b, self.a
        if self._z is None:  # at rest on the first value (lfilter_zi)
            self._z = (self.zi[0] * noisy, self.zi[1] * noisy)
        z0, z1 = self._z
        y = b[0] * noisy + z0
        self._z = (b[1] * noisy - a[1] * y + z1, b[2] * noisy - a[2] * y)
        return np.round(y / self.q_yaw) * self.q_yaw

    def steer(self, delta: np.ndarray) -> np.ndarray:
        return np.round(delta / self.q_steer) * self.q_steer

    def speed(self, v: np.ndarray) -> np.ndarray:
        return np.round(v / self.q_speed) * self.q_speed
