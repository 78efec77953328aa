"""Figures of HIL runs, drawn from their per-step tables (``hil_steps.Step``) over the
scenario's own time, with the scenario's events marked.

matplotlib (the ``plot`` extra) is imported only when a figure is drawn; without it the
functions return None and the caller writes no figure.
"""

from __future__ import annotations

import io
import math
from typing import Any, Sequence

from firmware_py import model_regulator as mr
from sim_plant.car import scenario as scn
from sim_plant.harness.hil_steps import Step, state_names

#: The controller lane's levels, bottom to top: from not yet running to the most severe.
LANE = (mr.STATUS_STARTING, mr.STATUS_INACTIVE, mr.STATUS_ACTIVE, mr.STATUS_SATURATED, mr.STATUS_DEGRADED,
        mr.STATUS_FAULT)


def event_marks(sc: scn.Scenario) -> list[tuple[float, str]]:
    """Where and what the scenario's events are, as labels for the time axis."""
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
    return [(e.t, loads[e.kind](e.load) if e.load is not None else labels[e.kind](e.value)) for e in sc.events]


def run_png(steps: Sequence[Step], marks: Sequence[tuple[float, str]], title: str) -> bytes | None:
    """One run: yaw rate; driver's angle, auxiliary command and applied angle; controller state."""
    plt = _pyplot()
    if plt is None or not steps:
        return None
    t = [s.t_s for s in steps]
    has_ctrl = any(s.ctrl_state for s in steps)
    fig, axes = plt.subplots(3 if has_ctrl else 2, 1, figsize=(9, 8 if has_ctrl else 6), sharex=True,
                             gridspec_kw={"height_ratios": [3, 3, 1.6] if has_ctrl else [1, 1]})
    axes[0].plot(t, [s.yaw_rate_rad_s for s in steps], color="C0", label="yaw rate")
    axes[0].set_ylabel("yaw rate [rad/s]")
    _angles(axes[1], steps, t)
    if has_ctrl:
        ax, states = axes[2], lane_levels()
        ax.step(t, [states.index(s.ctrl_state) if s.ctrl_state in states else math.nan for s in steps],
                where="post", color="C3")
        ax.set_yticks(range(len(states)), states, fontsize=7)
        ax.set_ylim(-0.5, len(states) - 0.5)
        ax.set_ylabel("controller")
    _finish(axes, marks, fig, title)
    return _png(fig, plt)


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
    axes[0].set_ylabel("yaw rate [rad/s]")
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
    ax.set_ylabel("front-wheel angle [deg]")


def _finish(axes: Sequence[Any], marks: Sequence[tuple[float, str]], fig: Any, title: str) -> None:
    for ax in axes:
        for t, _ in marks:
            ax.axvline(t, color="C2", lw=0.9, ls=":")
        ax.grid(True, alpha=0.3)
    top = axes[0]
    for t, label in marks:
        top.annotate(label, (t, 1.0), xycoords=("data", "axes fraction"), xytext=(0, 3),
                     textcoords="offset points", ha="center", va="bottom", color="C2", fontsize=8)
    for ax in axes[:2]:
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
