"""Figures of HIL runs, drawn from their per-step tables (``hil_steps.Step``) over the
scenario's own time, with the scenario's events marked.

matplotlib (the ``plot`` extra) is imported only when a figure is drawn; without it the
functions return None and the caller writes no figure.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from typing import Any, Sequence

from firmware_py import model_regulator as mr
from sim_plant.car import scenario as scn
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.harness.hil_steps import Step, state_names

#: The controller lane's levels, bottom to top: from not yet running to the most severe.
LANE = (mr.STATUS_STARTING, mr.STATUS_INACTIVE, mr.STATUS_ACTIVE, mr.STATUS_SATURATED, mr.STATUS_DEGRADED,
        mr.STATUS_FAULT)
YAW, ANGLES = "yaw rate [rad/s]", "front-wheel angle [deg]"  # the run figure's first two axes
# A faulty sensor's reading beside the truth it measures: (its axis, the true value's Step
# field, the reading's, the unit's scale for the axis); on an axis of its own, the truth is drawn too.
SENSOR_TRACES = {
    "yaw_rate": (YAW, "yaw_rate_rad_s", "yaw_rate_measured_rad_s", 1.0),
    "yaw_rate_redundant": (YAW, "yaw_rate_rad_s", "yaw_rate_redundant_measured_rad_s", 1.0),
    "steer": (ANGLES, "driver_angle_rad", "steer_measured_rad", math.degrees(1.0)),
    "steer_redundant": (ANGLES, "driver_angle_rad", "steer_redundant_measured_rad", math.degrees(1.0)),
    "lat_accel": ("lateral acceleration [m/s²]", "lat_accel_m_s2", "lat_accel_measured_m_s2", 1.0),
    "speed": ("speed [m/s]", "v_m_s", "speed_measured_m_s", 1.0),
    "speed_redundant": ("speed [m/s]", "v_m_s", "speed_redundant_measured_m_s", 1.0),
}


@dataclass(frozen=True)
class Trace:
    """One more line on the run's figure: on ``axis`` (``YAW``, ``ANGLES`` or its own)."""

    axis: str
    label: str
    values: list[float]
    faulty: bool  # a faulty sensor's reading (drawn red) or the true value beside it


def fault_label(f: SensorFault) -> str:
    """``yaw_rate stuck 0.01``: a sensor fault in words, as ``--sensor-fault`` writes it."""
    return f"{f.sensor} {f.kind}" + ("" if f.value is None else f" {f.value:g}")


def sensor_traces(steps: Sequence[Step], faults: Sequence[SensorFault]) -> list[Trace]:
    """Each faulty sensor's reading (what the bus carried) beside the true value it measures
    (the plant's state), one reading per sensor; the truth drawn where its axis lacks it."""
    out: list[Trace] = []
    for sensor in dict.fromkeys(f.sensor for f in faults):
        axis, true, reading, scale = SENSOR_TRACES[sensor]
        when = ", ".join(f"{fault_label(f)} from {f.start:g} s" for f in faults if f.sensor == sensor)
        if axis not in (YAW, ANGLES) and not any(t.axis == axis and not t.faulty for t in out):
            out.append(Trace(axis, f"{true} (true)", [scale * getattr(s, true) for s in steps], False))
        out.append(Trace(axis, f"{sensor} reading ({when})", [scale * getattr(s, reading) for s in steps], True))
    return out


def event_marks(sc: scn.Scenario) -> list[tuple[float, str]]:
    """Where and what the scenario's events are, as labels for the time axis: its own, and each
    sensor fault's onset (and its end, within the run)."""
    labels = {
        "yaw_moment": lambda v: f"M_z {v:g} Nm",
        "steer": lambda v: f"driver steers {math.degrees(v):.2f} deg",
        "steer_norm": lambda v: f"driver steering step ({v:g})",
        "mu": lambda v: f"mu {v:g}",
        "speed": lambda v: f"v {v:g} m/s",
    }
    loads = {"split_mu_braking": lambda d: f"split-mu braking {d.mu_left:g}/{d.mu_right:g}",
             "side_wind": lambda d: f"side wind {d.peak_force:g} N",
             "blowout": lambda d: f"blow-out {d.wheel}"}
    marks = [(e.t, loads[e.kind](e.load) if e.load is not None else labels[e.kind](e.value)) for e in sc.events]
    for f in sc.sensor_config.faults:
        if f.start <= sc.duration:
            marks.append((f.start, f"sensor fault: {fault_label(f)}"))
        if f.stop <= sc.duration:
            marks.append((f.stop, f"{f.sensor} healthy again"))
    return sorted(marks, key=lambda m: m[0])


