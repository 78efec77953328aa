"""What a log replay found, in words, JSON, a per-step table and a figure; and the what-if of a
new calibration on an old drive.

``whatif()`` replays the same frames through a node with another calibration.  It is open
loop: the sensor frames are the ones recorded, so it says what the new calibration would have
commanded at each step of that drive, not how the car would then have moved.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from typing import Any, Sequence

import mrsteer_dbc
from mrsteer_dbc.names import (MSG_CMD, MSG_REDUNDANT, MSG_SPEED, MSG_STEER, MSG_YAW, SIG_CMD_ANGLE, SIG_LAT_ACCEL,
                               SIG_SPEED, SIG_SPEED_2, SIG_STEER_ANGLE, SIG_STEER_ANGLE_2, SIG_YAW_RATE, SIG_YAW_RATE_2)
from sim_plant.figures import resolution_of, tidy, tidy_figures
from sim_plant.harness.replay import Mismatch, ReplayResult, Step

MAX_LISTED = 20  # mismatches listed in the text report; the JSON has all of them
LATE_LISTED = 8  # late cycles named in the text report


@dataclass
class WhatIf:
    """The new calibration's commands beside the recorded ones, step by step."""

    result: ReplayResult  # the replay with the new calibration
    max_abs_dangle: float  # rad
    rms_dangle: float  # rad
    steps_differing: int  # steps whose angle differs
    state_differing: int  # steps whose controller state differs
    peak_recorded: float  # rad, largest |recorded command|
    peak_new: float  # rad, largest |new command|


def whatif(result: ReplayResult) -> WhatIf:
    """Figures of a replay run with a new calibration (``result``) against the recorded commands."""
    pairs = [(s.out, s.recorded) for s in result.steps if s.recorded is not None and s.recorded.valid]
    deltas = [abs(o.angle - r.angle) for o, r in pairs]
    return WhatIf(result, max(deltas, default=0.0),
                  math.sqrt(sum(d * d for d in deltas) / len(deltas)) if deltas else 0.0,
                  sum(1 for d in deltas if d > 0.0), sum(1 for o, r in pairs if o.state != r.state),
                  max((abs(r.angle) for _, r in pairs), default=0.0), max((abs(o.angle) for o, _ in pairs), default=0.0))


def _mismatch(m: Mismatch, times: dict[int, float]) -> dict[str, Any]:
    return {"line": m.line, "t_s": times.get(m.line), "bus_time_s": m.t, "frame_id": m.frame_id, "what": m.what}


def verdict(agrees: bool, mismatches_apart: int) -> str:
    """The replay's verdict in one word, ``agrees``, ``agrees_up_to_a_late_cycle`` or
    ``disagrees``: ``agrees`` alone would read as the whole log where mismatches after a late
    cycle were left apart."""
    if not agrees:
        return "disagrees"
    return "agrees_up_to_a_late_cycle" if mismatches_apart else "agrees"


def summary(result: ReplayResult, impl: str) -> dict[str, Any]:
    """The replay's figures (JSON-ready, tidied: ``sim_plant.figures``)."""
    first, times = result.first, result.times
    late = result.late
    return tidy_figures({
        "impl": impl, "log": str(result.log), "verdict": verdict(result.agrees, len(result.apart)),
        "agrees": result.agrees, "trigger": result.settings.trigger,
        "rate_hz": result.settings.rate_hz, "frames": result.frames, "sensor_frames": result.sensor_frames,
        "steps": len(result.steps), "commands_recorded": sum(1 for s in result.steps if s.recorded is not None),
        "statuses_recorded": result.statuses_recorded, "mismatches": len(result.mismatches),
        "first_mismatch": None if first is None else _mismatch(first, times),
        "max_abs_dangle_rad": result.max_abs_dangle, "max_abs_dangle_deg": math.degrees(result.max_abs_dangle),
        "command_mismatches": result.count("command"), "angle_mismatches": result.count("command", "angle"),
        "state_mismatches": result.count("command", "state") + result.count("status", "state"),
        "status_mismatches": result.count("status"), "cause_mismatches": result.count("status", "cause"),
        "all_mismatches": [_mismatch(m, times) for m in result.mismatches],
        # the clock trigger's timing: cycles off their period, groupings the commands decided
        "late_cycles": len(late), "late_cycle_lines": [s.line for s in late],
        "cycles_grouped_by_their_commands": sum(1 for s in result.steps if s.groupings > 1),
        "min_answer_s": result.min_answer_s,
        "apart_from_line": result.unjudged_from, "mismatches_apart": len(result.apart),
        "apart_mismatches": [_mismatch(m, times) for m in result.apart],
    })


