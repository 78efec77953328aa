"""The trade-off of issue 15 (item 4): named calibrations side by side, and a cloud of candidates.

``compare()`` evaluates each named calibration on the ideal loop (the paper's G_sa = 1, exact
sensors) and on the reference loop (first-order 20 ms actuator within +-3 deg, 2nd-order 30 Hz
Butterworth on the measured yaw rate), both at 500 Hz with one sample of loop delay and the
paper's linear car, over an operating envelope: stability (largest pole radius), the worst gain,
phase and delay margins (``margins``), the worst H2 command noise and the dry-road peaks and
applied-angle saturation thresholds (``constraints``).

``cloud()`` scores candidate calibrations on the reference loop by the peak yaw rate at the
Figure-10 point (4000 Nm, 10 m/s, mu 1) against the worst command noise, and says whether each
meets every constraint (checked cheapest first, stopping at the first failure) on a coarse
envelope; ``plot_png()`` draws it.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import PAPER_MASS, VehicleParams
from sim_plant.offline import constraints as C
from sim_plant.offline.discrete_loop import max_pole_radius
from sim_plant.offline.loop_plant import LoopModels
from sim_plant.offline.margins import Envelope, envelope_margins, point_margins

DELAY_STEPS = 1
TARGET_PEAK = 0.045  # rad/s at the Figure-10 point (issue 15)
STRETCH_PEAK = 0.043
FIG10 = VehicleParams().at(v=10.0, mu=1.0)
#: The cloud's feasibility envelope: the breakpoints and points between them, the friction and
#: mass extremes and two frictions between (64 points).
CLOUD_ENVELOPE = Envelope(speeds=(5.0, 7.5, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0), frictions=(0.1, 0.4, 0.7, 1.0),
                          masses=(PAPER_MASS, 1800.0))
LOOPS = {"ideal": LoopModels.ideal(), "reference": LoopModels.reference()}
#: What every figure of this module assumes (docs beside the table and the plot).
ASSUMES = ("500 Hz, one sample of loop delay, the paper's linear single-track car (eq. 14, ZOH); ideal loop: "
           "G_sa = 1 and exact sensors; reference loop: first-order 20 ms actuator within +-3 deg (exact ZOH "
           "cascade), 2nd-order 30 Hz Butterworth on the measured yaw rate; step responses with noise-free "
           "sensors, noise from white yaw-rate noise of 0.014 deg/s/sqrt(Hz) (exact H2)")

Progress = Callable[[str, int, int], None]


def named_calibrations() -> list[tuple[str, mr.ControllerConfig]]:
    """The rows of the trade-off table.

    The paper's tuning is K = 10, tau = 6 ms, tau_n = 20 ms; ``PAPER_CONFIG`` runs it at 1 kHz
    without modelled delay (the paper's plain structure).  At 500 Hz with the one sample of delay
    every row has, that plain law is unstable even on the ideal loop, so the paper's gains are
    also shown with the delay modelled (M = 1), the structure the product runs: that is the fair
    comparison of the gains."""
    paper = replace(mr.PAPER_CONFIG, ts=0.002)
    return [("paper K 10, tau 6 ms, M 0", paper),
            ("paper K 10, tau 6 ms, M 1", replace(paper, model_delay_steps=1)),
            ("previous K 43, tau 21.2 ms, M 1", mr.PREVIOUS_CONFIG),
            ("shipped schedule", mr.ControllerConfig())]


@dataclass(frozen=True)
class LoopFigures:
    stable: bool
    max_pole_radius: float
    gain_margin_db: float | None
    phase_margin_deg: float | None
    delay_margin_samples: float | None
    delay_margin_s: float | None
    worst_noise_deg: float | None  # None: unbounded (an unstable loop)
    peak_yaw_rate: dict[float, float]  # v -> rad/s, 4000 Nm on mu 1
    threshold_nm: dict[float, float]  # v -> Nm, applied angle at 99 % of its range
    passes: bool  # every constraint of issue 15 on this loop and envelope
    failing: list[str]
    where: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        d = dict(vars(self))
        d["peak_yaw_rate"] = {f"{v:g}": x for v, x in self.peak_yaw_rate.items()}
        d["threshold_nm"] = {f"{v:g}": x for v, x in self.threshold_nm.items()}
        return d


def loop_figures(cfg: mr.ControllerConfig, models: LoopModels, envelope: Envelope,
                 progress: Callable[[int, int], None] | None = None) -> LoopFigures:
    m = envelope_margins(cfg, DELAY_STEPS, envelope, models=models, progress=progress)
    rep = C.evaluate(cfg, DELAY_STEPS, m, models)
    w, cw = m.worst(), rep.worst()
    dry = rep.dry
    return LoopFigures(
        stable=m.stable, max_pole_radius=w["max_pole_radius"],
        gain_margin_db=w["gain_margin_db"] if m.stable else None,
        phase_margin_deg=w["phase_margin_deg"] if m.stable else None,
        delay_margin_samples=w["delay_margin_samples"], delay_margin_s=w["delay_margin_s"],
        worst_noise_deg=cw["noise_rms_deg"]["value"],
        peak_yaw_rate=dict(zip(dry.speeds, dry.peak_yaw_rate)), threshold_nm=dict(zip(dry.speeds, dry.threshold_nm)),
        passes=rep.passes, failing=rep.binding(),
        where={**w["where"], "noise_rms_deg": cw["noise_rms_deg"]["where"]})


def compare(envelope: Envelope = Envelope(), progress: Progress | None = None) -> dict[str, dict[str, LoopFigures]]:
    """name -> loop ("ideal", "reference") -> figures, for every named calibration."""
    out: dict[str, dict[str, LoopFigures]] = {}
    for name, cfg in named_calibrations():
        out[name] = {}
        for loop, models in LOOPS.items():
            say = None if progress is None else (lambda d, n, s=f"{name}, {loop} loop": progress(s, d, n))
            out[name][loop] = loop_figures(cfg, models, envelope, say)
    return out


def _f(x: float | None, spec: str, none: str = "—") -> str:
    return none if x is None else format(x, spec)


def markdown(result: dict[str, dict[str, LoopFigures]]) -> str:
    """The trade-off table: one row per calibration, ideal and reference loop side by side."""
    cols = ["stable (max radius)", "GM dB", "PM deg", "delay margin (samples)", "peak r 10/20/40 m/s (rad/s)",
            "worst noise (deg)", "threshold 10/20/40 (Nm)", "all constraints"]
    head = "| calibration | loop | " + " | ".join(cols) + " |"
    lines = [head, "|" + "---|" * (len(cols) + 2)]
    for name, loops in result.items():
        for loop, f in loops.items():
            stable = f"{'yes' if f.stable else '**no**'} ({f.max_pole_radius:.4f})"
            peaks = " / ".join(f"{x:.4f}" for x in f.peak_yaw_rate.values()) + ("" if f.stable else " (diverging)")
            thr = " / ".join(f"{x:.0f}" for x in f.threshold_nm.values())
            verdict = "pass" if f.passes else "fails " + ", ".join(f.failing)
            dm = _f(f.delay_margin_samples, ".2f", "—" if not f.stable else "unbounded")
            lines.append(f"| {name} | {loop} | {stable} | {_f(f.gain_margin_db, '.2f')} | "
                         f"{_f(f.phase_margin_deg, '.1f')} | {dm} | {peaks} | "
                         f"{_f(f.worst_noise_deg, '.3f', 'unbounded')} | {thr} | {verdict} |")
    return "\n".join(lines)


@dataclass(frozen=True)
class Candidate:
    name: str
    peak: float  # rad/s at the Figure-10 point, reference loop
    worst_noise_deg: float  # inf when unstable somewhere
    feasible: bool
    failing: str | None  # the first constraint found failing
    named: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {**vars(self), "worst_noise_deg": None if math.isinf(self.worst_noise_deg) else self.worst_noise_deg}


def first_failure(cfg: mr.ControllerConfig, models: LoopModels, points: list[VehicleParams]) -> str | None:
    """The first constraint of issue 15 that ``cfg`` fails at ``points`` (cheapest first), or None."""
    coeffs = mr.configure(cfg)
    n = DELAY_STEPS
    if any(max_pole_radius(p, coeffs, n, models) >= 1.0 for p in points):
        return "max_pole_radius"
    if any(C.noise_rms_deg(p, coeffs, n, models) > C.NOISE_MAX_DEG for p in points):
        return "noise_rms_deg"
    if any(max_pole_radius(p, coeffs, n + 1, models) >= 1.0 for p in points):
        return "extra_delay_pole_radius"
    if models.actuator.order and any(max_pole_radius(p, coeffs, n, models.with_time_constant_scaled(f)) >= 1.0
                                     for f in C.TAU_FACTORS for p in points):
        return "tau_range_pole_radius"
    for p in points:
        m = point_margins(p, cfg, n, with_delay_margin=False, models=models)
        if m.gain_margin_db is not None and m.gain_margin_db < C.LIMITS["gain_margin_db"][0]:
            return "gain_margin_db"
        if m.phase_margin_deg is not None and m.phase_margin_deg < C.LIMITS["phase_margin_deg"][0]:
            return "phase_margin_deg"
    base = VehicleParams()
    if any(C.applied_threshold(base.at(v=v, mu=1.0), cfg, n, models) < C.THRESHOLD_MIN_NM for v in C.SPEEDS):
        return "threshold_nm"
    return None


def score(name: str, cfg: mr.ControllerConfig, envelope: Envelope = CLOUD_ENVELOPE,
          models: LoopModels = LOOPS["reference"], named: bool = False) -> Candidate:
    pts = envelope.points()
    coeffs = mr.configure(cfg)
    noise = max(C.noise_rms_deg(p, coeffs, DELAY_STEPS, models) for p in pts)
    why = first_failure(cfg, models, pts)
    return Candidate(name, C.peak_yaw_rate(FIG10, cfg, DELAY_STEPS, models), noise, why is None, why, named)


def scaled_schedule(cfg: mr.ControllerConfig, k: float = 1.0, tau_q: float = 1.0, tau_n: float = 1.0
                    ) -> mr.ControllerConfig:
    """``cfg``'s schedule with K, tau_Q = tau / (1 + K) and tau_n scaled at every breakpoint."""
    ks = tuple(x * k for x in cfg.schedule_k)
    tqs = tuple(t / (1.0 + x) * tau_q for t, x in zip(cfg.schedule_tau, cfg.schedule_k))
    return replace(cfg, schedule_k=ks, schedule_tau=tuple(t * (1.0 + x) for t, x in zip(tqs, ks)),
                   schedule_tau_n=tuple(x * tau_n for x in cfg.schedule_tau_n))


CLOUD_FACTORS = (0.6, 0.75, 0.9, 1.1, 1.25, 1.5)


#: The best constant-gain plain law on the reference loop (``design tune --reference``, docs/design.md).
PLAIN_RETUNE = mr.plain_law(mr.ControllerConfig(), 2.48, 0.001, 0.005)


def cloud_configs(base: mr.ControllerConfig | None = None) -> list[tuple[str, mr.ControllerConfig]]:
    """The shipped schedule with each of K, tau_Q, tau_n scaled alone, and K with tau_Q together;
    and the plain retune of the previous structure."""
    b = base or mr.ControllerConfig()
    out = [("plain retune K 2.48, M 0", replace(PLAIN_RETUNE, model_delay_steps=0))]
    out += [(f"K x{f:g}", scaled_schedule(b, k=f)) for f in CLOUD_FACTORS]
    out += [(f"tau_Q x{f:g}", scaled_schedule(b, tau_q=f)) for f in CLOUD_FACTORS]
    out += [(f"tau_n x{f:g}", scaled_schedule(b, tau_n=f)) for f in CLOUD_FACTORS]
    out += [(f"K x{a:g}, tau_Q x{c:g}", scaled_schedule(b, k=a, tau_q=c))
            for a in (0.8, 1.25) for c in (0.8, 1.25)]
    return out


def cloud(extra: list[tuple[str, mr.ControllerConfig]] = (), envelope: Envelope = CLOUD_ENVELOPE,
          progress: Progress | None = None) -> list[Candidate]:
    """Every candidate (the named calibrations first) scored on the reference loop."""
    items = [(n, c, True) for n, c in named_calibrations()] + [(n, c, False) for n, c in [*cloud_configs(), *extra]]
    out = []
    for i, (name, cfg, named) in enumerate(items):
        out.append(score(name, cfg, envelope, named=named))
        if progress is not None:
            progress("cloud", i + 1, len(items))
    return out


def plot_png(cands: list[Candidate], noise_cap: float = 1.0) -> bytes:
    """Peak yaw rate at the Figure-10 point against worst command noise (PNG bytes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    for feasible, style, label in ((True, dict(marker="o", color="tab:blue"), "meets every constraint"),
                                   (False, dict(marker="x", color="tab:red"), "fails a constraint")):
        pts = [c for c in cands if c.feasible == feasible and not c.named]
        ax.scatter([min(c.worst_noise_deg, noise_cap) for c in pts], [c.peak for c in pts], label=label,
                   **style, s=28)
    for c in cands:
        if c.named:
            x = min(c.worst_noise_deg, noise_cap)
            shipped = c.name.startswith("shipped")
            ax.scatter([x], [c.peak], marker="*" if shipped else "s", s=220 if shipped else 60,
                       color="gold" if shipped else "none", edgecolors="black", zorder=5)
            note = "" if c.feasible else " (unstable)" if c.failing == "max_pole_radius" else f" (fails {c.failing})"
            ax.annotate(c.name + note, (x, c.peak), textcoords="offset points", xytext=(-6, 6), fontsize=7, ha="right")
    ax.axhline(TARGET_PEAK, color="green", ls="--", lw=1, label=f"target {TARGET_PEAK} rad/s")
    ax.axhline(STRETCH_PEAK, color="green", ls=":", lw=1, label=f"stretch {STRETCH_PEAK} rad/s")
    ax.axvline(C.NOISE_MAX_DEG, color="purple", ls="--", lw=1, label=f"noise limit {C.NOISE_MAX_DEG} deg")
    ax.set_xscale("log")
    ax.set_xlabel(f"worst command noise over the envelope, deg RMS (unbounded drawn at {noise_cap:g})")
    ax.set_ylabel("peak yaw rate, 4000 Nm at 10 m/s, mu 1 [rad/s]")
    ax.set_title("Reference loop: 500 Hz, 1 sample, 20 ms actuator +-3 deg, 30 Hz Butterworth", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(True, which="both", alpha=0.3)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()
