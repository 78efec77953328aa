"""Log replay: the sensor frames of a recorded drive through the firmware again, offline.

``replay()`` reads a candump ``-L`` log (``hil run``'s ``traffic.log``, or ``candump -L`` from
anywhere), feeds every frame the controller takes (its receive filters: driver angle, yaw
rate, speed, and the SecOC sync when keyed) to a real ``ControllerNode`` on a bus that only
records what the node sends, and lines the node's commands and status frames up with the
ones recorded in the log.  Nothing of the controller is re-implemented here: the frames go
through ``ControllerNode.receive`` (``RxLink``: length, CRC, range, MAC, counter), the cycle
is ``ControllerNode.control`` (freshness, ``step()``, cause bits), and the frames it sends are
decoded through the contract like the recorded ones.

When the node ran a cycle is taken from the log, by the node's own trigger:

* ``sensors`` (lockstep runs, ``hil run`` default): one cycle for each accepted yaw-rate
  frame, at once; its command must be the next recorded command, before the next sensor
  frame (the plant waits for it).  A recorded command with no new yaw-rate frame to answer is
  the node's watchdog cycle; the last command of the log, the node's final zero command.
* ``clock`` (realtime runs): every recorded command is one cycle.  Before it, the node is
  given the logged frames up to the yaw-rate frame the command names by its ``MeasCounter``;
  the frames after that one (the plant sends driver angle and speed before yaw rate) wait for
  the next cycle.  A command naming an older measurement, or none, gets no new frames (see
  ``_Replayer._drained`` for the exceptions).  Which frames a clocked controller had drained is not in the log
  otherwise: a driver-angle or speed frame that a late cycle drained just before the yaw-rate
  frame it did not yet have is given to the next cycle here, which shows as a mismatch when
  the value changed between the two.

Each replayed command is compared with the recorded one in state, ``MeasCounter``, alive
counter (a dropped or repeated command shows there even where the angle happens to agree)
and angle; each status frame in state, range flags, cause, rejection count and plausibility bits
(overruns and lateness are timing, not replayable).  The per-step inputs that went into ``step()`` and the
plausibility monitor are kept (``Step.inputs``) so that another implementation of the law, the
monitor and the authority limiter (the C port: ``replay_c``) can be run on exactly them.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import can

import mrsteer_dbc
from firmware_py import authority as au
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from firmware_py.controller.node import DEFAULT_RATE_HZ, TRIGGERS, ControllerNode, RuntimeConfig
from mrsteer_dbc.e2e import E2EStatus
from mrsteer_dbc.names import (MEAS_NONE, MSG_CMD, MSG_SPEED, MSG_STATUS, MSG_STEER, MSG_YAW,
                               SIG_CMD_ANGLE, SIG_CMD_MEAS, SIG_CMD_STATE, SIG_SPEED, SIG_STATUS_CAUSE, SIG_STATUS_FLAGS,
                               SIG_STATUS_PLAUS, SIG_STATUS_REJECTED, SIG_STATUS_STATE, SIG_STEER_ANGLE, SIG_YAW_RATE)
from sim_plant.nodes.candump_log import LogError, read_candump_messages

__all__ = ["LogError", "Mismatch", "Out", "ReplayResult", "ReplaySettings", "Step", "effective_config", "replay"]

# What the replayed status frame is compared in (the rest is timing: overruns, lateness).
STATUS_FIELDS = ("state", "flags", "cause", "rejected", "plausibility")


@dataclass(frozen=True)
class ReplaySettings:
    """How the recorded controller ran: its rate, trigger, timeouts, calibration and key."""

    rate_hz: float = DEFAULT_RATE_HZ
    trigger: str = "sensors"
    timeout_cycles: int = 10
    controller: mr.ControllerConfig = field(default_factory=mr.ControllerConfig)
    secoc_key: bytes | None = None

    def runtime(self) -> RuntimeConfig:
        if self.trigger not in TRIGGERS:
            raise ValueError(f"trigger must be one of {', '.join(TRIGGERS)}")
        return RuntimeConfig(rate_hz=self.rate_hz, timeout_cycles=self.timeout_cycles, trigger=self.trigger,
                             secoc_key=self.secoc_key, controller=self.controller)


@dataclass(frozen=True)
class Out:
    """One command (with its status frame when one was sent in that cycle), replayed or recorded.
    ``None`` in a field: not known for this implementation (the C law has no cause bits)."""

    line: int  # log line of the recorded frame (0: replayed)
    t: float  # bus time, epoch s (replayed: the time of the frame that triggered the cycle)
    angle: float  # rad, as the DBC carries it
    state: int
    meas: int | None
    counter: int | None
    valid: bool = True  # recorded: the frame passed length, CRC and range


@dataclass(frozen=True)
class StatusOut:
    line: int
    t: float
    state: int
    flags: int
    cause: int | None
    rejected: int | None
    valid: bool = True
    plausibility: int | None = None  # CtrlStatus_Plausibility


@dataclass
class Step:
    """One controller cycle of the replay."""

    index: int
    kind: str  # "yaw" (answers an accepted yaw-rate frame), "watchdog", "clock" or "final"
    line: int  # the log line that triggered it (the yaw-rate frame, or the recorded command)
    t: float
    # (delta_driver, yaw_rate, speed) into step(), then (lat_accel, delta_driver_redundant,
    # yaw_rate_redundant, speed_redundant) into the monitor (with the command sent the cycle
    # before); NaN: invalid.
    inputs: tuple[float, float, float, float, float, float, float]
    out: Out
    flags: int = 0  # the firmware's range flags after this step
    status: StatusOut | None = None  # the status frame sent in this cycle
    recorded: Out | None = None
    recorded_status: StatusOut | None = None
    monitor_steps: int = 1  # yaw-rate samples the monitor stepped over (0: its verdict held)
    # the driver's angle of the monitor's first step (``ControllerNode.monitor_driver_angle``: the
    # one that came with a new redundant sample, else delta_driver); the replay sets it every cycle
    monitor_driver: float = math.nan


@dataclass(frozen=True)
class Mismatch:
    line: int  # log line of the frame that disagrees (the recorded one, or the yaw frame left unanswered)
    t: float
    frame_id: int
    what: str  # "angle", "state", "meas", "counter", "missing", "extra", "invalid", status fields
    frame: str = "command"  # which recorded frame kind it concerns: "command" or "status"

    def describe(self) -> str:
        return f"line {self.line} t={self.t:.6f} ID 0x{self.frame_id:03X}: {self.what}"


@dataclass
class ReplayResult:
    log: Path
    settings: ReplaySettings
    frames: int
    sensor_frames: int
    steps: list[Step]
    statuses_recorded: int
    mismatches: list[Mismatch]
    max_abs_dangle: float  # rad, over the steps with a recorded command
    config: mr.ControllerConfig  # the calibration the node ran (effective_config)
    recorded_statuses: list[StatusOut] = field(default_factory=list)
    structural: list[Mismatch] = field(default_factory=list)  # cycles the log has no command for

    @property
    def agrees(self) -> bool:
        return not self.mismatches

    @property
    def first(self) -> Mismatch | None:
        return min(self.mismatches, key=lambda m: m.line) if self.mismatches else None

    def count(self, frame: str, *what: str) -> int:
        """Mismatches of ``frame`` ("command" or "status"), of the kinds ``what`` (all if none)."""
        return sum(1 for m in self.mismatches if m.frame == frame and (not what or m.what.split(":")[0] in what))


class _RecordingBus:
    """Stands in for the bus: keeps what the node sends; there is nothing to receive."""

    def __init__(self) -> None:
        self.sent: list[can.Message] = []

    def set_filters(self, filters: Any) -> None:
        self.filters = filters

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)

    def recv(self, timeout: float | None = None) -> None:
        return None


def effective_config(node: ControllerNode) -> mr.ControllerConfig:
    """The calibration ``node`` runs (its period, the DBC's input ranges), checked against the
    node's own coefficients: what another implementation of the law must be configured with."""
    c, cfg = node.contract, node.cfg.controller
    eff = replace(cfg, ts=node.period, driver_angle_max=c.signal_range(MSG_STEER, SIG_STEER_ANGLE)[1],
                  yaw_rate_max=c.signal_range(MSG_YAW, SIG_YAW_RATE)[1],
                  speed_max=c.signal_range(MSG_SPEED, SIG_SPEED)[1],
                  aux_limit=min(cfg.aux_limit, c.signal_range(MSG_CMD, SIG_CMD_ANGLE)[1]))
    if mr.configure(eff) != node.coeffs:
        raise AssertionError("the node's calibration is not the one derived here: update effective_config")
    return eff


class _Replayer:
    """Drives one node through one log (see the module docstring for when a cycle runs)."""

    def __init__(self, settings: ReplaySettings, contract: mrsteer_dbc.Contract) -> None:
        self.contract = contract
        self.bus = _RecordingBus()
        self.node = ControllerNode(self.bus, settings.runtime(), contract)  # type: ignore[arg-type]
        self.rx_ids = {int(f["can_id"]) for f in self.bus.filters}
        self.cmd_id = contract.frame_id(MSG_CMD)
        self.status_id = contract.frame_id(MSG_STATUS)
        self.yaw_id = contract.frame_id(MSG_YAW)
        self.steps: list[Step] = []
        self.mismatches: list[Mismatch] = []
        self.recorded_statuses: list[StatusOut] = []
        self.sensor_frames = 0

    # ------------------------------------------------------------- the node

    def _inputs(self) -> tuple[float, float, float, float, float, float, float]:
        """What ``control()`` is about to pass to ``step()`` and the monitor: the node's freshness
        rule, read from its public input records (and ``redundant_inputs``); ``cycle`` checks the
        node's command against it."""
        e2e_max = self.node.cfg.e2e_fail_max
        vals = []
        for name in (MSG_STEER, MSG_YAW, MSG_SPEED):
            inp = self.node.input(name)
            vals.append(inp.value if inp.valid(e2e_max) else math.nan)
        lat, steer_2, speed_2 = self.node.redundant_inputs()
        yaw_2 = math.nan if math.isnan(vals[1]) else self.node.input(MSG_YAW).extra[0]
        return vals[0], vals[1], vals[2], lat, steer_2, yaw_2, speed_2

    def _shadow(self, inputs: tuple[float, float, float, float, float, float, float], monitor_steps: int,
                monitor_driver: float) -> float:
        """The command the node should send for ``inputs``: the monitor's ``monitor_steps`` steps
        (none: its held bits; the first with ``monitor_driver``), step() with its suspicion of the
        yaw rate and the authority limiter, run on copies of the node's states."""
        node = self.node
        d, r, v, lat, d2, r2, v2 = inputs
        bits, monitor = node.plausibility, copy.deepcopy(node.monitor)
        for k in range(monitor_steps):
            bits = pl.monitor_step(node.monitor_coeffs, monitor, monitor_driver if k == 0 else d, d2, r, lat, v,
                                   node.command, r2, v2)
        u = mr.step(node.coeffs, copy.deepcopy(node.state), d, r, v, (monitor.flags & pl.SUSPECT_CHECKS) != 0)
        return au.authority_step(node.authority_coeffs, copy.deepcopy(node.authority), u, bits,
                                 monitor.flags & pl.CUT_CHECKS, monitor.flags & pl.FADE_CHECKS)

    def cycle(self, kind: str, line: int, t: float) -> Step:
        node = self.node
        inputs = self._inputs()
        monitor_steps = node.monitor_steps()
        monitor_driver = node.monitor_driver_angle(inputs[0])
        shadow = self._shadow(inputs, monitor_steps, monitor_driver)
        before = len(self.bus.sent)
        if kind == "final":
            node.finish()
        else:
            node.control()
            if not (shadow == node.command or (math.isnan(shadow) and math.isnan(node.command))):
                raise AssertionError(f"line {line}: the inputs read from the node are not the ones it used")
        out, status = None, None
        for msg in self.bus.sent[before:]:
            if msg.arbitration_id == self.cmd_id:
                out = self._command(msg, line, t)
            else:
                status = self._status(msg, line, t)
        assert out is not None
        step = Step(len(self.steps), kind, line, t, inputs, out, node.state.fault_flags, status,
                    monitor_steps=monitor_steps, monitor_driver=monitor_driver)
        self.steps.append(step)
        return step

    # ------------------------------------------------------------- frames

    def _command(self, msg: can.Message, line: int, t: float) -> Out:
        d = self.contract.decode(msg.arbitration_id, bytes(msg.data))
        if d is None or d.status is not E2EStatus.OK:
            return Out(line, t, math.nan, -1, None, None, valid=False)
        s = d.signals
        return Out(line, t, float(s[SIG_CMD_ANGLE]), int(s[SIG_CMD_STATE]), int(s[SIG_CMD_MEAS]), d.counter)

    def _status(self, msg: can.Message, line: int, t: float) -> StatusOut:
        d = self.contract.decode(msg.arbitration_id, bytes(msg.data))
        if d is None or d.status is not E2EStatus.OK:
            return StatusOut(line, t, -1, -1, None, None, valid=False)
        s = d.signals
        return StatusOut(line, t, int(s[SIG_STATUS_STATE]), int(s[SIG_STATUS_FLAGS]), int(s[SIG_STATUS_CAUSE]),
                         int(s[SIG_STATUS_REJECTED]), plausibility=int(s[SIG_STATUS_PLAUS]))

    def miss(self, line: int, t: float, frame_id: int, what: str) -> None:
        self.mismatches.append(Mismatch(line, t, frame_id, what))

    def yaw_counter(self, msg: can.Message) -> int | None:
        d = self.contract.decode(msg.arbitration_id, bytes(msg.data))
        return d.counter if d is not None and d.status is E2EStatus.OK else None

    # ------------------------------------------------------------- triggers

    def run_sensors(self, frames: list[tuple[int, can.Message]], last_cmd: int) -> None:
        pending: Step | None = None  # a cycle whose command has not been seen in the log yet
        for line, msg in frames:
            fid = msg.arbitration_id
            if fid in self.rx_ids:
                if pending is not None:
                    self.miss(pending.line, pending.t, self.yaw_id, "missing: no command answers this yaw-rate frame")
                    pending = None
                self.sensor_frames += 1
                if self.node.receive(msg):
                    pending = self.cycle("yaw", line, msg.timestamp)
            elif fid == self.cmd_id:
                rec = self._command(msg, line, msg.timestamp)
                if pending is None:
                    pending = self.cycle("final" if line == last_cmd else "watchdog", line, msg.timestamp)
                pending.recorded = rec
                pending = None
            elif fid == self.status_id:
                self.recorded_statuses.append(self._status(msg, line, msg.timestamp))
        if pending is not None:
            self.miss(pending.line, pending.t, self.yaw_id, "missing: no command answers this yaw-rate frame")

    def run_clock(self, frames: list[tuple[int, can.Message]], last_cmd: int) -> None:
        buffered: list[tuple[int, can.Message]] = []
        for line, msg in frames:
            fid = msg.arbitration_id
            if fid in self.rx_ids:
                buffered.append((line, msg))
                self.sensor_frames += 1
            elif fid == self.cmd_id:
                rec = self._command(msg, line, msg.timestamp)
                take = self._drained(buffered, rec.meas, msg.timestamp - self.node.period)
                for _, m in buffered[:take]:
                    self.node.receive(m)
                del buffered[:take]
                self.cycle("final" if line == last_cmd else "clock", line, msg.timestamp).recorded = rec
            elif fid == self.status_id:
                self.recorded_statuses.append(self._status(msg, line, msg.timestamp))

    def _drained(self, buffered: list[tuple[int, can.Message]], meas: int | None, settled: float) -> int:
        """How many of the buffered frames the node had received when it computed a command
        answering yaw-rate counter ``meas``: up to the last yaw-rate frame of that counter.  A
        command answering an older measurement, or none, ran before the next burst of sensor
        frames arrived (the plant sends each step's frames together): nothing new, except
        yaw-rate frames that no receiver can accept (a bad length or CRC, say), which are what
        made it answer none.  With no yaw-rate frame buffered at all (the plant stopped, or lost
        its yaw-rate sensor), the frames logged a period or more before the command
        (``settled``) had reached the node; bus times say no more than that (a late cycle can
        miss frames logged well before its command)."""
        yaws = [i for i, (_, m) in enumerate(buffered) if m.arbitration_id == self.yaw_id]
        take = 0
        if meas is not None and meas != MEAS_NONE:
            named = [i for i in yaws if self.yaw_counter(buffered[i][1]) == meas]
            take = named[-1] + 1 if named else 0
        if take == 0:
            for i in yaws:
                if self.yaw_counter(buffered[i][1]) is not None:
                    break
                take = i + 1
        while not yaws and take < len(buffered) and buffered[take][1].timestamp <= settled:
            take += 1
        return take

def replay(log: Path, settings: ReplaySettings | None = None, contract: mrsteer_dbc.Contract | None = None,
           warn: Callable[[str], None] | None = None) -> ReplayResult:
    """Replay ``log`` through the Python controller; ``LogError`` when it is not a usable log
    (``warn``: told of a cut-off last line, ``read_candump_messages``)."""
    settings = settings or ReplaySettings()
    contract = contract or mrsteer_dbc.load()
    if not log.is_file():
        raise LogError(f"{log}: {'is a directory, not a log file' if log.is_dir() else 'no such file'}")
    frames = read_candump_messages(log, warn)
    r = _Replayer(settings, contract)
    if not any(m.arbitration_id in r.rx_ids for _, m in frames):
        raise LogError(f"{log}: no sensor frames ({MSG_STEER}, {MSG_YAW}, {MSG_SPEED}) in {len(frames)} frames")
    cmds = [line for line, m in frames if m.arbitration_id == r.cmd_id]
    last_cmd = cmds[-1] if cmds else -1
    if settings.trigger == "sensors":
        r.run_sensors(frames, last_cmd)
    else:
        r.run_clock(frames, last_cmd)
    found, worst = compare(r.steps, r.recorded_statuses, r.cmd_id, r.status_id)
    pair_statuses(r.steps, r.recorded_statuses)
    return ReplayResult(log, settings, len(frames), r.sensor_frames, r.steps, len(r.recorded_statuses),
                        r.mismatches + found, worst, effective_config(r.node), r.recorded_statuses, r.mismatches)


def pair_statuses(steps: list[Step], recorded: list[StatusOut]) -> None:
    """The k-th recorded status frame goes with the k-th cycle that sent one."""
    sent = [s for s in steps if s.status is not None]
    for step, rec in zip(sent, recorded):
        step.recorded_status = rec


def compare(steps: list[Step], recorded_statuses: list[StatusOut], cmd_id: int, status_id: int,
            outs: list[Out] | None = None, statuses: list[StatusOut | None] | None = None
            ) -> tuple[list[Mismatch], float]:
    """Mismatches of the replayed commands and status frames (``outs``/``statuses``: another
    implementation's, step by step; default the steps' own) against the recorded ones, and the
    largest |delta angle| in rad."""
    found: list[Mismatch] = []
    worst = 0.0
    for i, step in enumerate(steps):
        out = outs[i] if outs is not None else step.out
        rec = step.recorded
        if rec is None:
            continue  # a missing command: reported where the cycle was found
        if not rec.valid:
            found.append(Mismatch(rec.line, rec.t, cmd_id, "invalid: the recorded command fails its E2E check"))
            continue
        delta = abs(out.angle - rec.angle)
        worst = max(worst, delta)
        for name, got, want in (("state", out.state, rec.state), ("meas", out.meas, rec.meas),
                                ("counter", out.counter, rec.counter)):
            if got is not None and got != want:
                found.append(Mismatch(rec.line, rec.t, cmd_id, f"{name}: replayed {got}, recorded {want}"))
        if delta > 0.0:
            found.append(Mismatch(rec.line, rec.t, cmd_id,
                                  f"angle: replayed {out.angle:.6f} rad, recorded {rec.angle:.6f} rad"))
    mine = [s for s in (statuses if statuses is not None else [st.status for st in steps]) if s is not None]
    for got, rec in zip(mine, recorded_statuses):
        if not rec.valid:
            found.append(Mismatch(rec.line, rec.t, status_id, "invalid: the recorded status fails its E2E check",
                                  "status"))
            continue
        for name in STATUS_FIELDS:
            g, w = getattr(got, name), getattr(rec, name)
            if g is not None and g != w:
                found.append(Mismatch(rec.line, rec.t, status_id, f"{name}: replayed {g}, recorded {w}", "status"))
    for rec in recorded_statuses[len(mine):]:
        found.append(Mismatch(rec.line, rec.t, status_id, "extra: a status frame the replay did not send", "status"))
    for got in mine[len(recorded_statuses):]:
        found.append(Mismatch(got.line, got.t, status_id, "missing: the replay sent a status frame not in the log",
                              "status"))
    return found, worst
