"""Magic-formula (Pacejka) lateral tyre forces of the realistic car, scaled by the road's mu.

One axle's pure-slip lateral force at slip angle alpha (rad) is

    F_y(alpha) = D sin(C atan(B alpha - E (B alpha - atan(B alpha))))

with

* peak ``D = mu F_z``: mu is the road's peak friction coefficient and F_z the axle's static
  load, so the force saturates at mu F_z.  The source's peak factor p_dy1 = 1.0489 (a tyre on
  a test rig's surface) is absorbed into mu: mu = 1 means "the peak of this car's tyres on a
  dry road", as the paper's mu_n = 1 does.
* shape ``C = p_cy1 = 1.3507`` and curvature ``E = p_ey1 = -0.00747``: the lateral pure-slip
  coefficients of CommonRoad's ``parameters_vehicle2`` (BMW 320i), taken there from the
  MSC ADAMS tyre handbook (CommonRoad vehicle models, Althoff et al.; see
  research/anchors.md section 3).  C < 2 gives a force that falls after its peak to
  D sin(C pi/2) = 0.85 D at large slip.
* stiffness ``B = c_0 / (C F_z)``: chosen so that the slope at zero slip, dF_y/dalpha(0) =
  B C D = mu c_0, is the paper's cornering stiffness c = mu c_0 (section 3: c_f0 = 84000,
  c_r0 = 96000 N/rad).  Small signals therefore reproduce the linear model of eqs. (14)/(16)
  exactly to first order; B does not depend on mu, so the slip angle of the peak does not
  either (about 13.9 deg front, 11.5 deg rear for the paper's car).

A wheel (half an axle) uses the same formula with half the axle's c_0 and F_z; a damaged
wheel (blow-out) keeps a fraction ``stiffness`` of its slope and ``peak`` of its peak force,
which moves its B to (stiffness / peak) B.  The sum of an axle's two healthy wheels on roads
of friction mu_l and mu_r equals one axle at (mu_l + mu_r) / 2.

Every function is evaluated element-wise over numpy arrays: a batch of cars (the campaign
engine's) or a batch of one (the plant node's and the offline tools', ``nonlinear.NonlinearPlant``).

The sine is taken as 2 t / (1 + t^2) with t = tan(x / 2) (``shape_sine``): numpy's float64
``tan`` is vectorised and its ``sin`` is not (about 7x slower), and |x| < C pi / 2 keeps t
finite.  The identity costs a few ulp against libm's ``sin``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from sim_plant.car.vehicle import MAX_MU

#: Standard gravity, m/s^2.
G = 9.81
#: CommonRoad parameters_vehicle2 (ADAMS handbook) lateral shape factor p_cy1.
PACEJKA_SHAPE = 1.3507
#: CommonRoad parameters_vehicle2 (ADAMS handbook) lateral curvature factor p_ey1.
PACEJKA_CURVATURE = -0.00747
#: tan's argument in ``shape_sine``: half the shape factor (sin x = 2 t / (1 + t^2), t = tan(x/2)).
HALF_SHAPE = 0.5 * PACEJKA_SHAPE


def magic_formula(alpha: ArrayLike, stiffness: ArrayLike, shape: float, peak: ArrayLike,
                  curvature: float) -> np.ndarray:
    """F_y = D sin(C atan(B alpha - E (B alpha - atan(B alpha)))) with B, C, D, E as named.

    A float for float arguments (the plant's hot path, where numpy's per-call overhead would
    dominate), else an array broadcast over the arguments."""
    if isinstance(alpha, float) and isinstance(stiffness, float) and isinstance(peak, float):
        ba = stiffness * alpha
        return peak * math.sin(shape * math.atan(ba - curvature * (ba - math.atan(ba))))  # type: ignore[return-value]
    ba = np.multiply(stiffness, alpha)
    return np.multiply(peak, np.sin(shape * np.arctan(ba - curvature * (ba - np.arctan(ba)))))


def static_axle_loads(mass: ArrayLike, l_f: float, l_r: float, g: float = G) -> tuple[ArrayLike, ArrayLike]:
    """(F_zf, F_zr) in N: the car's weight shared by the lever rule, F_zf = m g l_r / (l_f + l_r)."""
    wheelbase = l_f + l_r
    return mass * g * l_r / wheelbase, mass * g * l_f / wheelbase  # type: ignore[operator]


def stiffness_factor(c0: ArrayLike, f_z: ArrayLike) -> ArrayLike:
    """B = c_0 / (C F_z), so that the slope at zero slip is mu c_0 (for the peak mu F_z)."""
    return c0 / (PACEJKA_SHAPE * f_z)  # type: ignore[operator]


def shape_sine(alpha: ArrayLike, b: ArrayLike, out: np.ndarray | None = None,
               tmp: np.ndarray | None = None) -> np.ndarray:
    """sin(C atan(B alpha - E (B alpha - atan(B alpha)))): the magic formula over its peak D,
    written into ``out`` (``tmp`` a scratch array of its shape; both made when not given)."""
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


def lateral_force(alpha: ArrayLike, b: ArrayLike, peak: ArrayLike) -> np.ndarray:
    """F_y = D sin(C atan(B alpha - E (B alpha - atan(B alpha)))) with B = ``b``, D = ``peak``."""
    return np.multiply(peak, shape_sine(alpha, b))


