"""The C port's law and its guards on a replay's inputs: ``ports/c/mrs_replay`` (``mrsteer replay
--impl c``): ``mrs_step``, the plausibility monitor and the authority limiter, as the node runs them.

The Python replay (``replay.replay``) has already decoded the frames, run the receive checks,
the freshness rule and the trigger, and kept what went into ``step()`` and the monitor at every cycle.  Those
inputs go to the C driver with the node's effective calibration (a calibration file,
``firmware_py.calibration_file``); its ``mrs_step`` outputs are put in the command's DBC encoding
(so an angle is compared at the resolution the bus carries) and compared with the recorded
frames exactly as the Python replay's are, cycle by cycle as the Python replay grouped the
frames (on the ``clock`` trigger, ``replay_clock``: the same late cycles, judged alike).  What
is the node's and not the law's stays the Python node's: the ``MeasCounter``, the alive
counter, the final zero command at shutdown, and whether a cycle was in the start state (passed
to the driver, which reports its state from it, the law's status and its monitor's bits as the
C node does: ``mrs_reported_state``).  The cause bits are not the law's either; the C
node (``mrs_node``) has its own, so this replay does not compare them.

Why the decoding stays in Python: the receive path is the node's concern (the C node has its
own, ``mrs_node_rx``), and keeping it out of this driver means a mismatch here is the port's
``step()`` and nothing else.
"""

from __future__ import annotations

import subprocess
import tempfile
from dataclasses import replace
from pathlib import Path

import mrsteer_dbc
from mrsteer_dbc.names import MSG_CMD, MSG_STATUS, SIG_CMD_ANGLE, SIG_CMD_MEAS, SIG_CMD_STATE
from sim_plant.harness.launch import make_port
from sim_plant.harness.replay import Mismatch, Out, ReplayResult, StatusOut, compare, judge
from firmware_py import calibration_file

PORT = Path(__file__).resolve().parents[2] / "ports" / "c"
DRIVER = "mrs_replay_f64"


class PortError(RuntimeError):
    """The C driver could not be built or run; the message says why."""


def build() -> Path:
    """``make -C ports/c mrs_replay_f64`` (nothing to do when it is up to date)."""
    if not (PORT / "mrs_replay.c").is_file():
        raise PortError(f"the C port is not here: {PORT}")
    try:
        proc = make_port(DRIVER, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise PortError(f"cannot build {DRIVER}: {exc}") from None
    if proc.returncode != 0:
        raise PortError(f"cannot build {DRIVER}: {(proc.stderr or proc.stdout).strip().splitlines()[-1:]}")
    return PORT / DRIVER


def run_driver(result: ReplayResult) -> list[tuple[float, int, int, int]]:
    """(u, reported state, fault_flags, plausibility bits) of the C port at every non-final step
    of ``result``."""
    exe = build()
    inputs = "".join(f"{d!r} {r!r} {v!r} {lat!r} {d2!r} {s.monitor_steps} {r2!r} {v2!r} {s.monitor_driver!r} "
                     f"{int(s.starting)}\n"
                     for s in result.steps if s.kind != "final" for d, r, v, lat, d2, r2, v2 in [s.inputs])
    with tempfile.TemporaryDirectory(prefix="mrs-replay-") as tmp:
        cfg = Path(tmp) / "replay.cfg"
        cfg.write_text(calibration_file.dumps(result.config))
        proc = subprocess.run([str(exe), str(cfg)], input=inputs, capture_output=True, text=True, timeout=120)
    if proc.returncode != 0:
        raise PortError(f"{DRIVER} failed: {proc.stderr.strip()}")
    rows = []
    for line in proc.stdout.splitlines():
        u, status, flags, plausibility = line.split()
        rows.append((float(u), int(status), int(flags), int(plausibility)))
    return rows


def replay_c(result: ReplayResult, contract: mrsteer_dbc.Contract | None = None) -> ReplayResult:
    """``result`` (a Python replay) with the C port's commands in place of the Python node's."""
    c = contract or mrsteer_dbc.load()
    rows = iter(run_driver(result))
    outs: list[Out] = []
    statuses: list[StatusOut | None] = []
    for step in result.steps:
        if step.kind == "final":  # the node's shutdown, not the law
            outs.append(step.out)
            statuses.append(step.status)
            continue
        u, status, flags, plausibility = next(rows)
        d = c.decode(c.frame_id(MSG_CMD), c.encode(MSG_CMD, {SIG_CMD_STATE: status, SIG_CMD_ANGLE: u,
                                                            SIG_CMD_MEAS: step.out.meas or 0}, 0))
        assert d is not None
        outs.append(replace(step.out, angle=float(d.signals[SIG_CMD_ANGLE]), state=status))
        statuses.append(None if step.status is None else replace(step.status, state=status, flags=flags, cause=None,
                                                                 rejected=None, plausibility=plausibility))
    found, worst = compare(result.steps, result.recorded_statuses, c.frame_id(MSG_CMD), c.frame_id(MSG_STATUS),
                           outs, statuses)
    steps = [replace(s, out=o) for s, o in zip(result.steps, outs)]
    judged, apart, since = judge(steps, result.structural + found)
    # The port against the Python firmware on the very same inputs, whatever the log's timing let
    # the replay judge: a difference here is the port's, never a late cycle's.
    port = [Mismatch(s.recorded.line if s.recorded is not None else s.line, s.t, c.frame_id(MSG_CMD),
                     f"port: C sent {o.angle!r} rad, state {o.state}; the Python firmware {s.out.angle!r} rad, "
                     f"state {s.out.state}")
            for s, o in zip(result.steps, outs) if s.kind != "final" and (o.angle, o.state) != (s.out.angle, s.out.state)]
    return replace(result, steps=steps, mismatches=judged + port, apart=apart, unjudged_from=since,
                   max_abs_dangle=worst)
