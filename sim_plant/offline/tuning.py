"""Choosing K, tau and tau_n of the discrete limited-integrator regulator (issue 5).

Objective: the disturbance rejection the paper measures (Figure 10): the peak yaw rate after a
4000 Nm yaw-moment step at 10 m/s on dry road, driver's wheel held, simulated with the
firmware's own step() at the given rate and loop delay (``simulate_discrete``; saturation
included).  Smaller is better.

Constraints: gain margin >= 6 dB and phase margin >= 45 deg at every point of the operating
envelope, with a stable closed loop (``sim_plant.offline.margins``).  With an actuator or sensor
model in the loop (``LoopModels``, e.g. issue 15's reference loop) also the constraints of
``sim_plant.offline.constraints``: stable with one more sample of delay and for the actuator's
time constant x0.5 and x2, command noise <= 0.15 deg RMS, applied-angle saturation threshold
>= 6119 Nm on dry road; candidates are checked in the objective's order, and if none of the
margin-feasible ones meets them, ``TuneInfeasible`` says which constraint failed how often.

Both controller structures are searched: the plain law (the yaw rate compared with the command
being computed) and the one that models the known loop delay in the nominal model (compared
with the command issued N steps ago, ``model_delay_steps``), as discrete disturbance observers
commonly do.

Search: (1) a screen of a log-spaced (K, tau, tau_n) grid on a coarse envelope, with the loop
frequency response of all points evaluated at once and crossovers read off a dense frequency
grid; (2) the feasible candidates ranked by the objective; (3) a coordinate refinement of the
best along K and tau with the exact margins on the coarse envelope; (4) the winner checked with
the exact margins on the full envelope (and the next candidate taken if it fails there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from firmware_py import model_regulator as mr
from sim_plant.offline.closed_loop import Experiment, simulate_discrete
from sim_plant.offline.margins import (Envelope, EnvelopeMargins, LoopResponse, Margins, envelope_margins, law_response,
                               point_margins)
from sim_plant.car.vehicle import PAPER_MASS, VehicleParams
from sim_plant.offline import constraints
from sim_plant.offline.constraints import ConstraintReport
from sim_plant.offline.discrete_loop import IDEAL, max_pole_radius
from sim_plant.offline.loop_plant import LoopModels

GM_MIN_DB = 6.0
PM_MIN_DEG = 45.0
OBJECTIVE_POINT = VehicleParams(v=10.0, mu=1.0)  # Figure 10's operating point
OBJECTIVE_MZ = 4000.0  # Nm, the paper's disturbance step
OBJECTIVE_DURATION = 1.5  # s: the peak comes well inside the driver's reaction time

# Search box.  K above 50 (q0 = K/(1+K) > 0.98) would make the limited integrator a plain one,
# and the low-frequency action would no longer fade for the driver (the point of eq. 22).
K_BOUNDS = (0.5, 50.0)
TAU_BOUNDS = (0.001, 1.0)
K_GRID = tuple(float(x) for x in np.geomspace(*K_BOUNDS, 24))
TAU_GRID = tuple(float(x) for x in np.geomspace(0.002, 0.5, 25))
TAU_N_GRID = (0.005, 0.01, 0.02, 0.05, 0.1)
COARSE_STRIDE = 3  # ``tune(coarse=True)``: every third K and tau of the grids (a smoke run, ~1/9 the work)

SCREEN_ENVELOPE = Envelope(speeds=(5.0, 10.0, 20.0, 35.0, 50.0), frictions=(0.1, 0.3, 0.6, 1.0),
                           masses=(PAPER_MASS, 1800.0))

Progress = Callable[[str, int, int], None]


def objective(config: mr.ControllerConfig, delay_steps: int, models: LoopModels = IDEAL) -> float:
    """Peak |yaw rate| (rad/s) after the 4000 Nm step at 10 m/s on dry road (noise-free sensors)."""
    exp = Experiment(OBJECTIVE_POINT, config.q_form, config, m_z=OBJECTIVE_MZ, duration=OBJECTIVE_DURATION)
    tr = simulate_discrete(exp, config.ts, delay_steps, models.deterministic())
    if not tr.stable:
        return math.inf
    return float(np.max(np.abs(tr.yaw_rate)))


class _Screen:
    """Vectorised margin screen: plant responses of the coarse envelope, computed once."""

    def __init__(self, base: mr.ControllerConfig, delay_steps: int, envelope: Envelope, n_freq: int = 1500,
                 models: LoopModels = IDEAL) -> None:
        self.ts = base.ts
        w_nyq = math.pi / base.ts
        self.w = np.concatenate([np.geomspace(1e-2, w_nyq, n_freq, endpoint=False), [w_nyq]])
        self.z = np.exp(1j * self.w * base.ts)
        coeffs = mr.configure(base)
        self.plant = np.array([LoopResponse(p, coeffs, delay_steps, models).plant_path(self.w)
                               for p in envelope.points()])
        self.speeds = [p.v for p in envelope.points()]

    def passes(self, config: mr.ControllerConfig, gm_min_db: float = GM_MIN_DB, pm_min_deg: float = PM_MIN_DEG) -> bool:
        coeffs = mr.configure(config)
        L = self.plant * np.array([law_response(coeffs, self.z, v) for v in self.speeds])
        mag = np.abs(L)
        # Every phase crossover (Im L changes sign where Re L < 0) below -6 dB ...
        flip = np.signbit(L.imag[:, :-1]) != np.signbit(L.imag[:, 1:])
        neg = (L.real[:, :-1] < 0.0) | (L.real[:, 1:] < 0.0)
        peak = np.maximum(mag[:, :-1], mag[:, 1:])
        if np.any(flip & neg & (peak > 10.0 ** (-gm_min_db / 20.0))):
            return False
        if np.any((L[:, -1].real < 0.0) & (mag[:, -1] > 10.0 ** (-gm_min_db / 20.0))):
            return False
        # ... and every gain crossover with 45 deg of phase to spare.
        cross = (mag[:, :-1] >= 1.0) != (mag[:, 1:] >= 1.0)
        pm = 180.0 - np.abs(np.degrees(np.angle(L)))
        worst_pm = np.minimum(pm[:, :-1], pm[:, 1:])
        return not np.any(cross & (worst_pm < pm_min_deg))


def _meets(m: EnvelopeMargins) -> bool:
    return all(_point_meets(p) for p in m.points)


@dataclass(frozen=True)
class TuneResult:
    config: mr.ControllerConfig
    delay_steps: int
    objective_peak_yaw_rate: float
    margins: EnvelopeMargins
    screened: int
    feasible: int
    constraints: ConstraintReport | None = None  # with an actuator or sensor model in the loop

    def as_dict(self) -> dict[str, Any]:
        c = self.config
        w = self.margins.worst()
        extra = {} if self.constraints is None else {"constraint_figures": self.constraints.as_dict()}
        return {**extra,
            "ts": c.ts, "rate_hz": 1.0 / c.ts, "delay_steps": self.delay_steps, "controller": c.q_form,
            **mr.describe_gains(c),
            "objective": {"peak_yaw_rate_rad_s": self.objective_peak_yaw_rate, "m_z_nm": OBJECTIVE_MZ,
                          "v": OBJECTIVE_POINT.v, "mu": OBJECTIVE_POINT.mu},
            "constraints": {"gain_margin_db_min": GM_MIN_DB, "phase_margin_deg_min": PM_MIN_DEG},
            "stable": self.margins.stable, "worst": w,
            "search": {"screened": self.screened, "feasible": self.feasible},
        }


class TuneInfeasible(ValueError):
    """No candidate meets every constraint; the message says which bind and the best found."""


def tune(ts: float, delay_steps: int, envelope: Envelope = Envelope(), q_form: str = mr.Q_LIMITED,
         base: mr.ControllerConfig | None = None, progress: Progress | None = None,
         models: LoopModels = IDEAL, coarse: bool = False) -> TuneResult:
    """Best-rejecting (K, tau, tau_n) that keeps the margins over ``envelope``; with an actuator
    or sensor model in the loop, also the constraints of ``constraints`` (issue 15).  ``coarse``
    searches every ``COARSE_STRIDE``-th K and tau only: a quick run, not the optimum."""
    say = progress or (lambda *_: None)
    # Constant gains on the base's structure (by default the paper's plain law, the structure
    # this grid search was built for; the shipped law's schedule comes from tune_schedule).
    start = base or mr.PREVIOUS_CONFIG
    cfg0 = replace(mr.constant_gains(start, *(start.gain_points()[0])), ts=ts, q_form=q_form)
    mr.configure(cfg0)
    screen = _Screen(cfg0, delay_steps, SCREEN_ENVELOPE, models=models)
    checks = _Checks(delay_steps, models)

    # The firmware may model the loop delay (w compares the yaw rate with the command issued
    # N steps ago) or not: both structures are searched.
    plain = cfg0.model_actuator_tau == 0.0 and cfg0.model_filter_hz == 0.0
    delays = sorted({0, min(delay_steps, mr.MAX_MODEL_DELAY)} if plain else {max(1, min(delay_steps, mr.MAX_MODEL_DELAY))})
    stride = COARSE_STRIDE if coarse else 1
    candidates = [replace(cfg0, k=k, tau=t, tau_n=tn, model_delay_steps=m)
                  for m in delays for tn in TAU_N_GRID for k in K_GRID[::stride] for t in TAU_GRID[::stride]]
    feasible = []
    for i, c in enumerate(candidates):
        if screen.passes(c):
            feasible.append(c)
        if i % 200 == 0 or i == len(candidates) - 1:
            say("screen", i + 1, len(candidates))
    if not feasible:
        raise TuneInfeasible(f"no (K, tau, tau_n) on the search grid meets GM >= {GM_MIN_DB:g} dB and "
                             f"PM >= {PM_MIN_DEG:g} deg at ts = {ts:g} s with {delay_steps} samples of delay")
    scored = []
    for i, c in enumerate(feasible):
        scored.append((objective(c, delay_steps, models), i, c))
        if i % 50 == 0 or i == len(feasible) - 1:
            say("rank", i + 1, len(feasible))
    scored.sort()
    if checks.active:
        scored = checks.first_passing(scored, SCREEN_ENVELOPE.points(), say)

    # Refine the best candidate with exact margins on the coarse envelope plus every point
    # where a refined design has failed on the full envelope so far (an active set).
    critical = SCREEN_ENVELOPE.points()
    for attempt in range(6):
        score, _, c = scored[0]
        best, best_score = _refine(c, score, delay_steps, critical, say, checks)
        full = envelope_margins(best, delay_steps, envelope, with_delay_margin=False, models=models,
                                progress=lambda d, n: say("verify", d, n) if d % 50 == 0 or d == n else None)
        failing = [envelope.points()[i] for i, p in enumerate(full.points) if not _point_meets(p)]
        if not failing and checks.active:
            failing = checks.failing_points(best, envelope.points())
        if not failing:
            # The delay margins (a pole search per point) only for the design reported.
            full = envelope_margins(best, delay_steps, envelope, models=models,
                                    progress=lambda d, n: say("delay margins", d, n) if d % 50 == 0 or d == n else None)
            report = constraints.evaluate(best, delay_steps, full, models) if checks.active else None
            return TuneResult(best, delay_steps, best_score, full, len(candidates), len(feasible), report)
        critical += failing
    raise ValueError("the refined design kept failing on the full envelope; use a coarser envelope grid")


class _Checks:
    """The constraints besides the margins, checked cheapest and most likely to fail first
    (active only with an actuator or sensor model in the loop)."""

    def __init__(self, delay_steps: int, models: LoopModels) -> None:
        self.delay_steps, self.models = delay_steps, models
        self.active = not models.is_ideal

    def first_failure(self, config: mr.ControllerConfig, points: list[VehicleParams]) -> str | None:
        coeffs = mr.configure(config)
        n, m = self.delay_steps, self.models
        if any(constraints.noise_rms_deg(p, coeffs, n, m) > constraints.NOISE_MAX_DEG for p in points):
            return "noise_rms_deg"
        if any(max_pole_radius(p, coeffs, n + 1, m) >= 1.0 for p in points):
            return "extra_delay_pole_radius"
        if m.actuator.order and any(max_pole_radius(p, coeffs, n, m.with_time_constant_scaled(f)) >= 1.0
                                    for f in (constraints.TAU_FACTORS[0], constraints.TAU_FACTORS[-1])
                                    for p in points):
            return "tau_range_pole_radius"
        base = VehicleParams()
        if any(constraints.applied_threshold(base.at(v=v, mu=1.0), config, n, m) < constraints.THRESHOLD_MIN_NM
               for v in constraints.SPEEDS):
            return "threshold_nm"
        return None

    def first_passing(self, scored: list, points: list[VehicleParams], say: Callable[..., None]) -> list:
        """``scored`` from its first candidate that meets every constraint at ``points``."""
        tally: dict[str, int] = {}
        for i, (score, _, c) in enumerate(scored):
            why = self.first_failure(c, points)
            if why is None:
                return scored[i:]
            tally[why] = tally.get(why, 0) + 1
            if i % 50 == 0:
                say("constraints", i + 1, len(scored))
        best = scored[0]
        raise TuneInfeasible(
            f"none of the {len(scored)} candidates that meet GM >= {GM_MIN_DB:g} dB and PM >= {PM_MIN_DEG:g} deg "
            f"meets the other constraints (first failing: {tally}); the best by the objective, K = {best[2].k:.4g}, "
            f"tau = {best[2].tau:.4g} s, tau_n = {best[2].tau_n:g} s, M = {best[2].model_delay_steps}, "
            f"peaks at {best[0]:.4f} rad/s")

    def failing_points(self, config: mr.ControllerConfig, points: list[VehicleParams]) -> list[VehicleParams]:
        """Points of the envelope where a pole or noise constraint fails (the threshold is global)."""
        return [p for p in points if self.first_failure(config, [p]) not in (None, "threshold_nm")]


def _point_meets(m: Margins) -> bool:
    # A negative reported gain margin (a gain reduction destabilises) fails as well.
    return (m.stable and (m.gain_margin_db is None or m.gain_margin_db >= GM_MIN_DB)
            and (m.phase_margin_deg is None or m.phase_margin_deg >= PM_MIN_DEG))


def _meets_at(config: mr.ControllerConfig, delay_steps: int, points: list[VehicleParams],
              models: LoopModels = IDEAL) -> bool:
    return all(_point_meets(point_margins(p, config, delay_steps, with_delay_margin=False, models=models))
               for p in points)


def _refine(c: mr.ControllerConfig, score: float, delay_steps: int, points: list[VehicleParams],
            say: Callable[..., None], checks: "_Checks") -> tuple[mr.ControllerConfig, float]:
    """Coordinate search in log K and log tau with exact margins at ``points``."""
    step = 0.25  # in log space: the screening grid's spacing is about 0.2
    rounds = 0
    while step > 0.01 and rounds < 60:
        rounds += 1
        improved = False
        for dk, dt in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1), (1, -1), (-1, 1)):
            trial = replace(c, k=min(max(c.k * math.exp(dk * step), K_BOUNDS[0]), K_BOUNDS[1]),
                            tau=min(max(c.tau * math.exp(dt * step), TAU_BOUNDS[0]), TAU_BOUNDS[1]))
            if (trial.k, trial.tau) == (c.k, c.tau):
                continue
            s = objective(trial, delay_steps, checks.models)
            if (s < score and _meets_at(trial, delay_steps, points, checks.models)
                    and (not checks.active or checks.first_failure(trial, points) is None)):
                c, score, improved = trial, s, True
                break
        if not improved:
            step /= 2.0
        say("refine", rounds, 60)
    return c, score