@dataclass(frozen=True)
class WheelGrip:
    """What one wheel has to work with: the road's mu under it and its own condition.

    ``mu`` None means the car's road friction (``VehicleParams.mu``); ``stiffness`` and ``peak``
    are the fractions of the healthy wheel's cornering stiffness and peak force left (1 = intact).
    """

    mu: float | None = None
    stiffness: float = 1.0
    peak: float = 1.0

    def __post_init__(self) -> None:
        if self.mu is not None and not (math.isfinite(self.mu) and 0.0 < self.mu <= MAX_MU):
            raise ValueError(f"wheel mu must be in (0, {MAX_MU:g}], got {self.mu!r}")
        for name in ("stiffness", "peak"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 < value <= 1.0):
                raise ValueError(f"wheel {name} fraction must be in (0, 1], got {value!r}")

    def then(self, other: "WheelGrip") -> "WheelGrip":
        """Both changes at once: ``other``'s mu if it sets one, the fractions multiplied."""
        return WheelGrip(other.mu if other.mu is not None else self.mu,
                         self.stiffness * other.stiffness, self.peak * other.peak)


@dataclass(frozen=True)
class Grip:
    """The four wheels' grip: front left, front right, rear left, rear right."""

    fl: WheelGrip = WheelGrip()
    fr: WheelGrip = WheelGrip()
    rl: WheelGrip = WheelGrip()
    rr: WheelGrip = WheelGrip()

    def then(self, other: "Grip") -> "Grip":
        return Grip(self.fl.then(other.fl), self.fr.then(other.fr), self.rl.then(other.rl), self.rr.then(other.rr))


#: A wheel intact on the car's road.
HEALTHY = WheelGrip()
#: All four wheels intact on the car's road.
INTACT = Grip()


class Tyres:
    """The tyres of a batch for one step: ``b`` (2, nb, N) and ``d`` (2, nd, N), axis 0 the axle
    (front, rear), axis 1 its wheels.  nb = nd = 1: each axle as one tyre of peak mu F_z; nb = 1,
    nd = 2: the axle's two wheels share B and differ in their peak (split mu); nb = nd = 2: every
    wheel its own (a wheel: half the axle's c_0 and F_z, its B times stiffness / peak, its peak
    0.5 peak mu F_z).  With intact wheels on the road's mu the two-wheel sum is bitwise the
    axle's value (the halving and doubling are exact in binary floating point)."""

    def __init__(self, b: np.ndarray, d: np.ndarray) -> None:
        self.b, self.d = b, d


def wheel_tyres(b: tuple[float, float], f_z: tuple[float, float], mu: float, grip: Grip) -> Tyres:
    """One car's four wheels (a batch of one) with ``grip`` on the road of friction ``mu``:
    the axles' B ``b`` and static loads ``f_z`` (front, rear)."""
    wheels = ((grip.fl, grip.fr), (grip.rl, grip.rr))
    return Tyres(np.array([[[b[a] * w.stiffness / w.peak] for w in pair] for a, pair in enumerate(wheels)]),
                 np.array([[[0.5 * w.peak * (mu if w.mu is None else w.mu) * f_z[a]] for w in pair]
                           for a, pair in enumerate(wheels)]))


def max_mu(mu: float, grip: Grip) -> float:
    """The largest friction under any wheel (the road's ``mu`` where a wheel sets none)."""
    return max([mu] + [w.mu for w in (grip.fl, grip.fr, grip.rl, grip.rr) if w.mu is not None])


@dataclass(frozen=True)
class AxleTyre:
    """One axle's two tyres: cornering stiffness ``c0`` at mu = 1 (N/rad) and static load ``f_z`` (N)."""

    c0: float
    f_z: float
    shape: float = PACEJKA_SHAPE
    curvature: float = PACEJKA_CURVATURE

    def __post_init__(self) -> None:
        for name in ("c0", "f_z"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"axle {name} must be positive and finite, got {value!r}")
        if not 0.0 < self.shape < 2.0:
            raise ValueError(f"magic-formula shape C must be in (0, 2) (a lateral force), got {self.shape}")
        if not -10.0 <= self.curvature <= 1.0:
            raise ValueError(f"magic-formula curvature E must be in [-10, 1], got {self.curvature}")

    @cached_property
    def stiffness_factor(self) -> float:
        """B = c_0 / (C F_z), so that the slope at zero slip is mu c_0."""
        return self.c0 / (self.shape * self.f_z)

    def force(self, alpha: ArrayLike, mu: ArrayLike) -> np.ndarray:
        """Both wheels intact on one road of friction ``mu``: peak mu F_z, slope mu c_0."""
        return magic_formula(alpha, self.stiffness_factor, self.shape, mu * self.f_z if isinstance(mu, float) else np.multiply(mu, self.f_z), self.curvature)

    def wheel_force(self, alpha: ArrayLike, mu: float, grip: WheelGrip) -> np.ndarray:
        """One wheel (half the axle) on friction ``mu`` with its condition ``grip``."""
        b = self.stiffness_factor * grip.stiffness / grip.peak
        return magic_formula(alpha, b, self.shape, 0.5 * grip.peak * mu * self.f_z, self.curvature)

    def axle_force(self, alpha: ArrayLike, road_mu: float, left: WheelGrip, right: WheelGrip) -> np.ndarray:
        """The axle's force as the sum of its two wheels (split mu, a blown wheel)."""
        if left == right == HEALTHY:
            return self.force(alpha, road_mu)
        mu_l = road_mu if left.mu is None else left.mu
        mu_r = road_mu if right.mu is None else right.mu
        return self.wheel_force(alpha, mu_l, left) + self.wheel_force(alpha, mu_r, right)


def axle_tyres(p: VehicleParams, g: float = G) -> tuple[AxleTyre, AxleTyre]:
    """The front and rear axle tyres of the car ``p`` (its c_f0, c_r0 and static loads)."""
    f_zf, f_zr = static_axle_loads(p.mass, p.l_f, p.l_r, g)
    return AxleTyre(p.c_f0, f_zf), AxleTyre(p.c_r0, f_zr)
