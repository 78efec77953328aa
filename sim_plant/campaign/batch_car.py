"""The realistic car, vectorised over a batch of samples: one numpy operation per time step
for all of them.

Each class is the batch twin of a scalar model of ``sim_plant.car`` and repeats its arithmetic
statement for statement (the same operations in the same order), so that a batch row equals the
scalar model up to the last bits of numpy's and libm's transcendental functions
(``tests/test_campaign_engine.py`` holds the closed loop to 1e-12):

* ``BatchCar``: ``nonlinear.NonlinearPlant`` (kinematic slip, no relaxation) with the
  magic-formula tyres of ``tyres``, RK4 in ``substeps()`` equal sub-steps, the speed a state
  that braking lowers down to ``STOP_SPEED``; its a_y (``outputs``);
* ``BatchPositionActuator``: ``actuator_dynamics.PositionActuator`` of order 1 (no dead time):
  range, exact ZOH lag, rate limit, end stop, and the position's mean over the step.

The sensors are in ``batch_sensors``.

A tyre axle is evaluated either as one axle on the road's mu (``tyres.AxleTyre.force``) or as
its two wheels (``AxleTyre.axle_force``).  With intact wheels on the road's mu the two-wheel
sum is bitwise the axle's value (the halving and doubling are exact in binary floating point),
so a batch whose rows may lose a wheel's grip evaluates the wheels throughout.
"""

from __future__ import annotations

import math

import numpy as np

from sim_plant.car.nonlinear import MAX_STEP_RATE, STOP_SPEED
from sim_plant.car.tyres import G, PACEJKA_CURVATURE, PACEJKA_SHAPE
from sim_plant.car.vehicle import MAX_SPEED, VehicleParams, zoh_discretize

BASE = VehicleParams()  # the car's data besides mass (inertia, axle positions, stiffnesses)


#: tan's argument in ``shape_sine``: half the shape factor (sin x = 2 t / (1 + t^2), t = tan(x/2)).
HALF_SHAPE = 0.5 * PACEJKA_SHAPE


def shape_sine(alpha: np.ndarray, b: np.ndarray, out: np.ndarray | None = None,
               tmp: np.ndarray | None = None) -> np.ndarray:
    """sin(C atan(B alpha - E (B alpha - atan(B alpha)))): the magic formula over its peak D,
    written into ``out`` (``tmp`` a scratch array of its shape; both made when not given).

    The sine is taken as 2 t / (1 + t^2) with t = tan(x / 2): numpy's float64 ``tan`` is
    vectorised and its ``sin`` is not (about 7x slower), and |x| < C pi / 2 keeps t finite.  The
    identity costs a few ulp against libm's ``sin``, well inside the engine's 1e-12."""
    if out is None or tmp is None:
        shape = np.broadcast_shapes(np.shape(alpha), np.shape(b))
        out, tmp = np.empty(shape), np.empty(shape)
    ba = np.multiply(b, alpha, out=tmp)
    np.arctan(ba, out=out)
    np.subtract(ba, out, out=out)
    out *= PACEJKA_CURVATURE
    np.subtract(ba, out, out=out)
    np.arctan(out, out=out)
    out *= HALF_SHAPE
    np.tan(out, out=out)
    np.multiply(out, out, out=tmp)
    tmp += 1.0
    out += out
    out /= tmp
    return out


class Tyres:
    """The tyres of a batch for one step: ``b`` (2, nb, N) and ``d`` (2, nd, N), axis 0 the axle
    (front, rear), axis 1 its wheels.  nb = nd = 1: each axle as one tyre on one mu
    (``AxleTyre.force``); nb = 1, nd = 2: the axle's two wheels share B and differ in their peak
    (split mu: ``axle_force``'s two ``wheel_force`` of one B); nb = nd = 2: every wheel its own."""

    def __init__(self, b: np.ndarray, d: np.ndarray) -> None:
        self.b, self.d = b, d