def whatif_summary(w: WhatIf) -> dict[str, Any]:
    return tidy_figures({"max_abs_dangle_rad": w.max_abs_dangle, "max_abs_dangle_deg": math.degrees(w.max_abs_dangle),
            "rms_dangle_rad": w.rms_dangle, "steps_differing": w.steps_differing,
            "state_differing": w.state_differing, "peak_recorded_deg": math.degrees(w.peak_recorded),
            "peak_new_deg": math.degrees(w.peak_new)})


def text(s: dict[str, Any]) -> list[str]:
    """The report in lines: the verdict first, then the figures, the late cycles and the first
    mismatches."""
    said = {"agrees": "agrees with the log", "disagrees": "DISAGREES with the log",
            "agrees_up_to_a_late_cycle": f"agrees with the log up to line {s['apart_from_line']}, the late cycle "
            "no grouping of its frames reproduces"}[s["verdict"]]
    lines = [f"replay ({s['impl']}) of {s['log']}: {said}",
             f"  frames {s['frames']}, sensor frames {s['sensor_frames']}, cycles {s['steps']}, recorded commands "
             f"{s['commands_recorded']}, status frames {s['statuses_recorded']} ({s['trigger']} trigger, "
             f"{s['rate_hz']:g} Hz)",
             f"  largest |delta angle| {s['max_abs_dangle_rad']:.3g} rad ({s['max_abs_dangle_deg']:.3g} deg); "
             f"mismatches: {s['mismatches']} (command {s['command_mismatches']}, status {s['status_mismatches']}, "
             f"cause {s['cause_mismatches']})"]
    lines += _late_text(s)
    if s["first_mismatch"] is not None:
        lines.append(f"  first mismatch: {_where(s['first_mismatch'])}: {s['first_mismatch']['what']}")
        lines += _listed(s["all_mismatches"], s["mismatches"])
    if s["mismatches_apart"]:
        lines.append(f"  from line {s['apart_from_line']} on, a late cycle that no grouping of its sensor frames "
                     "reproduces: the replayed controller's state may differ from the recorded one's from there, so "
                     f"its {s['mismatches_apart']} mismatches in what the inputs decide are apart, not the "
                     "firmware's:")
        lines += _listed(s["apart_mismatches"], s["mismatches_apart"])
    return lines


def _late_text(s: dict[str, Any]) -> list[str]:
    if s["trigger"] != "clock":
        return []
    if not s["late_cycles"]:
        return ["  every command came on its period: the controller held its timing"]
    shown = ", ".join(str(n) for n in s["late_cycle_lines"][:LATE_LISTED])
    more = f" and {s['late_cycles'] - LATE_LISTED} more" if s["late_cycles"] > LATE_LISTED else ""
    return [f"  late cycles (a command more than 1.5 periods after the one before, or less than half): "
            f"{s['late_cycles']}, at lines {shown}{more}: the controller did not hold its timing there",
            f"  {s['cycles_grouped_by_their_commands']} cycles' sensor frames could have been drained in more than "
            "one way: their commands decided which (docs/can-runtime.md, \"Log replay\")"]


def _where(m: dict[str, Any]) -> str:
    at = "" if m["t_s"] is None else f" (t = {m['t_s']:.3f} s)"
    return f"line {m['line']}{at}, ID 0x{m['frame_id']:03X}"


def _listed(found: list[dict[str, Any]], count: int) -> list[str]:
    lines = [f"    {_where(m)}: {m['what']}" for m in found[:MAX_LISTED]]
    if count > MAX_LISTED:
        lines.append(f"    ... {count - MAX_LISTED} more (--json lists all)")
    return lines


