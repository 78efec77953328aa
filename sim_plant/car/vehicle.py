"""Linear single-track (bicycle) vehicle model of the paper, section 3.

State x = [beta, r] (chassis side-slip angle at the CG in rad, yaw rate in rad/s),
inputs u = [delta_f, M_z] (front-wheel steering angle in rad, yaw disturbance moment in Nm),
outputs y = [r, beta, a_y] (a_y the lateral acceleration at the CG in m/s^2).

With alpha_f = delta_f - beta - l_f r / v and alpha_r = -beta + l_r r / v the linear
force balance is

    m v (beta' + r) = c_f alpha_f + c_r alpha_r
    J r'            = l_f c_f alpha_f - l_r c_r alpha_r + M_z

whose transfer functions delta_f -> r and M_z -> r are exactly eqs. (14) and (16);
``steering_tf`` and ``disturbance_tf`` return the paper's coefficient formulas so that the
state-space form can be checked against them independently.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from firmware_py.calibration import NOMINAL_C_F, NOMINAL_C_R, NOMINAL_L_F, NOMINAL_L_R, NOMINAL_MASS

# Section 3: "a mid-sized passenger car that is available in the literature".  It is the nominal
# car the shipped calibration is written for, so its data are the calibration's (decision 0010);
# the yaw inertia, which the controller's model does not use, is the car's alone.
PAPER_L_F = NOMINAL_L_F  # m, front axle to CG
PAPER_L_R = NOMINAL_L_R  # m, rear axle to CG
PAPER_MASS = NOMINAL_MASS  # kg
PAPER_INERTIA = 1750.0  # kg m^2, yaw moment of inertia
PAPER_C_F0 = NOMINAL_C_F  # N/rad, front cornering stiffness at mu = 1
PAPER_C_R0 = NOMINAL_C_R  # N/rad, rear cornering stiffness at mu = 1

#: Lowest speed at which the model is evaluated: the single-track equations divide by v.
MIN_SPEED = 0.5
MAX_SPEED = 100.0
MAX_MU = 1.5


@dataclass(frozen=True)
class VehicleParams:
    """Operating point and vehicle data of the single-track model (section 3 defaults)."""

    v: float = 20.0
    mu: float = 1.0
    mass: float = PAPER_MASS
    inertia: float = PAPER_INERTIA
    l_f: float = PAPER_L_F
    l_r: float = PAPER_L_R
    c_f0: float = PAPER_C_F0
    c_r0: float = PAPER_C_R0

    def __post_init__(self) -> None:
        for name in ("v", "mu", "mass", "inertia", "l_f", "l_r", "c_f0", "c_r0"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
        if not MIN_SPEED <= self.v <= MAX_SPEED:
            raise ValueError(f"speed v must be in [{MIN_SPEED}, {MAX_SPEED}] m/s, got {self.v}")
        if not 0.0 < self.mu <= MAX_MU:
            raise ValueError(f"friction mu must be in (0, {MAX_MU}], got {self.mu}")
        for name in ("mass", "inertia", "l_f", "l_r", "c_f0", "c_r0"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")

    @property
    def c_f(self) -> float:
        return self.mu * self.c_f0

    @property
    def c_r(self) -> float:
        return self.mu * self.c_r0

    @property
    def wheelbase(self) -> float:
        return self.l_f + self.l_r

    def at(self, **changes: float) -> "VehicleParams":
        """The same vehicle at another operating point (v, mu, mass, ...)."""
        return replace(self, **changes)


@dataclass(frozen=True)
class TransferFunction:
    """Polynomial coefficients, highest power of s first (scipy.signal convention)."""

    num: tuple[float, ...]
    den: tuple[float, ...]

    def dc_gain(self) -> float:
        return self.num[-1] / self.den[-1]


def steering_tf(p: VehicleParams) -> TransferFunction:
    """Eq. (14): G_r,delta_f(s) = (b1 s + b0) / (a2 s^2 + a1 s + a0)."""
    c_f, c_r, l_f, l_r, m, v = p.c_f, p.c_r, p.l_f, p.l_r, p.mass, p.v
    b0 = c_f * c_r * (l_f + l_r) * v
    b1 = c_f * l_f * m * v**2
    return TransferFunction((b1, b0), _char_poly(p))


def disturbance_tf(p: VehicleParams) -> TransferFunction:
    """Eq. (16): G_r,Mz(s) = (m v^2 s + (c_f + c_r) v) / (a2 s^2 + a1 s + a0)."""
    return TransferFunction((p.mass * p.v**2, (p.c_f + p.c_r) * p.v), _char_poly(p))


def _char_poly(p: VehicleParams) -> tuple[float, float, float]:
    c_f, c_r, l_f, l_r, m, J, v = p.c_f, p.c_r, p.l_f, p.l_r, p.mass, p.inertia, p.v
    a0 = c_f * c_r * (l_f + l_r) ** 2 + (c_r * l_r - c_f * l_f) * m * v**2
    a1 = (c_f * (J + l_f**2 * m) + c_r * (J + l_r**2 * m)) * v
    a2 = J * m * v**2
    return (a2, a1, a0)


def nominal_yaw_gain(v: float, p: VehicleParams | None = None) -> float:
    """Eq. (15): K_n(v), the d.c. gain of eq. (14) at mu = mu_n = 1 (rad/s per rad)."""
    base = p if p is not None else VehicleParams()
    return steering_tf(base.at(v=v, mu=1.0)).dc_gain()


@dataclass(frozen=True)
class StateSpace:
    """x' = A x + B u, y = C x + D u with u = [delta_f, M_z], y = [r, beta, a_y]."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray

    OUTPUTS = ("yaw_rate", "beta", "lat_accel")
    INPUTS = ("delta_f", "m_z")