class BatchCar:
    """N nonlinear single-track cars: state beta, r, v (arrays of N, advanced in place)."""

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
        #: the intact axles on the road's mu (rows of the yaw-moment step and the side wind)
        self.intact = Tyres(np.stack([self.b_f, self.b_r])[:, None], np.stack([self.peak_f, self.peak_r])[:, None])
        n = v.size
        self.x = np.zeros((3, n))  # beta, r, v: one array, so that RK4 combines them in one operation
        self.beta, self.r, self.v = self.x
        self.v[:] = v
        self._fixed_substeps: np.ndarray | None = None
        # scratch arrays of the right-hand side and RK4 (no temporaries in the step)
        self._alpha = np.empty((2, 1, n))
        self._s = {1: np.empty((2, 1, n)), 2: np.empty((2, 2, n))}
        self._s_tmp = {1: np.empty((2, 1, n)), 2: np.empty((2, 2, n))}
        self._f = {1: np.empty((2, 1, n)), 2: np.empty((2, 2, n))}
        self._axle = np.empty((2, n))
        self._k = np.empty((4, 3, n))  # k1..k4 of (beta, r, v)
        self._stage = np.empty((3, n))
        self._t1, self._t2 = np.empty(n), np.empty(n)
        self._arms = np.array([[p.l_f], [p.l_r]])  # the axles' distances from the centre of mass
        self._lr = np.empty((2, n))
        self._mv: np.ndarray | None = None  # m v while the speed is constant
        self._mass_min = float(mass.min()) if n else 1.0
        # lat_accel's rear axle force for advance's first stage, and the tyres it was of (False: none)
        self._rear, self._rear_of = np.empty(n), False
        self._acc_tmp = np.empty((3, n))

    def substeps(self, mu_max: np.ndarray) -> np.ndarray:
        """``NonlinearPlant.substeps`` per row, with ``mu_max`` the largest mu on any wheel."""
        p, v, m = BASE, self.v, self.mass
        c_f, c_r = mu_max * p.c_f0, mu_max * p.c_r0
        moment = np.abs(c_r * p.l_r - c_f * p.l_f)
        row1 = (c_f + c_r) / (m * v) + np.abs(moment / (m * v * v) - 1.0)
        row2 = moment / p.inertia + (c_f * p.l_f**2 + c_r * p.l_r**2) / (p.inertia * v)
        return np.maximum(1, np.ceil(self.ts * np.maximum(row1, row2) / MAX_STEP_RATE)).astype(np.int64)

    def one_substep(self, mu_max: np.ndarray) -> bool:
        """``substeps`` is 1 in every row: its rates bounded above with the largest mu, the
        smallest mass and speed (and |x - 1| <= x + 1), a margin far beyond rounding."""
        p, mu, v, m = BASE, float(mu_max.max()), float(self.v.min()), self._mass_min
        if not (v > 0.0 and 0.0 <= mu < math.inf):  # (False for a NaN)
            return False
        c_f, c_r = mu * p.c_f0, mu * p.c_r0
        moment = abs(c_r * p.l_r - c_f * p.l_f)
        row1 = (c_f + c_r) / (m * v) + moment / (m * v * v) + 1.0
        row2 = moment / p.inertia + (c_f * p.l_f**2 + c_r * p.l_r**2) / (p.inertia * v)
        return self.ts * max(row1, row2) / MAX_STEP_RATE * (1.0 + 1e-9) <= 1.0

    def lat_accel(self, delta: np.ndarray, f_y: np.ndarray | None, tyres: Tyres | None) -> np.ndarray:
        """``NonlinearPlant.outputs``' a_y = sum F_y / m at the current state, with the front-wheel
        angle ``delta`` and this step's side force and tyres (None: none, the intact axles).

        The rear axle's force does not depend on the steering angle: ``advance`` with the same
        tyres, from this state, reuses it for its first stage."""
        f_front, f_rear = self._forces(self.beta, self.r, self.v, delta, tyres or self.intact)
        np.copyto(self._rear, f_rear)
        self._rear_of = tyres
        a_y = f_front + f_rear
        if f_y is not None:
            a_y += f_y
        a_y /= self.mass
        return a_y

    def _forces(self, beta, r, v, delta, tyres: Tyres, rear: np.ndarray | None = None) -> np.ndarray:
        """(F_yf, F_yr) as one (2, N) array at the kinematic slip angles (``_slip`` and
        ``axle_forces``): a view of scratch arrays, valid until the next call.  ``rear``: the
        rear axle's force, known (only the front is evaluated)."""
        alpha = self._alpha
        axles = 2 if rear is None else 1
        if rear is None:
            lr = self._lr
            np.multiply(self._arms, r, out=lr)  # l_f r / v and l_r r / v, both axles in one operation
            lr /= v
            np.subtract(lr[1], beta, out=alpha[1, 0])  # alpha_r = -beta + l_r r / v
            lf = lr[0]
        else:
            lf = np.multiply(self.l_f, r, out=self._t1)
            lf /= v
        np.subtract(delta, beta, out=alpha[0, 0])  # alpha_f = delta - beta - l_f r / v
        alpha[0, 0] -= lf
        nb, nd = tyres.b.shape[1], tyres.d.shape[1]
        s = shape_sine(alpha[:axles], tyres.b[:axles], self._s[nb][:axles], self._s_tmp[nb][:axles])
        f = np.multiply(tyres.d[:axles], s, out=self._f[nd][:axles])
        if nd == 2:
            out = self._axle
            np.add(f[:, 0], f[:, 1], out=out[:axles])
        else:
            out = self._f[nd][:, 0]
        if rear is not None:
            np.copyto(out[1], rear)
        return out

    def _derivative(self, beta, r, v, delta, m_z, f_y, a_x, tyres: Tyres, k: np.ndarray,
                    rear: np.ndarray | None = None) -> None:
        """``NonlinearPlant._derivative`` into k (3, N): d beta, d r, d v (the last only with a_x)."""
        forces = self._forces(beta, r, v, delta, tyres, rear)  # (F_yf, F_yr) as one (2, N) array
        t1, lr = self._t1, self._lr
        np.add(forces[0], forces[1], out=t1)
        if f_y is not None:
            t1 += f_y
        if v is self.v and a_x is None:  # the speed constant: m v too
            if self._mv is None:
                self._mv = self.mass * v
            mv = self._mv
        else:
            mv = np.multiply(self.mass, v, out=self._t2)
        np.divide(t1, mv, out=k[0])
        k[0] -= r
        np.multiply(self._arms, forces, out=lr)  # l_f F_yf and l_r F_yr
        np.subtract(lr[0], lr[1], out=k[1])
        k[1] += m_z
        k[1] /= self.inertia
        if a_x is not None:  # -a_x, but no braking below STOP_SPEED
            if v.min() > STOP_SPEED:
                np.negative(a_x, out=k[2])
            else:
                np.copyto(k[2], np.where((a_x < 0.0) | (v > STOP_SPEED), -a_x, 0.0))

    def advance(self, delta: np.ndarray, m_z: np.ndarray, f_y: np.ndarray | None, a_x: np.ndarray | None,
                tyres: Tyres | None, mu_max: np.ndarray) -> None:
        """``NonlinearPlant.advance``: one step, inputs held.  ``f_y`` None: no side force;
        ``a_x`` None: the speed stays; ``tyres`` None: the intact axles (``self.intact``)."""
        if a_x is None and tyres is None:  # speed and grip constant: so is the sub-step count
            if self._fixed_substeps is None:
                self._fixed_substeps = self.substeps(mu_max)
            n = self._fixed_substeps
        elif self.one_substep(mu_max):
            n = None
        else:
            n = self.substeps(mu_max)
        n_max = 1 if n is None else int(n.max())
        h = self.ts / n if n_max > 1 else self.ts
        braking = (self.v > STOP_SPEED) & (a_x > 0.0) if a_x is not None else None
        if braking is not None and not braking.any():
            braking = None
        rear = self._rear if self._rear_of is tyres else None  # (lat_accel's, at this state and tyres)
        self._rear_of = False
        for j in range(n_max):
            self._rk4(delta, m_z, f_y, a_x, tyres or self.intact, h, braking, None if n_max == 1 else j < n,
                      rear if j == 0 else None)
        if a_x is not None:
            np.minimum(self.v, MAX_SPEED, out=self.v)

    def _rk4(self, delta, m_z, f_y, a_x, tyres: Tyres, h, braking, active, rear=None) -> None:
        """One classical RK4 step of (beta, r[, v]) in place (``NonlinearPlant``'s); ``rear``: the
        rear axle's force at the state, known."""
        dims = 3 if a_x is not None else 2
        x, k, stage = self.x[:dims], self._k[:, :dims], self._stage[:dims]
        half = 0.5 * h
        self._derivative(self.beta, self.r, self.v, delta, m_z, f_y, a_x, tyres, self._k[0], rear)
        for i, step in ((1, half), (2, half), (3, h)):
            np.multiply(step, k[i - 1], out=stage)  # the stage's state x + step k_(i-1)
            np.add(x, stage, out=stage)
            v = stage[2] if dims == 3 else self.v
            self._derivative(stage[0], stage[1], v, delta, m_z, f_y, a_x, tyres, self._k[i])
        acc, tmp = stage, self._acc_tmp[:dims]  # x + h/6 (k1 + 2 k2 + 2 k3 + k4)
        np.multiply(2.0, k[1], out=acc)
        np.add(k[0], acc, out=acc)
        np.multiply(2.0, k[2], out=tmp)
        acc += tmp
        acc += k[3]
        acc *= h / 6.0
        if active is None:
            np.add(acc, x, out=x)
            if braking is not None:
                np.copyto(x[2], np.maximum(x[2], STOP_SPEED), where=braking)
            return
        acc += x
        if braking is not None:
            np.copyto(acc[2], np.maximum(acc[2], STOP_SPEED), where=braking)
        np.copyto(x, acc, where=active)  # rows with fewer sub-steps than the most are done


class BatchPositionActuator:
    """``PositionActuator`` of order 1 per row: time constant and rate limit per row."""

    def __init__(self, time_constant: np.ndarray, rate_limit_deg_s: np.ndarray, limit_deg: float, ts: float) -> None:
        self.limit = math.radians(limit_deg)
        self.max_move = np.radians(rate_limit_deg_s) * ts
        # vehicle.zoh_discretize's expm of [[-1/T, 1/T], [0, 0]] ts in closed form: e^(-ts/T) and
        # 1 - e^(-ts/T) (expm1, as exact as the Pade approximant; scipy's batched expm was 0.4 s
        # per 16k rows)
        self.phi = np.exp(-ts / time_constant)
        self.gamma = -np.expm1(-ts / time_constant)
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
        if exact.all() and np.abs(nxt).max() <= lim:  # no row rate-limited or at its end stop
            self.mean = u + (x - u) * self.mean_c
            self.position = nxt
            return nxt
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
