"""What a fault-matrix row left in its work directory, read once for the judge: the plant's
trace, every node's statistics, and the traffic of both buses (candump logs, decoded through
the DBC)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mrsteer_dbc
from mrsteer_dbc import names
from firmware_py import model_regulator as mr
from sim_plant.harness.faults.rows import Row
from sim_plant.harness.faults.settings import TIMEOUT_CYCLES, Setup
from sim_plant.nodes.candump_log import Frame, read_candump


@dataclass(frozen=True)
class Trace:
    """Plant time, applied angle, the command the actuator holds and the wall clock (epoch s;
    in ``Evidence``, the car's time: ``CarClock``) of every plant step."""

    t: list[float]
    applied: list[float]
    held: list[float]
    wall: list[float]
    columns: dict[str, list[float]] = field(default_factory=dict)  # every column, by its header name


def read_trace(path: Path) -> Trace:
    lines = path.read_text().splitlines()
    head = lines[0].split(",")
    rows = [[float(x) for x in line.split(",")] for line in lines[1:]]
    columns = {name: [r[i] for r in rows] for i, name in enumerate(head)}
    return Trace(columns["t_s"], columns["aux_applied_rad"], columns["aux_cmd_rad"], columns["wall_s"], columns)


def gaps(frames: list[Frame], ids: list[int], longer: float) -> list[tuple[float, float]]:
    """Intervals in which a message of ``ids`` went quiet for longer than ``longer`` s."""
    out = []
    for fid in ids:
        times = [t for t, f, _ in frames if f == fid]
        out += [(a, b) for a, b in zip(times, times[1:]) if b - a > longer]
    return out


def stall_gaps(e: Evidence) -> list[tuple[float, float]]:
    """The gaps in the control law's sensor frames on the controller's bus long enough to time
    an input out (a machine stall): each input times out after TIMEOUT_CYCLES of its own cycle
    (speed: 10 ms at most rates)."""
    c, ts = mrsteer_dbc.load(), e.setup.ts
    return [g for n in (names.MSG_STEER, names.MSG_YAW, names.MSG_SPEED)
            for g in gaps(e.frames, [c.frame_id(n)], TIMEOUT_CYCLES * (c.cycle_time_s(n, ts) or ts) - ts)]


def stalled(t: float, found: list[tuple[float, float]]) -> bool:
    """A FAULT at ``t`` is explained by one of the ``stall_gaps``."""
    return any(g0 - 0.005 <= t <= g1 + 0.1 for g0, g1 in found)


@dataclass(frozen=True)
class Status:
    """One ``MRS_CtrlStatus``: its time, state, plausibility bits and cause."""

    t: float
    state: int
    plausibility: int
    cause: int


@dataclass(frozen=True)
class Evidence:
    """One row's run: what the runner did (exit status, kill and restart times) and what was
    recorded.  Every time in it is epoch s read as the car's time (``CarClock``: the wall
    clock itself at slow motion 1)."""

    row: Row
    setup: Setup
    ctl_code: int | None  # the controller's exit status when stopped (None: it was not running)
    killed_at: float | None
    restarted: float | None
    trace: Trace
    bridge: dict[str, Any]
    plant: dict[str, Any]
    ctl_stats: dict[str, Any] | None  # None: the controller wrote none (killed)
    logged: dict[str, int]  # frames each logger logged, by side
    vehicle_frames: list[Frame]
    frames: list[Frame]  # the controller's bus
    cmds: list[tuple[float, float]]  # (t, AuxSteerCmd_State) of every accepted command to the run's end
    angles: list[tuple[float, float]]  # (t, AuxSteerCmd_Angle) of the same
    cmd_counters: list[int]  # the alive counter of each of the same (the controller's cycle)
    causes: list[tuple[float, int]]  # (t, CtrlStatus_Cause)
    faults_after: list[float]  # times of FAULT commands after the controller first became active
    statuses: list[Status]  # every decoded MRS_CtrlStatus to the run's end
    end: float  # the run's end: the plant's last yaw-rate frame (epoch s)


#: What every row's processes write when they exit (``gather`` reads them all).
STATISTICS = ("bridge.json", "plant.json", "logger-vehicle.json", "logger-controller.json", "trace.csv")
BRIDGE_TIMES = ("t0", "first_affected", "last_affected")  # the bridge's statistics that are epoch s


class CarClock:
    """Wall time (epoch s) read back as the car's: a row run in slow motion ``f`` lasted ``f``
    times its scenario in wall time, so ``ref + (t - ref) / f`` from one common reference.
    Identity (exactly) at ``f`` = 1."""

    def __init__(self, slow_motion: float, ref: float) -> None:
        self.f, self.ref = slow_motion, ref

    def __call__(self, t: float) -> float:
        return t if self.f == 1.0 else self.ref + (t - self.ref) / self.f

    def maybe(self, t: float | None) -> float | None:
        return None if t is None else self(t)

    def frames(self, frames: list[Frame]) -> list[Frame]:
        return frames if self.f == 1.0 else [fr._replace(t=self(fr.t)) for fr in frames]

    def trace(self, tr: Trace) -> Trace:
        if self.f == 1.0:
            return tr
        wall = [self(w) for w in tr.wall]
        return Trace(tr.t, tr.applied, tr.held, wall, {**tr.columns, "wall_s": wall})


def gather(row: Row, work: Path, ctl_code: int | None, killed_at: float | None, restarted: float | None,
           setup: Setup) -> Evidence:
    """Everything the row left, every time in it (frames, trace, kill and restart, the bridge's)
    in the car's time (``CarClock``)."""
    c = mrsteer_dbc.load()
    ctl_json = work / "controller.json"
    raw_vehicle = read_candump(work / "vehicle.log")
    clock = CarClock(setup.slow_motion, raw_vehicle[0].t if raw_vehicle else 0.0)
    vehicle_frames, frames = clock.frames(raw_vehicle), clock.frames(read_candump(work / "controller.log"))
    killed_at, restarted = clock.maybe(killed_at), clock.maybe(restarted)
    bridge = json.loads((work / "bridge.json").read_text())
    bridge.update({k: clock.maybe(bridge.get(k)) for k in BRIDGE_TIMES})
    cmd_id, status_id = c.frame_id(names.MSG_CMD), c.frame_id(names.MSG_STATUS)
    decoded = [(t, c.decode(fid, data)) for t, fid, data in frames if fid == cmd_id]
    cutoff = max(t for t, fid, _ in vehicle_frames
                 if fid == c.frame_id(names.MSG_YAW))  # the plant's last measurement: the run's end
    accepted = [(t, d) for t, d in decoded if d is not None and d.status.accepted and t <= cutoff]
    cmds = [(t, d.signals["AuxSteerCmd_State"]) for t, d in accepted]
    statuses = [(t, c.decode(fid, data)) for t, fid, data in frames if fid == status_id]
    first_active = next((t for t, s in cmds if s in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED)), None)
    status_list = [Status(t, int(d.signals[names.SIG_STATUS_STATE]), int(d.signals[names.SIG_STATUS_PLAUS]),
                          int(d.signals[names.SIG_STATUS_CAUSE])) for t, d in statuses if d is not None and t <= cutoff]
    return Evidence(
        row, setup, ctl_code, killed_at, restarted, clock.trace(read_trace(work / "trace.csv")),
        bridge, json.loads((work / "plant.json").read_text()),
        json.loads(ctl_json.read_text()) if ctl_json.exists() else None,
        {side: json.loads((work / f"logger-{side}.json").read_text())["frames"] for side in ("vehicle", "controller")},
        vehicle_frames, frames, cmds, [(t, d.signals["AuxSteerCmd_Angle"]) for t, d in accepted],
        [d.counter for _, d in accepted],
        [(t, int(d.signals["CtrlStatus_Cause"])) for t, d in statuses if d is not None],
        [t for t, s in cmds if s == mr.STATUS_FAULT and first_active is not None and t > first_active],
        status_list, cutoff)
