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

from sim_plant.harness.replay import Mismatch, ReplayResult, Step

MAX_LISTED = 20  # mismatches listed in the text report; the JSON has all of them


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


def _mismatch(m: Mismatch) -> dict[str, Any]:
    return {"line": m.line, "t": m.t, "frame_id": m.frame_id, "what": m.what}


def summary(result: ReplayResult, impl: str) -> dict[str, Any]:
    first = result.first
    return {
        "impl": impl, "log": str(result.log), "agrees": result.agrees, "trigger": result.settings.trigger,
        "rate_hz": result.settings.rate_hz, "frames": result.frames, "sensor_frames": result.sensor_frames,
        "steps": len(result.steps), "commands_recorded": sum(1 for s in result.steps if s.recorded is not None),
        "statuses_recorded": result.statuses_recorded, "mismatches": len(result.mismatches),
        "first_mismatch": None if first is None else _mismatch(first),
        "max_abs_dangle_rad": result.max_abs_dangle, "max_abs_dangle_deg": math.degrees(result.max_abs_dangle),
        "command_mismatches": result.count("command"), "angle_mismatches": result.count("command", "angle"),
        "state_mismatches": result.count("command", "state") + result.count("status", "state"),
        "status_mismatches": result.count("status"), "cause_mismatches": result.count("status", "cause"),
        "all_mismatches": [_mismatch(m) for m in result.mismatches],
    }


def whatif_summary(w: WhatIf) -> dict[str, Any]:
    return {"max_abs_dangle_rad": w.max_abs_dangle, "max_abs_dangle_deg": math.degrees(w.max_abs_dangle),
            "rms_dangle_rad": w.rms_dangle, "steps_differing": w.steps_differing,
            "state_differing": w.state_differing, "peak_recorded_deg": math.degrees(w.peak_recorded),
            "peak_new_deg": math.degrees(w.peak_new)}


def text(s: dict[str, Any]) -> list[str]:
    """The report in lines: the verdict first, then the figures and the first mismatches."""
    verdict = "agrees with the log" if s["agrees"] else "DISAGREES with the log"
    lines = [f"replay ({s['impl']}) of {s['log']}: {verdict}",
             f"  frames {s['frames']}, sensor frames {s['sensor_frames']}, cycles {s['steps']}, recorded commands "
             f"{s['commands_recorded']}, status frames {s['statuses_recorded']} ({s['trigger']} trigger, "
             f"{s['rate_hz']:g} Hz)",
             f"  largest |delta angle| {s['max_abs_dangle_rad']:.3g} rad ({s['max_abs_dangle_deg']:.3g} deg); "
             f"mismatches: {s['mismatches']} (command {s['command_mismatches']}, status {s['status_mismatches']}, "
             f"cause {s['cause_mismatches']})"]
    if s["first_mismatch"] is not None:
        f = s["first_mismatch"]
        lines.append(f"  first mismatch: line {f['line']}, t={f['t']:.6f}, ID 0x{f['frame_id']:03X}: {f['what']}")
        for m in s["all_mismatches"][:MAX_LISTED]:
            lines.append(f"    line {m['line']} ID 0x{m['frame_id']:03X}: {m['what']}")
        if s["mismatches"] > MAX_LISTED:
            lines.append(f"    ... {s['mismatches'] - MAX_LISTED} more (--json lists all)")
    return lines


def whatif_text(w: dict[str, Any], calibration: str) -> list[str]:
    return [f"what-if with {calibration} (open loop, on the recorded sensor frames):",
            f"  largest |new - recorded| {w['max_abs_dangle_rad']:.3g} rad ({w['max_abs_dangle_deg']:.3g} deg), "
            f"RMS {w['rms_dangle_rad']:.3g} rad; {w['steps_differing']} steps differ in angle, "
            f"{w['state_differing']} in state",
            f"  peak |command|: recorded {w['peak_recorded_deg']:.3g} deg, new {w['peak_new_deg']:.3g} deg"]


def steps_csv(steps: Sequence[Step], new: Sequence[Step] | None = None) -> str:
    """One row per cycle: what went in, what the replay commanded, what the log holds."""
    f = io.StringIO()
    w = csv.writer(f, lineterminator="\n")
    w.writerow(["step", "kind", "line", "t", "delta_driver", "yaw_rate", "speed", "lat_accel", "delta_driver_2",
                "yaw_rate_2", "speed_2", "monitor_steps", "monitor_driver", "replayed_angle", "replayed_state",
                "recorded_angle", "recorded_state", *(["new_angle", "new_state"] if new is not None else [])])
    for i, s in enumerate(steps):
        rec = s.recorded
        extra = [repr(new[i].out.angle), new[i].out.state] if new is not None and i < len(new) else []
        w.writerow([s.index, s.kind, s.line, f"{s.t:.6f}", *(repr(x) for x in s.inputs), s.monitor_steps,
                    repr(s.monitor_driver), repr(s.out.angle), s.out.state, "" if rec is None else repr(rec.angle),
                    "" if rec is None else rec.state, *extra])
    return f.getvalue()


def whatif_png(w: WhatIf, period: float, title: str) -> bytes | None:
    """Recorded and new commands over the drive's steps, and their difference; None without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    steps = [s for s in w.result.steps if s.recorded is not None and s.recorded.valid]
    t = [s.index * period for s in steps]
    rec = [math.degrees(s.recorded.angle) for s in steps if s.recorded is not None]
    new = [math.degrees(s.out.angle) for s in steps]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    a1.plot(t, rec, label="recorded command")
    a1.plot(t, new, label="new calibration", linestyle="--")
    a1.set_ylabel("aux. steering command (deg)")
    a1.legend(loc="best")
    a1.grid(True, alpha=0.3)
    a2.plot(t, [n - r for n, r in zip(new, rec)], color="tab:red")
    a2.set_ylabel("new - recorded (deg)")
    a2.set_xlabel("controller cycles x period (s)")
    a2.grid(True, alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()