def state_space(p: VehicleParams) -> StateSpace:
    """The single-track model with state [beta, r] (derivation in the module docstring)."""
    c_f, c_r, l_f, l_r, m, J, v = p.c_f, p.c_r, p.l_f, p.l_r, p.mass, p.inertia, p.v
    a11 = -(c_f + c_r) / (m * v)
    a12 = (c_r * l_r - c_f * l_f) / (m * v**2) - 1.0
    a21 = (c_r * l_r - c_f * l_f) / J
    a22 = -(c_f * l_f**2 + c_r * l_r**2) / (J * v)
    A = np.array([[a11, a12], [a21, a22]])
    B = np.array([[c_f / (m * v), 0.0], [c_f * l_f / J, 1.0 / J]])
    # a_y = v (beta' + r): the first row of the state equation plus r, times v.
    C = np.array([[0.0, 1.0], [1.0, 0.0], [v * a11, v * (a12 + 1.0)]])
    D = np.array([[0.0, 0.0], [0.0, 0.0], [v * B[0, 0], 0.0]])
    return StateSpace(A, B, C, D)


def zoh_discretize(A: np.ndarray, B: np.ndarray, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation: expm([[A, B], [0, 0]] ts) = [[Phi, Gamma], [0, I]]."""
    if not (math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"sample time must be positive and finite, got {ts!r}")
    # Here, not at the top: scipy.linalg costs every importer of the car (the command line, the
    # nodes) 0.3 s on this host and half a minute under the CI's emulated VM.
    from scipy.linalg import expm

    n, m = B.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = A
    aug[:n, n:] = B
    e = expm(aug * ts)
    return e[:n, :n], e[:n, n:]


class DiscretePlant:
    """The single-track model discretised exactly (ZOH) at a fixed step.

    Changing the operating point (``set_params``) re-discretises while keeping the
    physical state [beta, r], so speed, friction or mass can change mid-run.
    """

    def __init__(self, params: VehicleParams, ts: float) -> None:
        self.ts = ts
        self.x = np.zeros(2)
        self.set_params(params)

    def set_params(self, params: VehicleParams) -> None:
        self.params = params
        ss = state_space(params)
        self._phi, self._gamma = zoh_discretize(ss.A, ss.B, self.ts)
        self._C, self._D = ss.C, ss.D

    def outputs(self, delta_f: float, m_z: float) -> np.ndarray:
        """[r, beta, a_y] at the current state with the given (held) inputs."""
        return self._C @ self.x + self._D @ np.array([delta_f, m_z])

    def advance(self, delta_f: float, m_z: float) -> None:
        """One step with inputs held constant over it."""
        self.x = self._phi @ self.x + self._gamma @ np.array([delta_f, m_z])

    def reset(self) -> None:
        self.x = np.zeros(2)
