"""Tuning the shipped law's speed schedule (issue 15): K, tau_Q and tau_n per breakpoint.

The structure is the shipped one (docs/controller.md): the nominal actuator and yaw-rate filter
in the nominal model, M = 1, and K, tau = tau_Q (1 + K) of eq. (22) and tau_n of eq. (18) at
the speed breakpoints of the starting calibration.  ``step()`` interpolates the *coefficients*
linearly between breakpoints, so a breakpoint's values act on the whole interval between its
neighbours: every figure here is computed on the interpolated law (``mr.law_at``, through
``discrete_loop``, ``margins`` and ``simulate_discrete``).

Per breakpoint i (Gauss-Seidel: in order, the others held at their current values):

* objective: the peak yaw rate after the 4000 Nm step at v_i on mu = 1 (``constraints.peak_yaw_rate``
  on the given loop; at 10 m/s this is the Figure-10 point);
* constraints, at every point it influences (speeds from v_{i-1} to v_{i+1} on a grid, times the
  friction and mass grids): stable, GM >= 6 dB, PM >= 45 deg, stable with one more sample and for
  the actuator's time constant x0.5..x2, H2 command noise <= 0.15 deg; and the applied-angle
  saturation threshold >= 6119 Nm at the dry-road speeds of ``constraints.SPEEDS`` inside
  (v_{i-1}, v_{i+1});
* search: a compass search in (log K, log tau_Q, log tau_n), a trial accepted when it is better
  in (total violation, peak) order, so that an infeasible start first moves to feasibility.  The
  constraints are checked during the search at an active set (the tightest points of the local
  grid, per constraint), then on the whole local grid; failing points join the set and the search repeats.

Finally the whole schedule is verified on the full envelope (``envelope_margins`` and
``constraints.evaluate``); points that fail join the active sets of the breakpoints that
influence them and those breakpoints are refined again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import PAPER_MASS, VehicleParams
from sim_plant.offline import constraints as C
from sim_plant.offline.discrete_loop import max_pole_radius
from sim_plant.offline.loop_plant import LoopModels
from sim_plant.offline.margins import Envelope, envelope_margins, point_margins

DELAY_STEPS = 1
GM_MIN_DB = C.LIMITS["gain_margin_db"][0]
PM_MIN_DEG = C.LIMITS["phase_margin_deg"][0]
K_BOUNDS = (0.5, 60.0)
TAU_Q_BOUNDS = (2e-4, 0.1)
TAU_N_BOUNDS = (0.002, 1.0)

Progress = Callable[[str], None]


@dataclass(frozen=True)
class Grids:
    """How finely the search works: local speed step, frictions and masses, compass steps."""

    speed_step: float = 2.5
    frictions: tuple[float, ...] = tuple(float(x) for x in np.linspace(0.1, 1.0, 10))
    masses: tuple[float, ...] = (PAPER_MASS, 1548.0, 1800.0)
    steps: tuple[float, ...] = (0.08, 0.04, 0.02, 0.01)  # compass step sizes in log space
    active: int = 2  # tightest local points of each constraint kept in the active set
    max_trials: int = 80  # per breakpoint and round
    rounds: int = 3  # local (and global) re-refinements after failures


FULL = Grids()
QUICK = Grids(speed_step=5.0, frictions=(0.1, 1.0), masses=(PAPER_MASS, 1800.0), steps=(0.08,), active=1,
              max_trials=4, rounds=1)


def gains(cfg: mr.ControllerConfig) -> list[list[float]]:
    """[log K, log tau_Q, log tau_n] per breakpoint."""
    return [[math.log(k), math.log(t / (1.0 + k)), math.log(tn)]
            for k, t, tn in zip(cfg.schedule_k, cfg.schedule_tau, cfg.schedule_tau_n)]


def with_gains(cfg: mr.ControllerConfig, x: list[list[float]]) -> mr.ControllerConfig:
    ks = tuple(math.exp(p[0]) for p in x)
    return replace(cfg, schedule_k=ks, schedule_tau=tuple(math.exp(p[1]) * (1.0 + k) for p, k in zip(x, ks)),
                   schedule_tau_n=tuple(math.exp(p[2]) for p in x))


def _clip(p: list[float]) -> list[float]:
    return [min(max(v, math.log(lo)), math.log(hi)) for v, (lo, hi) in zip(p, (K_BOUNDS, TAU_Q_BOUNDS, TAU_N_BOUNDS))]


def influence(speeds: tuple[float, ...], i: int) -> tuple[float, float]:
    """The speeds whose law breakpoint i changes (held beyond the ends up to the envelope's)."""
    return (speeds[i - 1] if i > 0 else 0.0, speeds[i + 1] if i + 1 < len(speeds) else math.inf)


def local_speeds(speeds: tuple[float, ...], i: int, step: float, lo: float, hi: float) -> list[float]:
    a, b = influence(speeds, i)
    a, b = max(a, lo), min(b, hi)
    grid = set(float(x) for x in np.arange(a, b + 1e-9, step)) | {speeds[i], a, b}
    return sorted(v for v in grid if lo <= v <= hi)


def point_slack(cfg: mr.ControllerConfig, p: VehicleParams, models: LoopModels,
                factors: tuple[float, ...] = (C.TAU_FACTORS[0], C.TAU_FACTORS[-1])) -> dict[str, float]:
    """Normalised slack of every per-point constraint at ``p`` (>= 0: met)."""
    coeffs = mr.configure(cfg)
    r = max_pole_radius(p, coeffs, DELAY_STEPS, models)
    out = {"max_pole_radius": 1.0 - r}
    if r >= 1.0:
        return out
    out["extra_delay_pole_radius"] = 1.0 - max_pole_radius(p, coeffs, DELAY_STEPS + 1, models)
    if models.actuator.order:
        out["tau_range_pole_radius"] = 1.0 - max(max_pole_radius(p, coeffs, DELAY_STEPS,
                                                                 models.with_time_constant_scaled(f)) for f in factors)
    out["noise_rms_deg"] = (C.NOISE_MAX_DEG - C.noise_rms_deg(p, coeffs, DELAY_STEPS, models)) / C.NOISE_MAX_DEG
    m = point_margins(p, cfg, DELAY_STEPS, with_delay_margin=False, models=models)
    if m.gain_margin_db is not None:
        out["gain_margin_db"] = (m.gain_margin_db - GM_MIN_DB) / GM_MIN_DB
    if m.phase_margin_deg is not None:
        out["phase_margin_deg"] = (m.phase_margin_deg - PM_MIN_DEG) / PM_MIN_DEG
    return out


def _violation(slacks: dict[str, float]) -> float:
    # An unstable point counts heavily: nothing else there is meaningful.
    return sum(max(0.0, -s) for s in slacks.values()) + (10.0 if slacks["max_pole_radius"] <= 0.0 else 0.0)


@dataclass
class _Problem:
    """One breakpoint's search: objective point, active set, dry-road speeds, local grid."""

    i: int
    objective: VehicleParams
    local: list[VehicleParams]
    active: list[VehicleParams]
    dry: list[VehicleParams]


def _merit(cfg: mr.ControllerConfig, prob: _Problem, models: LoopModels, bound: tuple[float, float] | None
           ) -> tuple[float, float]:
    """(violation, peak) on the active set; early exit once it cannot beat ``bound``."""
    peak = C.peak_yaw_rate(prob.objective, cfg, DELAY_STEPS, models)
    if bound is not None and bound[0] == 0.0 and peak >= bound[1]:
        return math.inf, peak
    viol = 0.0
    for p in prob.active:
        viol += _violation(point_slack(cfg, p, models))
        if bound is not None and bound[0] == 0.0 and viol > 0.0:
            return viol, peak
    for p in prob.dry:
        thr = C.applied_threshold(p, cfg, DELAY_STEPS, models)
        viol += max(0.0, (C.THRESHOLD_MIN_NM - thr) / C.THRESHOLD_MIN_NM)
    return viol, peak


def _compass(cfg: mr.ControllerConfig, prob: _Problem, models: LoopModels, grids: Grids,
             say: Progress) -> tuple[mr.ControllerConfig, tuple[float, float]]:
    x = gains(cfg)
    best = _merit(cfg, prob, models, None)
    trials = 0
    for step in grids.steps:
        improved = True
        while improved and trials < grids.max_trials:
            improved = False
            for j in range(3):
                for sign in (1.0, -1.0):
                    trial_x = [list(p) for p in x]
                    trial_x[prob.i][j] += sign * step
                    trial_x[prob.i] = _clip(trial_x[prob.i])
                    if trial_x[prob.i] == x[prob.i]:
                        continue
                    trials += 1
                    m = _merit(with_gains(cfg, trial_x), prob, models, best)
                    if m < best:
                        x, best, improved = trial_x, m, True
                        say(f"breakpoint {prob.objective.v:g} m/s: violation {best[0]:.3g}, peak {best[1]:.5f}")
                        break
                if improved or trials >= grids.max_trials:
                    break
    return with_gains(cfg, x), best


def _local_slacks(cfg: mr.ControllerConfig, points: list[VehicleParams], models: LoopModels
                  ) -> list[tuple[dict[str, float], VehicleParams]]:
    """(slacks, point) at every point, all five actuator factors included."""
    return [(point_slack(cfg, p, models, C.TAU_FACTORS), p) for p in points]


def _tightest(slacks: list[tuple[dict[str, float], VehicleParams]], per_key: int) -> list[VehicleParams]:
    """The ``per_key`` points with the least slack of each constraint (the radii's slack is always
    small where the car's own slow mode is, so a single ranking would pick only those)."""
    out: list[VehicleParams] = []
    keys = {k for s, _ in slacks for k in s}
    for key in sorted(keys):
        ranked = sorted((s[key], i) for i, (s, _) in enumerate(slacks) if key in s)
        for _, i in ranked[:per_key]:
            if slacks[i][1] not in out:
                out.append(slacks[i][1])
    return out


def refine_breakpoint(cfg: mr.ControllerConfig, i: int, envelope: Envelope, models: LoopModels, grids: Grids,
                      say: Progress, extra: list[VehicleParams] = ()) -> mr.ControllerConfig:
    """The schedule with breakpoint i refined (see the module docstring)."""
    speeds = cfg.schedule_speed
    base = VehicleParams()
    lo, hi = min(envelope.speeds), max(envelope.speeds)
    local = [base.at(v=v, mu=mu, mass=m) for v in local_speeds(speeds, i, grids.speed_step, lo, hi)
             for mu in grids.frictions for m in grids.masses] + list(extra)
    a, b = influence(speeds, i)
    dry = [base.at(v=v, mu=1.0) for v in C.SPEEDS if a < v < b]
    active = _tightest(_local_slacks(cfg, local, models), grids.active) + list(extra)
    prob = _Problem(i, base.at(v=speeds[i], mu=1.0), local, active, dry)
    start = cfg
    for _ in range(grids.rounds + 1):
        cand, merit = _compass(start, prob, models, grids, say)
        failing = [(s, p) for s, p in _local_slacks(cand, local, models)
                   if min(s.values()) < 0.0 and p not in prob.active]
        if not failing:
            if merit[0] > 0.0:
                say(f"breakpoint {speeds[i]:g} m/s: no feasible point found near the start (violation {merit[0]:.3g})")
            return cand
        # The worst failing points of each constraint join the active set (all of them could be
        # hundreds, and every trial pays for each).
        worst = _tightest(failing, grids.active)
        say(f"breakpoint {speeds[i]:g} m/s: {len(failing)} local points fail; {len(worst)} join the active set")
        prob.active += worst
    return start


@dataclass(frozen=True)
class ScheduleResult:
    config: mr.ControllerConfig
    start: mr.ControllerConfig
    report: C.ConstraintReport
    peaks: dict[float, float]  # breakpoint speed -> peak yaw rate after 4000 Nm on mu 1
    start_peaks: dict[float, float]

    @property
    def passes(self) -> bool:
        return self.report.passes

    def as_dict(self) -> dict[str, Any]:
        c = self.config
        rows = [{"v": v, "k": k, "tau_s": t, "tau_q_s": t / (1.0 + k), "tau_n_s": tn, "peak_yaw_rate_rad_s": self.peaks[v],
                 "start_peak_yaw_rate_rad_s": self.start_peaks[v]}
                for v, k, t, tn in zip(c.schedule_speed, c.schedule_k, c.schedule_tau, c.schedule_tau_n)]
        return {**mr.describe_gains(c), "breakpoints": rows, "passes": self.passes,
                "margins": self.report.margins.as_dict(),
                "constraints": self.report.as_dict()}


def _peaks(cfg: mr.ControllerConfig, models: LoopModels) -> dict[float, float]:
    base = VehicleParams()
    return {v: C.peak_yaw_rate(base.at(v=v, mu=1.0), cfg, DELAY_STEPS, models) for v in cfg.schedule_speed}


def tune_schedule(envelope: Envelope = Envelope(), start: mr.ControllerConfig | None = None,
                  models: LoopModels = LoopModels.reference(), grids: Grids = FULL, progress: Progress | None = None,
                  with_delay_margin: bool = True) -> ScheduleResult:
    """The schedule refined from ``start`` (default: the shipped one) and verified on ``envelope``."""
    say = progress or (lambda _m: None)
    cfg = start or mr.ControllerConfig()
    if not cfg.scheduled or cfg.model_delay_steps != DELAY_STEPS:
        raise ValueError("tune_schedule needs a scheduled calibration with model_delay_steps = 1")
    mr.configure(cfg)
    extra: dict[int, list[VehicleParams]] = {}
    for round_ in range(grids.rounds + 1):
        for i in range(len(cfg.schedule_speed)):
            say(f"refining breakpoint {cfg.schedule_speed[i]:g} m/s (round {round_ + 1})")
            cfg = refine_breakpoint(cfg, i, envelope, models, grids, say, extra.get(i, []))
        say(f"verifying on {len(envelope)} points")
        m = envelope_margins(cfg, DELAY_STEPS, envelope, models=models, with_delay_margin=False)
        report = C.evaluate(cfg, DELAY_STEPS, m, models)
        failing = [(p, c) for p, c in zip(m.points, report.points)
                   if not _point_passes(p, c)]
        if not failing and report.passes:
            break
        say(f"{len(failing)} envelope points fail ({', '.join(report.binding())}); refining again")
        for p, _ in failing:
            for i in range(len(cfg.schedule_speed)):
                a, b = influence(cfg.schedule_speed, i)
                if a < p.v < b:
                    extra.setdefault(i, []).append(VehicleParams().at(v=p.v, mu=p.mu, mass=p.mass))
    if with_delay_margin:
        say("delay margins")
        m = envelope_margins(cfg, DELAY_STEPS, envelope, models=models)
        report = C.evaluate(cfg, DELAY_STEPS, m, models)
    return ScheduleResult(cfg, start or mr.ControllerConfig(), report, _peaks(cfg, models),
                          _peaks(start or mr.ControllerConfig(), models))


def _point_passes(m: Any, c: C.PointConstraints) -> bool:
    return (m.stable and (m.gain_margin_db is None or m.gain_margin_db >= GM_MIN_DB)
            and (m.phase_margin_deg is None or m.phase_margin_deg >= PM_MIN_DEG)
            and c.extra_delay_pole_radius < 1.0 and (c.tau_range_pole_radius is None or c.tau_range_pole_radius < 1.0)
            and c.noise_rms_deg <= C.NOISE_MAX_DEG)