def run_png(steps: Sequence[Step], marks: Sequence[tuple[float, str]], title: str,
            traces: Sequence[Trace] = ()) -> bytes | None:
    """One run: yaw rate; driver's angle, auxiliary command and applied angle; a faulty sensor's
    reading beside the truth (``traces``); controller state."""
    plt = _pyplot()
    if plt is None or not steps:
        return None
    return _png(run_figure(plt, steps, marks, title, traces), plt)


def run_figure(plt: Any, steps: Sequence[Step], marks: Sequence[tuple[float, str]], title: str,
               traces: Sequence[Trace] = ()) -> Any:
    """``run_png``'s figure (matplotlib's), to draw or to look into."""
    t = [s.t_s for s in steps]
    has_ctrl = any(s.ctrl_state for s in steps)
    extra = list(dict.fromkeys(tr.axis for tr in traces if tr.axis not in (YAW, ANGLES)))
    ratios = [3, 3, *([2] * len(extra)), *([1.2] if has_ctrl else [])]
    fig, axes = plt.subplots(len(ratios), 1, figsize=(9, 1.9 + 1.1 * sum(ratios)), sharex=True,
                             gridspec_kw={"height_ratios": ratios})
    axes[0].plot(t, [s.yaw_rate_rad_s for s in steps], color="C0", label="yaw rate")
    axes[0].set_ylabel(YAW)
    _angles(axes[1], steps, t)
    by_axis = {YAW: axes[0], ANGLES: axes[1], **{name: axes[2 + i] for i, name in enumerate(extra)}}
    for name in extra:
        by_axis[name].set_ylabel(name)
    for tr in traces:
        by_axis[tr.axis].plot(t, tr.values, color="C3" if tr.faulty else "0.3", lw=1.0,
                              ls="-" if tr.faulty else "--", label=tr.label)
    if has_ctrl:
        ax, states = axes[-1], lane_levels()
        ax.step(t, [states.index(s.ctrl_state) if s.ctrl_state in states else math.nan for s in steps],
                where="post", color="C3")
        ax.set_yticks(range(len(states)), states, fontsize=7)
        ax.set_ylim(-0.5, len(states) - 0.5)
        ax.set_ylabel("controller")
    _finish(axes, marks, fig, title, legends=2 + len(extra))
    return fig


def lane_levels() -> list[str]:
    """The controller lane's state names, bottom to top: ``LANE``'s order, then any other state
    the DBC names."""
    names = state_names()
    return [names[v] for v in LANE if v in names] + [n for v, n in names.items() if v not in LANE]


def comparison_png(with_ctrl: Sequence[Step], without_ctrl: Sequence[Step], marks: Sequence[tuple[float, str]],
                   title: str) -> bytes | None:
    """The same scenario with and without the controller, overlaid."""
    plt = _pyplot()
    if plt is None or not with_ctrl or not without_ctrl:
        return None
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for steps, label, color in ((without_ctrl, "without controller", "C7"), (with_ctrl, "with controller", "C0")):
        r = [s.yaw_rate_rad_s for s in steps]
        axes[0].plot([s.t_s for s in steps], r, color=color,
                     label=f"{label} (peak {max(abs(x) for x in r):.3g} rad/s)")
    axes[0].set_ylabel(YAW)
    _angles(axes[1], with_ctrl, [s.t_s for s in with_ctrl], suffix=" (with controller)")
    axes[1].plot([s.t_s for s in without_ctrl], [math.degrees(s.driver_angle_rad) for s in without_ctrl], color="C7",
                 lw=1.0, ls="--", label="driver's angle (without controller)")
    _finish(axes, marks, fig, title)
    return _png(fig, plt)


def _angles(ax: Any, steps: Sequence[Step], t: list[float], suffix: str = "") -> None:
    ax.plot(t, [math.degrees(s.driver_angle_rad) for s in steps], color="k", lw=1.0, label="driver's angle" + suffix)
    ax.plot(t, [math.degrees(s.aux_applied_rad) for s in steps], color="C1", label="auxiliary, applied" + suffix)
    ax.plot(t, [math.degrees(s.aux_cmd_rad) for s in steps], color="C1", lw=0.8, ls="--",
            label="auxiliary, commanded" + suffix)
    ax.set_ylabel(ANGLES)


def _finish(axes: Sequence[Any], marks: Sequence[tuple[float, str]], fig: Any, title: str, legends: int = 2) -> None:
    for ax in axes:
        for t, _ in marks:
            ax.axvline(t, color="C2", lw=0.9, ls=":")
        ax.grid(True, alpha=0.3)
    top = axes[0]
    for t, label in marks:
        top.annotate(label, (t, 1.0), xycoords=("data", "axes fraction"), xytext=(0, 3),
                     textcoords="offset points", ha="center", va="bottom", color="C2", fontsize=8)
    for ax in axes[:legends]:
        ax.legend(fontsize=8, loc="best")
    axes[-1].set_xlabel("scenario time [s]")
    fig.suptitle(title)
    fig.tight_layout()


def _pyplot() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def _png(fig: Any, plt: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()
