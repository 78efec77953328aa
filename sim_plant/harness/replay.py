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
* ``clock`` (realtime runs): every recorded command is one cycle, and the frames it had are
  the ones the command shows (``replay_clock``): a prefix of the logged sensor frames ending
  before the command, reaching the yaw-rate frame its ``MeasCounter`` names and not the next
  one; the frames between (the next step's driver angle and speed, sent before its yaw rate)
  are decided by the command itself, each possible prefix run through a copy of the node.  A
  cycle whose command came off its period (more than 1.5 periods after the one before, or less
  than half) is *late*: the controller did not hold its timing there.  Where a late cycle's
  command is reproduced by no grouping of its frames, the controller's state from there on is
  not known (a stalled machine also stalls the bus and the logger, and the log's order may not
  be the one the node saw): the mismatches from that cycle on that depend on the inputs (angle,
  state, ``MeasCounter``, the status frames' fields) are reported apart (``ReplayResult.apart``)
  and do not make the log disagree; a wrong alive counter, a missing or an invalid frame still do.

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
from dataclasses import replace
from pathlib import Path
from typing import Callable

import can

import mrsteer_dbc
from firmware_py import cycle as cy
from firmware_py import model_regulator as mr
from firmware_py.controller.node import ControllerNode
from mrsteer_dbc.e2e import E2EStatus
from mrsteer_dbc.names import (MSG_CMD, MSG_SPEED, MSG_STATUS, MSG_STEER, MSG_YAW,
                               SIG_CMD_ANGLE, SIG_CMD_MEAS, SIG_CMD_STATE, SIG_SPEED, SIG_STATUS_CAUSE, SIG_STATUS_FLAGS,
                               SIG_STATUS_PLAUS, SIG_STATUS_REJECTED, SIG_STATUS_STATE, SIG_STEER_ANGLE, SIG_YAW_RATE)
from sim_plant.harness.log_time import scenario_times
from sim_plant.harness.replay_data import Mismatch, Out, ReplayResult, ReplaySettings, StatusOut, Step
from sim_plant.harness.replay_clock import Command, Grouper, RecordingBus, late
from sim_plant.nodes.candump_log import LogError, read_candump_messages

__all__ = ["LogError", "Mismatch", "Out", "ReplayResult", "ReplaySettings", "Step", "effective_config", "replay"]

# What the replayed status frame is compared in (the rest is timing: overruns, lateness).
STATUS_FIELDS = ("state", "flags", "cause", "rejected", "plausibility")
# Mismatches that no grouping of the sensor frames can explain: judged even after a late cycle.
FRAME_KINDS = ("counter", "missing", "extra", "invalid")
# After a tie between groupings, an angle this many command resolutions off is the state's
# uncertainty showing (``judge``), not the firmware's error.
TIE_SLACK = 2


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
        self.bus = RecordingBus()
        self.node = ControllerNode(self.bus, settings.runtime(), contract)  # type: ignore[arg-type]
        self.rx_ids = {int(f["can_id"]) for f in self.bus.filters}
        self.cmd_id = contract.frame_id(MSG_CMD)
        self.status_id = contract.frame_id(MSG_STATUS)
        self.yaw_id = contract.frame_id(MSG_YAW)
        self.steps: list[Step] = []
        self.mismatches: list[Mismatch] = []
        self.recorded_statuses: list[StatusOut] = []
        self.sensor_frames = 0
        self.min_answer: float | None = None

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
        """The command the node should send for ``inputs``: its cycle (``firmware_py.cycle``) with
        ``monitor_steps`` monitor steps, the first with ``monitor_driver``, run on a copy of the
        node's cycle state."""
        node = self.node
        i = cy.CycleInputs(*inputs[:3], lat_accel=inputs[3], delta_driver_redundant=inputs[4],
                           yaw_rate_redundant=inputs[5], speed_redundant=inputs[6], monitor_steps=monitor_steps,
                           monitor_driver=monitor_driver, starting=node.starting)
        return cy.step(node.cycle_coeffs, copy.deepcopy(node.cycle_state), i)

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
                    monitor_steps=monitor_steps, monitor_driver=monitor_driver,
                    starting=node.starting and kind != "final")
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

    def run_clock(self, frames: list[tuple[int, can.Message]], last_cmd: int, like: list[int] | None = None) -> None:
        """One cycle per recorded command, its frames grouped by ``replay_clock`` (or as in
        ``like``: each cycle's ``Step.received`` of another replay of the same log)."""
        sensors: list[can.Message] = []
        commands: list[Command] = []
        recorded: list[Out] = []
        for line, msg in frames:
            fid = msg.arbitration_id
            if fid in self.rx_ids:
                sensors.append(msg)
            elif fid == self.cmd_id:
                rec = self._command(msg, line, msg.timestamp)
                recorded.append(rec)
                commands.append(Command(msg.timestamp, len(sensors), rec.angle, rec.state, rec.meas, line == last_cmd))
            elif fid == self.status_id:
                self.recorded_statuses.append(self._status(msg, line, msg.timestamp))
        self.sensor_frames = len(sensors)
        grouper = Grouper(self.contract, sensors, commands)
        self.min_answer = grouper.min_answer
        p = 0
        before: float | None = None
        for n, (c, rec) in enumerate(zip(commands, recorded)):
            if c.final:
                step = self.cycle("final", rec.line, rec.t)
            elif like is not None:
                for m in sensors[p:like[n]]:
                    self.node.receive(m)
                p = max(p, like[n])
                step = self.cycle("clock", rec.line, rec.t)
            else:
                choice, _ = grouper.choose(self.node, p, n)
                self.node, p = choice.node, choice.k
                self.bus = choice.node.bus  # type: ignore[assignment]
                step = self.cycle("clock", rec.line, rec.t)
                step.groupings, step.tied = choice.groupings, choice.tied
            step.received = p
            step.recorded = rec
            step.late = not c.final and late(c.t, before, self.node.period)
            before = c.t


def replay(log: Path, settings: ReplaySettings | None = None, contract: mrsteer_dbc.Contract | None = None,
           like: ReplayResult | None = None, warn: Callable[[str], None] | None = None) -> ReplayResult:
    """Replay ``log`` through the Python controller; ``LogError`` when it is not a usable log.
    ``like``: a replay of the same log whose clock-trigger grouping to keep (a what-if of
    another calibration: its commands are not the recorded ones, so they cannot decide it);
    ``warn``: told of a cut-off last line (``read_candump_messages``)."""
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
        r.run_clock(frames, last_cmd, None if like is None else [st.received for st in like.steps])
    times = dict(zip((line for line, _ in frames), scenario_times(
        [(m.arbitration_id, bytes(m.data), m.timestamp) for _, m in frames], r.node.period, contract)))
    for step in r.steps:
        step.t_s = times[step.line]
    found, worst = compare(r.steps, r.recorded_statuses, r.cmd_id, r.status_id)
    pair_statuses(r.steps, r.recorded_statuses)
    judged, apart, since = judge(r.steps, r.mismatches + found)
    return ReplayResult(log, settings, len(frames), r.sensor_frames, r.steps, len(r.recorded_statuses),
                        judged, worst, effective_config(r.node), r.recorded_statuses, r.mismatches, apart, since,
                        r.min_answer, times)


def judge(steps: list[Step], mismatches: list[Mismatch]) -> tuple[list[Mismatch], list[Mismatch], int | None]:
    """(judged, apart, line): the mismatches split at the first cycle where the replay cannot
    vouch for the controller's state: a late cycle whose command disagrees, or, after a tie
    between groupings (``Step.tied``: the next commands could not tell them apart, so the state
    may be off by less than the bus shows), a command off by at most ``TIE_SLACK`` resolutions in
    its angle alone.  From that line on, the mismatches the inputs decide are apart (the module
    docstring); a wrong alive counter, a missing, extra or invalid frame stay judged."""
    bad = {m.line for m in mismatches if m.frame == "command" and m.what.split(":")[0] not in FRAME_KINDS}
    slack = TIE_SLACK * mrsteer_dbc.load().signal_scale(MSG_CMD, SIG_CMD_ANGLE) * (1.0 + 1e-9)
    since, tied = None, False
    for s in steps:
        rec = s.recorded
        if rec is not None and rec.line in bad:
            near = (s.out.state, s.out.meas) == (rec.state, rec.meas) and abs(s.out.angle - rec.angle) <= slack
            if s.late or (tied and near):
                since = rec.line
                break
        tied = tied or s.tied
    if since is None:
        return mismatches, [], None
    judged: list[Mismatch] = []
    apart: list[Mismatch] = []
    for m in mismatches:
        (apart if m.line >= since and m.what.split(":")[0] not in FRAME_KINDS else judged).append(m)
    return judged, apart, since


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
