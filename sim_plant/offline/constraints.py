"""The design constraints of issue 15 (item 2), per operating point and on dry road.

Per point of the envelope (besides the margins of ``margins``):

* **extra delay**: the largest closed-loop pole radius with one more, unmodelled whole sample
  of loop delay (``discrete_loop``; < 1 is stable);
* **actuator time constant**: the largest pole radius over the actuator ``TAU_FACTORS`` times
  slower (order 1: T * f; order 2: w_n / f), and the factor where it occurs (None for the
  ideal actuator);
* **command noise**: the RMS (deg) of the auxiliary command from white yaw-rate noise of
  density N (deg/s/sqrt(Hz), one-sided: per-sample sigma = N sqrt(fs / 2)) entering at the
  sensor, through its low-pass and the loop: the exact H2 figure
  var(u) = sigma^2 (u_row P u_row' + u_noise^2),  P = F P F' + g_noise g_noise'
  (``scipy.linalg.solve_discrete_lyapunov``); infinite for an unstable loop.

On dry road (mu = 1, at the base vehicle's mass), at ``SPEEDS``:

* **saturation threshold**: the smallest yaw-moment step after which the *applied* auxiliary
  angle reaches 99 % of the actuator's range, by bisection on M_z with the saturating
  ``simulate_discrete`` (noise-free sensors: ``LoopModels.deterministic``);
* **objective**: the peak yaw rate after the 4000 Nm step (Figure 10's disturbance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import VehicleParams
from sim_plant.offline.closed_loop import Experiment, simulate_discrete
from sim_plant.offline.discrete_loop import IDEAL, closed_loop, max_pole_radius
from sim_plant.offline.loop_plant import LoopModels

NOISE_DENSITY = 0.014  # deg/s/sqrt(Hz), one-sided: Bosch BMG160 (issue 15)
NOISE_MAX_DEG = 0.15
THRESHOLD_MIN_NM = 6119.0  # the paper's smallest saturating step on dry road
SPEEDS = (10.0, 20.0, 40.0)
OBJECTIVE_MZ = 4000.0
TAU_FACTORS = (0.5, 0.5 ** 0.5, 1.0, 2.0 ** 0.5, 2.0)
APPLIED_FRACTION = 0.99
STEP_DURATION = 1.5  # s: the peak and the applied angle's peak come well inside it
_BISECT_REL = 1e-4


def noise_sigma(models: LoopModels, ts: float) -> float:
    """Per-sample yaw-rate noise sigma (rad/s): the sensors' density, or NOISE_DENSITY for exact
    sensors (the noise then enters unfiltered)."""
    if models.sensors.exact:
        return math.radians(NOISE_DENSITY) * math.sqrt(0.5 / ts)
    return models.yaw_noise_sigma(ts)


def noise_rms_deg(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                  models: LoopModels = IDEAL, sigma: float | None = None) -> float:
    """RMS of the auxiliary command (deg) for white yaw-rate noise of per-sample ``sigma``
    (rad/s; default ``noise_sigma``): exact H2 of the closed loop."""
    loop = closed_loop(params, coeffs, delay_steps, models=models)
    if np.max(np.abs(np.linalg.eigvals(loop.f))) >= 1.0:
        return math.inf
    P = solve_discrete_lyapunov(loop.f, np.outer(loop.g_noise, loop.g_noise))
    s = noise_sigma(models, coeffs.ts) if sigma is None else sigma
    return math.degrees(s * math.sqrt(float(loop.u_row @ P @ loop.u_row) + loop.u_noise ** 2))


def _finite(x: Any) -> Any:
    """inf (an unstable loop's noise) as None, so that the JSON stays standard."""
    return None if isinstance(x, float) and math.isinf(x) else x


@dataclass(frozen=True)
class PointConstraints:
    v: float
    mu: float
    mass: float
    extra_delay_pole_radius: float
    tau_range_pole_radius: float | None
    tau_range_worst_factor: float | None
    noise_rms_deg: float

    def as_dict(self) -> dict[str, Any]:
        return {k: _finite(x) for k, x in vars(self).items()}


def point_constraints(params: VehicleParams, config: mr.ControllerConfig, delay_steps: int,
                      models: LoopModels = IDEAL) -> PointConstraints:
    coeffs = mr.configure(config)
    extra = max_pole_radius(params, coeffs, delay_steps + 1, models)
    tau_r = tau_f = None
    if models.actuator.order != 0:
        radii = [(max_pole_radius(params, coeffs, delay_steps, models.with_time_constant_scaled(f)), f)
                 for f in TAU_FACTORS]
        tau_r, tau_f = max(radii)
    return PointConstraints(params.v, params.mu, params.mass, extra, tau_r, tau_f,
                            noise_rms_deg(params, coeffs, delay_steps, models))


def _step(params: VehicleParams, config: mr.ControllerConfig, ts: float, delay_steps: int, models: LoopModels,
          m_z: float):
    exp = Experiment(params, config.q_form, config, m_z=m_z, duration=STEP_DURATION)
    return simulate_discrete(exp, ts, delay_steps, models.deterministic())


def peak_yaw_rate(params: VehicleParams, config: mr.ControllerConfig, delay_steps: int,
                  models: LoopModels = IDEAL, m_z: float = OBJECTIVE_MZ) -> float:
    """Peak |r| (rad/s) within STEP_DURATION after the step (an unstable loop's too: check
    its poles)."""
    return float(np.max(np.abs(_step(params, config, config.ts, delay_steps, models, m_z).yaw_rate)))


def applied_threshold(params: VehicleParams, config: mr.ControllerConfig, delay_steps: int,
                      models: LoopModels = IDEAL, hi_limit: float = 1e5) -> float:
    """Smallest M_z step (Nm) after which the applied angle reaches 99 % of its range
    (0 for an unstable loop; ``hi_limit`` if not reached below it)."""
    limit = math.radians(models.actuator.limit_deg)
    goal = APPLIED_FRACTION * limit

    def reaches(m_z: float) -> bool:
        tr = _step(params, config, config.ts, delay_steps, models, m_z)
        return not tr.stable or float(np.max(np.abs(tr.applied))) >= goal

    probe = 1.0
    tr = _step(params, config, config.ts, delay_steps, models, probe)
    if not tr.stable:
        return 0.0
    per_nm = float(np.max(np.abs(tr.applied))) / probe
    if per_nm <= 0.0:
        return hi_limit
    lo = min(goal / per_nm, hi_limit)  # linear: the least it can be, and exact while the command is unsaturated
    if reaches(lo * (1.0 + 1e-9)):
        return lo
    hi = lo
    while not reaches(hi):
        if hi >= hi_limit:
            return hi_limit
        lo, hi = hi, min(2.0 * hi, hi_limit)
    while hi - lo > _BISECT_REL * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if reaches(mid) else (mid, hi)
    return hi


@dataclass(frozen=True)
class DryRoadFigures:
    speeds: tuple[float, ...]
    threshold_nm: tuple[float, ...]
    peak_yaw_rate: tuple[float, ...]

    def as_dict(self) -> dict[str, Any]:
        return {"m_z_nm": OBJECTIVE_MZ, "mu": 1.0, "duration_s": STEP_DURATION,
                "points": [{"v": v, "threshold_nm": t, "peak_yaw_rate_rad_s": p}
                           for v, t, p in zip(self.speeds, self.threshold_nm, self.peak_yaw_rate)]}


def dry_road(config: mr.ControllerConfig, delay_steps: int, models: LoopModels = IDEAL,
             base: VehicleParams = VehicleParams(), speeds: tuple[float, ...] = SPEEDS) -> DryRoadFigures:
    pts = [base.at(v=v, mu=1.0) for v in speeds]
    return DryRoadFigures(tuple(speeds), tuple(applied_threshold(p, config, delay_steps, models) for p in pts),
                          tuple(peak_yaw_rate(p, config, delay_steps, models) for p in pts))


#: name: (limit, the worst is the largest) of every constraint the report checks.
LIMITS: dict[str, tuple[float, bool]] = {
    "max_pole_radius": (1.0, True),
    "gain_margin_db": (6.0, False),
    "phase_margin_deg": (45.0, False),
    "extra_delay_pole_radius": (1.0, True),
    "tau_range_pole_radius": (1.0, True),
    "noise_rms_deg": (NOISE_MAX_DEG, True),
    "threshold_nm": (THRESHOLD_MIN_NM, False),
}


@dataclass(frozen=True)
class ConstraintReport:
    """Every constraint's figure per point, the worst of each, where, its limit and verdict."""

    margins: Any  # margins.EnvelopeMargins
    points: list[PointConstraints]
    dry: DryRoadFigures

    def worst(self) -> dict[str, dict[str, Any]]:
        rows = [(m.as_dict(), vars(c)) for m, c in zip(self.margins.points, self.points)]
        out: dict[str, dict[str, Any]] = {}
        for key, (limit, largest) in LIMITS.items():
            if key == "threshold_nm":
                cands = [({"v": v, "mu": 1.0}, t) for v, t in zip(self.dry.speeds, self.dry.threshold_nm)]
            else:
                cands = [({"v": m["v"], "mu": m["mu"], "mass": m["mass"]}, {**m, **c}[key]) for m, c in rows]
                cands = [(w, x) for w, x in cands if x is not None]
            if not cands:
                out[key] = {"value": None, "limit": limit, "pass": True, "where": None}
                continue
            where, value = (max if largest else min)(cands, key=lambda wx: wx[1])
            ok = value < limit if key.endswith("radius") else value <= limit if largest else value >= limit
            # A point without a crossover has an infinite margin; an unstable one fails its radius.
            out[key] = {"value": _finite(value), "limit": limit, "pass": bool(ok), "where": where}
        return out

    @property
    def passes(self) -> bool:
        return all(w["pass"] for w in self.worst().values())

    def binding(self) -> list[str]:
        return [k for k, w in self.worst().items() if not w["pass"]]

    def as_dict(self) -> dict[str, Any]:
        return {"passes": self.passes, "failing": self.binding(), "worst": self.worst(), "dry_road": self.dry.as_dict(),
                "points": [c.as_dict() for c in self.points]}


def evaluate(config: mr.ControllerConfig, delay_steps: int, margins: Any, models: LoopModels = IDEAL,
             base: VehicleParams = VehicleParams(), progress=None) -> ConstraintReport:
    """The constraints at the points of ``margins`` (an ``EnvelopeMargins`` of the same loop)."""
    pts = []
    for i, m in enumerate(margins.points):
        pts.append(point_constraints(base.at(v=m.v, mu=m.mu, mass=m.mass), config, delay_steps, models))
        if progress is not None:
            progress(i + 1, len(margins.points))
    return ConstraintReport(margins, pts, dry_road(config, delay_steps, models, base))
