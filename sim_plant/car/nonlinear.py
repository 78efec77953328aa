"""Nonlinear single-track model of the realistic car: the paper's section-3 model with
magic-formula tyres (``tyres``), optional tyre relaxation, and a speed that braking lowers.
``BatchCar`` steps N cars at once with the kinematic slip (the campaign engine's batch), one
numpy operation per stage for all of them.

State [beta, r] as in ``vehicle`` (side slip at the CG in rad, yaw rate in rad/s), plus the
speed v and, with a relaxation length, the two axles' lagged slip angles.  With the
small-angle kinematics of the paper's model

    alpha_f = delta - beta - l_f r / v,        alpha_r = -beta + l_r r / v

the force balance is

    m v (beta' + r) = F_yf(alpha_f) + F_yr(alpha_r) + F_ext
    J r'            = l_f F_yf(alpha_f) - l_r F_yr(alpha_r) + M_z
    v'              = -a_x

where F_ext is a lateral force at the CG (side wind) and a_x a longitudinal deceleration
(braking, a blown tyre's drag).  With F_y = c alpha (the tyres' slope at zero slip,
c = mu c_0) these are exactly ``vehicle``'s linear equations, whose transfer functions are
eqs. (14)/(16): small signals reproduce the paper's model.

**Speed.** v is a state, not a parameter, because a split-mu stop decelerates the car by up
to (mu_l + mu_r) g / 2 (5.9 m/s^2 at mu 1.0 / 0.2): 25 m/s falls to 13 m/s in 2 s, and every
coefficient of the lateral dynamics goes with 1/v.  It is integrated in the same RK4 step as
beta and r, and braking stops at ``stop_speed`` (3 m/s, the scenarios' lowest speed: below
about 5-10 km/h the slip-angle model is not valid; TUM's model blends to a kinematic one
there, research/anchors.md section 3).  Left out, as in the paper's model: the longitudinal
forces' lateral components (F_x sin beta, F_xf sin delta; about m a_x / c = 4 % of the
cornering terms in a full stop) and the load transfer braking causes.

**Relaxation.** With a relaxation length sigma > 0 each axle's slip angle lags its
kinematic value, alpha' = (v / sigma)(alpha_kin - alpha) (the PT1 slip transient of TUM's
single-track model); sigma = 0 (the default) uses the kinematic slip directly.

**Integration.** Fixed-step classical RK4 at the plant step ts with inputs held over it (a
zero-order hold, as ``vehicle.DiscretePlant``), split into n equal sub-steps so that
h * ||A||_inf <= 0.25, where A is the linear model at the current speed with the largest
friction on any wheel (the tyres' slope is largest at zero slip, so this bounds the
Jacobian) and the relaxation rate v / sigma.  RK4's error per step is then about
(h lambda)^5 / 120 <= 1e-5 of the state (measured against the exact ZOH solution at small
slip: ``tests/test_car_nonlinear.py``).

**Validity: a spin.**  The model holds while the side slip is moderate: its kinematics are
small-angle (alpha = -beta + ..., the forces not turned into the direction of travel), and its
tyres' force peaks at a slip angle of 11.5 deg (rear) to 13.9 deg (front) and falls after it
toward 0.85 D.  A car whose |beta| passes ``SPIN_SIDE_SLIP`` (30 deg: tan beta
10 % above beta, the rear axle at two and a half times its peak slip) has spun (``spun``): what
the equations do after it is not a car's motion (with the yaw moment still on and both axles
saturated, their moments cancel, l_f F_zf = l_r F_zr, and r grows without bound).  The bound
is on the side slip, not on the yaw rate: the tyres bound beta' + r, |beta' + r| <= (mu g +
|F_ext| / m) / v, not r, so a yaw rate above mu g / v makes beta grow, which the side slip then
shows; a yaw-rate bound would need each wheel's mu and the side force, and cars within the
side-slip bound pass mu g / v (docs/decisions/0016-a-run-ends-when-its-car-spins.md has the runs).  ``outputs``
gives beta wrapped to (-pi, pi] (``wrap_angle``); the state itself is not wrapped.
"""

from __future__ import annotations

import math

import numpy as np

