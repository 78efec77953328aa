"""Shared helpers for the test suite."""

from __future__ import annotations

import os
import signal
import tempfile

import numpy as np
import pytest
from numpy.polynomial import polynomial as P

# Every fallback-bus socket the tests create lives in a private directory of this run, so
# parallel runs and a user's own brokers never meet.
os.environ["MRSTEER_BUS_DIR"] = tempfile.mkdtemp(prefix="mrsteer-bus-test-")
# The tests choose their own run lengths: a user's MRSTEER_QUICK=1 (README) must not change them.
os.environ.pop("MRSTEER_QUICK", None)


def ctrl_c_reaches_it() -> None:
    """``preexec_fn`` of a child a test interrupts with SIGINT: SIGINT at its default there, as a
    terminal's Ctrl-C finds it.  A suite started in the background of a script (``cmd &``) runs
    with SIGINT ignored, children inherit that, and an ignoring child would never stop."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def polymul(*polys: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """Product of polynomials given highest power first (scipy.signal convention)."""
    out = np.array([1.0])
    for p in polys:
        out = np.polymul(out, np.asarray(p, dtype=float))
    return out


def polyadd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.polyadd(np.asarray(a, float), np.asarray(b, float))


@pytest.fixture
def channel(request: pytest.FixtureRequest) -> str:
    """A fresh fallback-bus channel name for one test."""
    return "t-" + "".join(ch if ch.isalnum() else "-" for ch in request.node.name)[-60:]


def lockstep_traffic(log: "os.PathLike[str] | str") -> dict[str, list]:
    """What a lockstep HIL run's controller answered, independent of process timing, from its
    ``traffic.log``: every frame the plant sent (payload hex, in order) and every command the
    controller sent from the plant's first frame on, decoded to (state, angle, measurement
    counter). The commands' alive counters and CRCs are left out, because a sensors-triggered
    controller may send watchdog commands while the plant is still starting (one per second of
    wall time), and those shift the counters; the frames before the plant's first are dropped
    for the same reason. Each command frame must pass its E2E check. ``stalls`` counts the
    watchdog cycles during the run (a command naming the same measurement as the one before: the
    plant was descheduled for more than a second, as a loaded machine does now and then).
    Commands after the last one that answers a new measurement (watchdog cycles after the plant
    finished, and the final zero command) are left out too: how many there are depends on how
    soon the harness stops the controller after the plant, which is process timing (under a VM,
    seconds)."""
    from pathlib import Path

    import mrsteer_dbc
    from mrsteer_dbc import E2EStatus, names

    c = mrsteer_dbc.load()
    cmd_id = c.frame_id(names.MSG_CMD)
    plant_ids = {c.frame_id(n) for n in names.SENSORS}
    out: dict[str, list] = {"plant": [], "commands": [], "stalls": []}
    started = False
    for line in Path(log).read_text().splitlines():
        fid_hex, data_hex = line.split()[2].split("#")
        fid = int(fid_hex, 16)
        if fid in plant_ids:
            started = True
            out["plant"].append(data_hex)
        elif fid == cmd_id and started:
            d = c.decode(fid, bytes.fromhex(data_hex))
            assert d is not None and d.status is E2EStatus.OK, line
            cmd = (d.signals[names.SIG_CMD_STATE], d.signals[names.SIG_CMD_ANGLE], d.signals[names.SIG_CMD_MEAS])
            if out["commands"] and out["commands"][-1][2] == cmd[2]:
                out["stalls"].append(len(out["commands"]))
            out["commands"].append(cmd)
    cmds = out["commands"]
    while len(cmds) >= 2 and cmds[-1][2] == cmds[-2][2]:
        cmds.pop()
    out["stalls"] = [i for i in out["stalls"] if i < len(cmds)]
    return out


def logged_states(log: "os.PathLike[str] | str") -> tuple[list[int], list[int], list[int]]:
    """The states of a run's logged commands and of its status frames up to the plant's last
    frame's answer, and for each command whether it came after that (a watchdog cycle of a
    controller not yet stopped, or the final zero command)."""
    from pathlib import Path

    import mrsteer_dbc
    from mrsteer_dbc import names

    c = mrsteer_dbc.load()
    cmd, status, plant = c.frame_id(names.MSG_CMD), c.frame_id(names.MSG_STATUS), {
        c.frame_id(n) for n in names.VEHICLE_SENSORS}
    frames = [(int(f, 16), bytes.fromhex(d)) for f, d in (ln.split()[2].split("#") for ln in Path(log).read_text().splitlines())]
    last = max(i for i, (fid, _) in enumerate(frames) if fid in plant)
    cmds, statuses, after = [], [], []
    for i, (fid, data) in enumerate(frames):
        if fid in (cmd, status):
            d = c.decode(fid, data)
            assert d is not None and d.status is mrsteer_dbc.E2EStatus.OK
            if fid == cmd:
                cmds.append(int(d.signals[names.SIG_CMD_STATE]))
                after.append(i > last + 1)  # the frame after the plant's last answers it
            elif i <= last + 2:  # the status of the last answer's cycle follows it
                statuses.append(int(d.signals[names.SIG_STATUS_STATE]))
    return cmds, statuses, after


__all__ = ["lockstep_traffic", "logged_states", "polymul", "polyadd", "P"]


#: Rows of a realtime fault matrix that may fail once on a shared machine and be run again.
MATRIX_RERUN_MAX = 2


def matrix_with_one_rerun(run, rows, keep):
    """``run(rows, keep)`` (a realtime fault matrix), and the rows that failed, if no more than
    ``MATRIX_RERUN_MAX``, once more in ``keep / "rerun"``: a realtime row on a machine shared
    with other jobs is occasionally late when the machine stalls its processes (the plant's
    frames 3-7 ms apart instead of 2, seen in CI), which no row can tell from a late controller.
    A row that fails twice, or more rows than that, fail the test; a rerun is reported as a
    warning with the first run's failures, so it is never silent."""
    import warnings

    results = run(rows, keep)
    failed = [r for r in results if not r.ok]
    if not failed or len(failed) > MATRIX_RERUN_MAX:
        return results
    names = {r.name for r in failed}
    again = {r.name: r for r in run(tuple(row for row in rows if row.name in names), keep / "rerun")}
    warnings.warn("fault matrix rows run again after failing once: " + "; ".join(
        f"{r.name}: {', '.join(r.failures)} -> {'PASS' if again[r.name].passed else 'FAIL again'}" for r in failed))
    return [again.get(r.name, r) for r in results]