def whatif_text(w: dict[str, Any], calibration: str) -> list[str]:
    return [f"what-if with {calibration} (open loop, on the recorded sensor frames):",
            f"  largest |new - recorded| {w['max_abs_dangle_rad']:.3g} rad ({w['max_abs_dangle_deg']:.3g} deg), "
            f"RMS {w['rms_dangle_rad']:.3g} rad; {w['steps_differing']} steps differ in angle, "
            f"{w['state_differing']} in state",
            f"  peak |command|: recorded {w['peak_recorded_deg']:.3g} deg, new {w['peak_new_deg']:.3g} deg"]


def steps_csv(steps: Sequence[Step], new: Sequence[Step] | None = None) -> str:
    """One row per cycle, scenario time first: what went in, what the replay commanded, what
    the log holds (angles to the command's 1e-6 rad, the inputs to their frames' resolution)."""
    f = io.StringIO()
    w = csv.writer(f, lineterminator="\n")
    w.writerow(["t_s", "step", "kind", "line", "bus_time_s", "late", "groupings", "delta_driver", "yaw_rate", "speed",
                "lat_accel", "delta_driver_2", "yaw_rate_2", "speed_2", "monitor_steps", "monitor_driver",
                "replayed_angle", "replayed_state", "recorded_angle", "recorded_state",
                *(["new_angle", "new_state"] if new is not None else [])])
    angle, inputs = _resolutions()
    for i, s in enumerate(steps):
        rec = s.recorded
        extra = [_cell(new[i].out.angle, angle), new[i].out.state] if new is not None and i < len(new) else []
        w.writerow([_cell(s.t_s, resolution_of("t_s")), s.index, s.kind, s.line, f"{s.t:.6f}", int(s.late),
                    s.groupings, *(_cell(x, res) for x, res in zip(s.inputs, inputs)), s.monitor_steps,
                    _cell(s.monitor_driver, inputs[0]), _cell(s.out.angle, angle), s.out.state,
                    "" if rec is None else _cell(rec.angle, angle), "" if rec is None else rec.state, *extra])
    return f.getvalue()


def _resolutions() -> tuple[float, tuple[float, ...]]:
    """The DBC scales of replay.csv's angle columns (the command's) and of its inputs, in
    ``Step.inputs`` order."""
    c = mrsteer_dbc.load()
    return c.signal_scale(MSG_CMD, SIG_CMD_ANGLE), tuple(c.signal_scale(m, sig) for m, sig in (
        (MSG_STEER, SIG_STEER_ANGLE), (MSG_YAW, SIG_YAW_RATE), (MSG_SPEED, SIG_SPEED), (MSG_REDUNDANT, SIG_LAT_ACCEL),
        (MSG_REDUNDANT, SIG_STEER_ANGLE_2), (MSG_YAW, SIG_YAW_RATE_2), (MSG_REDUNDANT, SIG_SPEED_2)))


def _cell(x: float, resolution: float | None) -> str:
    return repr(tidy(x, resolution))


def whatif_series(w: WhatIf) -> tuple[list[float], list[float], list[float]]:
    """(scenario time in s, recorded command in deg, new command in deg) of ``whatif.png``: the
    cycles with a valid recorded command, without the node's final zero command at shutdown
    (no part of the drive)."""
    steps = [s for s in w.result.steps if s.kind != "final" and s.recorded is not None and s.recorded.valid]
    return ([s.t_s for s in steps], [math.degrees(s.recorded.angle) for s in steps if s.recorded is not None],
            [math.degrees(s.out.angle) for s in steps])


def whatif_png(w: WhatIf, title: str) -> bytes | None:
    """Recorded and new commands over the drive's scenario time, and their difference; None
    without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    t, rec, new = whatif_series(w)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    a1.plot(t, rec, label="recorded command")
    a1.plot(t, new, label="new calibration", linestyle="--")
    a1.set_ylabel("aux. steering command (deg)")
    a1.legend(loc="best")
    a1.grid(True, alpha=0.3)
    a2.plot(t, [n - r for n, r in zip(new, rec)], color="tab:red")
    a2.set_ylabel("new - recorded (deg)")
    a2.set_xlabel("scenario time (s)")
    a2.grid(True, alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()