from sim_plant.car.tyres import G, INTACT, Grip, Tyres, axle_tyres, shape_sine, static_axle_loads, stiffness_factor
from sim_plant.car.vehicle import MAX_SPEED, VehicleParams

#: Braking ends here (m/s): the slip-angle model does not hold near standstill.
STOP_SPEED = 3.0
#: Largest h * ||A||_inf of one RK4 sub-step.
MAX_STEP_RATE = 0.25
MAX_RELAXATION = 5.0  # m; passenger-car tyres are 0.2-1 m
#: Beyond this side slip (rad) the car has spun: the model's validity ends (the module docstring).
SPIN_SIDE_SLIP = math.radians(30.0)
#: The car's data besides mass (inertia, axle positions, stiffnesses) of a batch that gives none.
BASE = VehicleParams()


def spun(beta: float | np.ndarray) -> bool | np.ndarray:
    """Whether the side slip ``beta`` (rad; element-wise for an array) is beyond ``SPIN_SIDE_SLIP``."""
    if isinstance(beta, float):
        return abs(beta) > SPIN_SIDE_SLIP
    return np.abs(beta) > SPIN_SIDE_SLIP


def wrap_angle(x: float | np.ndarray) -> float | np.ndarray:
    """``x`` (rad) wrapped to (-pi, pi]; an angle already in it unchanged, bit for bit."""
    if isinstance(x, float):
        return x if -math.pi < x <= math.pi else math.pi - (math.pi - x) % math.tau
    x = np.asarray(x, dtype=float)
    return np.where((-np.pi < x) & (x <= np.pi), x, np.pi - np.mod(np.pi - x, 2.0 * np.pi))


class BatchCar:
    """N nonlinear single-track cars: state beta, r, v (arrays of N, advanced in place); the
    car's data besides its mass (inertia, axle positions, stiffnesses) ``base``'s.

    The hot path allocates nothing: every stage writes into scratch arrays made here."""

    def __init__(self, v: np.ndarray, mu: np.ndarray, mass: np.ndarray, ts: float,
                 base: VehicleParams = BASE) -> None:
        p = self.base = base
        self.ts, self.mu, self.mass = ts, mu, mass
        self.l_f, self.l_r, self.inertia = p.l_f, p.l_r, p.inertia
        self.f_zf, self.f_zr = static_axle_loads(mass, p.l_f, p.l_r)
        self.b_f = stiffness_factor(p.c_f0, self.f_zf)
        self.b_r = stiffness_factor(p.c_r0, self.f_zr)
        self.peak_f = mu * self.f_zf  # an axle's peak: D = mu F_z
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
        """RK4 sub-steps of the next ``advance`` per row (the module docstring), with ``mu_max``
        the largest mu on any wheel."""
        p, v, m = self.base, self.v, self.mass
        c_f, c_r = mu_max * p.c_f0, mu_max * p.c_r0
        moment = np.abs(c_r * p.l_r - c_f * p.l_f)
        row1 = (c_f + c_r) / (m * v) + np.abs(moment / (m * v * v) - 1.0)
        row2 = moment / p.inertia + (c_f * p.l_f**2 + c_r * p.l_r**2) / (p.inertia * v)
        return np.maximum(1, np.ceil(self.ts * np.maximum(row1, row2) / MAX_STEP_RATE)).astype(np.int64)

    def one_substep(self, mu_max: np.ndarray) -> bool:
        """``substeps`` is 1 in every row: its rates bounded above with the largest mu, the
        smallest mass and speed (and |x - 1| <= x + 1), a margin far beyond rounding."""
        p, mu, v, m = self.base, float(mu_max.max()), float(self.v.min()), self._mass_min
        if not (v > 0.0 and 0.0 <= mu < math.inf):  # (False for a NaN)
            return False
        c_f, c_r = mu * p.c_f0, mu * p.c_r0
        moment = abs(c_r * p.l_r - c_f * p.l_f)
        row1 = (c_f + c_r) / (m * v) + moment / (m * v * v) + 1.0
        row2 = moment / p.inertia + (c_f * p.l_f**2 + c_r * p.l_r**2) / (p.inertia * v)
        return self.ts * max(row1, row2) / MAX_STEP_RATE * (1.0 + 1e-9) <= 1.0

    def lat_accel(self, delta: np.ndarray, f_y: np.ndarray | None, tyres: Tyres | None) -> np.ndarray:
        """a_y = sum F_y / m at the current state, with the front-wheel
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
        """(F_yf, F_yr) as one (2, N) array at the kinematic slip angles: a view of scratch arrays, valid until the next call.  ``rear``: the
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
        """The model's right-hand side into k (3, N): d beta, d r, d v (the last only with a_x)."""
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
        """One step, inputs held (a zero-order hold).  ``f_y`` None: no side force;
        ``a_x`` None: the speed stays; ``tyres`` None: the intact axles (``self.intact``)."""
        if a_x is None and tyres is None:  # speed and grip constant: so is the sub-step count
            if self._fixed_substeps is None:
                self._fixed_substeps = self.substeps(mu_max)
            n = self._fixed_substeps
        else:
            self._fixed_substeps = None  # (the speed or the grip may change: counted anew when constant)
            if a_x is not None:
                self._mv = None
            n = None if self.one_substep(mu_max) else self.substeps(mu_max)
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
        """One classical RK4 step of (beta, r[, v]) in place; ``rear``: the
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


class NonlinearPlant:
    """The nonlinear single-track model stepped at a fixed ``ts``, like ``vehicle.DiscretePlant``.

    ``x`` is [beta, r]; ``v`` the current speed.  ``outputs`` and ``advance`` take the
    front-wheel angle and the yaw moment as DiscretePlant's do, plus an optional lateral force
    at the CG and a longitudinal deceleration; ``set_grip`` changes the wheels' grip
    (split mu, a blow-out).
    """

    def __init__(self, params: VehicleParams, ts: float, relaxation_length: float = 0.0,
                 stop_speed: float = STOP_SPEED, g: float = G) -> None:
        if not (math.isfinite(ts) and 0.0 < ts <= 0.1):
            raise ValueError(f"plant step ts must be in (0, 0.1] s, got {ts!r}")
        if not (math.isfinite(relaxation_length) and 0.0 <= relaxation_length <= MAX_RELAXATION):
            raise ValueError(f"relaxation_length must be in [0, {MAX_RELAXATION:g}] m, got {relaxation_length!r}")
        if not (math.isfinite(stop_speed) and 0.5 <= stop_speed <= MAX_SPEED):
            raise ValueError(f"stop_speed must be in [0.5, {MAX_SPEED:g}] m/s, got {stop_speed!r}")
        self.ts = ts
        self.sigma = relaxation_length
        self.stop_speed = stop_speed
        self.g = g
        self.set_grip(INTACT)
        self._z = np.zeros(5)  # beta, r, v, alpha_f (lagged), alpha_r (lagged)
        self.set_params(params)

    # ------------------------------------------------------------------ state

    @property
    def x(self) -> np.ndarray:
        """[beta, r], the state ``vehicle.DiscretePlant`` has."""
        return self._z[:2].copy()

    @property
    def v(self) -> float:
        return float(self._z[2])

    def reset(self) -> None:
        self._z[[0, 1, 3, 4]] = 0.0
        self._z[2] = self.params.v

    def set_state(self, beta: float, r: float, delta: float = 0.0) -> None:
        """Start from side slip ``beta`` and yaw rate ``r`` at the current speed (a state read
        from a trace), with the lagged slip angles, if any, at their kinematic values for the
        front-wheel angle ``delta``."""
        self._z[0], self._z[1] = beta, r
        self._z[3], self._z[4] = self._kinematic_slip(self._z, delta)

    def set_params(self, params: VehicleParams, keep_speed: bool = False) -> None:
        """A new operating point (mu, mass, ...); the speed becomes ``params.v`` unless
        ``keep_speed`` (then the integrated speed carries on, e.g. while braking)."""
        self.params = params
        self._front, self._rear = axle_tyres(params, self.g)
        if not keep_speed:
            self._z[2] = params.v

    def set_grip(self, grip: Grip) -> None:
        """The wheels' grip from now on (``tyres.INTACT`` for all four on the car's road)."""
        self.grip = grip
        self._intact = grip == INTACT

    # ------------------------------------------------------------------ model

    def axle_forces(self, alpha_f: float, alpha_r: float) -> tuple[float, float]:
        """(F_yf, F_yr) in N at the given slip angles with the current grip and road mu."""
        mu, g = self.params.mu, self.grip
        if self._intact:
            return float(self._front.force(alpha_f, mu)), float(self._rear.force(alpha_r, mu))
        return (float(self._front.axle_force(alpha_f, mu, g.fl, g.fr)),
                float(self._rear.axle_force(alpha_r, mu, g.rl, g.rr)))

    def _slip(self, z: np.ndarray, delta: float) -> tuple[float, float]:
        if self.sigma > 0.0:
            return float(z[3]), float(z[4])
        return self._kinematic_slip(z, delta)

    def _kinematic_slip(self, z: np.ndarray, delta: float) -> tuple[float, float]:
        beta, r, v = z[0], z[1], z[2]
        return delta - beta - self.params.l_f * r / v, -beta + self.params.l_r * r / v

    def _derivative(self, z: np.ndarray, delta: float, m_z: float, f_y: float, a_x: float) -> np.ndarray:
        p = self.params
        beta, r, v = z[0], z[1], z[2]
        f_front, f_rear = self.axle_forces(*self._slip(z, delta))
        dz = np.zeros(5)
        dz[0] = (f_front + f_rear + f_y) / (p.mass * v) - r
        dz[1] = (p.l_f * f_front - p.l_r * f_rear + m_z) / p.inertia
        dz[2] = -a_x if (a_x < 0.0 or v > self.stop_speed) else 0.0
        if self.sigma > 0.0:
            rate = v / self.sigma
            dz[3] = rate * (delta - beta - p.l_f * r / v - z[3])
            dz[4] = rate * (-beta + p.l_r * r / v - z[4])
        return dz

    def substeps(self) -> int:
        """How many RK4 sub-steps the next ``advance`` takes (see the module docstring)."""
        p, v = self.params, self.v
        g = self.grip
        mu = max([p.mu] + [w.mu for w in (g.fl, g.fr, g.rl, g.rr) if w.mu is not None])
        c_f, c_r = mu * p.c_f0, mu * p.c_r0
        moment = abs(c_r * p.l_r - c_f * p.l_f)
        row1 = (c_f + c_r) / (p.mass * v) + abs(moment / (p.mass * v * v) - 1.0)
        row2 = moment / p.inertia + (c_f * p.l_f**2 + c_r * p.l_r**2) / (p.inertia * v)
        rate = max(row1, row2, v / self.sigma if self.sigma > 0.0 else 0.0)
        return max(1, math.ceil(self.ts * rate / MAX_STEP_RATE))

    # ------------------------------------------------------------------ the DiscretePlant interface

    def outputs(self, delta_f: float, m_z: float, f_y: float = 0.0) -> np.ndarray:
        """[r, beta, a_y] at the current state with the given (held) inputs; a_y = sum F_y / m;
        beta wrapped to (-pi, pi]."""
        f_front, f_rear = self.axle_forces(*self._slip(self._z, delta_f))
        return np.array([self._z[1], wrap_angle(float(self._z[0])), (f_front + f_rear + f_y) / self.params.mass])

    def advance(self, delta_f: float, m_z: float, f_y: float = 0.0, a_x: float = 0.0) -> None:
        """One plant step with the inputs held constant over it (RK4 in equal sub-steps)."""
        n = self.substeps()
        h = self.ts / n
        z = self._z
        braking = z[2] > self.stop_speed
        for _ in range(n):
            k1 = self._derivative(z, delta_f, m_z, f_y, a_x)
            k2 = self._derivative(z + 0.5 * h * k1, delta_f, m_z, f_y, a_x)
            k3 = self._derivative(z + 0.5 * h * k2, delta_f, m_z, f_y, a_x)
            k4 = self._derivative(z + h * k3, delta_f, m_z, f_y, a_x)
            z = z + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            if braking and a_x > 0.0:
                z[2] = max(z[2], self.stop_speed)
        if z[2] > MAX_SPEED:
            z[2] = MAX_SPEED
        self._z = z
