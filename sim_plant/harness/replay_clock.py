"""Which logged sensor frames each cycle of a clocked controller had: the grouping of a realtime log.

A node on the ``clock`` trigger drains its receive queue when its cycle starts (and waits up to a
quarter period for a late yaw-rate frame), runs the law and sends its command.  The log holds
every frame in the one order the bus carried them, and the node received its frames in that
order; so what a cycle had drained is a prefix of the logged sensor frames, ending before the
cycle's command.  The command says more:

* its ``MeasCounter`` names the newest yaw-rate frame the cycle had: the prefix reaches that
  frame and stops before the next yaw-rate frame (which would have changed the counter);
* the frames between the two (the next step's driver angle, speed and redundant sensors: the
  plant sends them before its yaw rate) may or may not have reached the node before it drained.
  One logged less than ``min_answer`` before the command had not: ``min_answer`` is the shortest
  time in the log from a yaw-rate frame to the command answering it, which no cycle can beat.
  The others are decided by the command itself: each possible prefix runs through a copy of the
  node, and the one whose command (angle, state, ``MeasCounter``) is the recorded one is taken.
  Where several are (a new driver angle changes the command by less than the bus's 1e-6 rad, but
  changes the law's state), the one whose next ``LOOKAHEAD`` commands are also reproduced wins,
  then the one whose commands before rounding lie nearest them, then the one with the most
  frames logged ``min_answer`` before the command.

Where no prefix reproduces the command, the one whose command comes nearest is taken and the
replay reports the mismatch.  A cycle whose command came more than ``LATE`` periods after the
one before it, or less than ``EARLY`` periods, is *late*: the controller did not hold its timing
there (the grouping above still holds, the bus order does not depend on timing, but a stalled
machine can also stall the bus's broker and the logger, and then the log's order is not the one
the node saw).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import can

import mrsteer_dbc
from firmware_py.controller.node import ControllerNode
from mrsteer_dbc.e2e import E2EStatus
from mrsteer_dbc.names import (MEAS_NONE, MSG_CMD, MSG_SPEED, MSG_STEER, MSG_YAW, SIG_CMD_ANGLE, SIG_CMD_MEAS,
                               SIG_CMD_STATE)

LOOKAHEAD = 30  # commands a tie between two groupings is followed for
LATE = 1.5  # periods after the command before: a late cycle
EARLY = 0.5  # periods after the command before: a cycle catching up after a late one


class RecordingBus:
    """Stands in for the bus: keeps what the node sends; there is nothing to receive."""

    def __init__(self) -> None:
        self.sent: list[can.Message] = []

    def set_filters(self, filters: Any) -> None:
        self.filters = filters

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)

    def recv(self, timeout: float | None = None) -> None:
        return None


@dataclass(frozen=True)
class Command:
    """A recorded command as the grouping needs it."""

    t: float  # bus time
    sensors_before: int  # sensor frames logged before it
    angle: float
    state: int
    meas: int | None  # None: the frame failed its E2E check
    final: bool  # the log's last command: the node's shutdown, no cycle


@dataclass
class Choice:
    """The frames one cycle had: the node with the first ``k`` sensor frames received, before
    its cycle; how many prefixes the log allowed; whether one reproduced the command."""

    node: ControllerNode
    k: int
    groupings: int
    reproduced: bool
    tied: bool = False  # several groupings that give the law different inputs reproduced the command


def fork(node: ControllerNode) -> ControllerNode:
    """A copy of ``node`` on a bus of its own; what holds no state (the contract, the
    configuration and the coefficients computed from it) is shared."""
    shared = (node.contract, node.cfg, node.cycle_coeffs)
    return copy.deepcopy(node, {id(node.bus): RecordingBus(), **{id(o): o for o in shared}})


def late(t: float, before: float | None, period: float) -> bool:
    """A command sent off its period after the one before it (see the module docstring)."""
    return before is not None and not EARLY * period <= t - before <= LATE * period


class Grouper:
    """Decides, command by command, how many of the logged sensor frames the node had."""

    def __init__(self, contract: mrsteer_dbc.Contract, sensors: list[can.Message], commands: list[Command]) -> None:
        self.contract = contract
        self.sensors = sensors
        self.commands = commands
        self.cmd_id = contract.frame_id(MSG_CMD)
        yaw_id = contract.frame_id(MSG_YAW)
        # each sensor frame's yaw-rate alive counter (None: no yaw-rate frame, or not a valid one)
        self.yaw = [self._counter(m) if m.arbitration_id == yaw_id else None for m in sensors]
        self.min_answer = self._min_answer()

    def _counter(self, msg: can.Message) -> int | None:
        d = self.contract.decode(msg.arbitration_id, bytes(msg.data))
        return d.counter if d is not None and d.status is E2EStatus.OK else None

    def _min_answer(self) -> float:
        """The shortest time from a yaw-rate frame to the command naming it (0 if none does)."""
        newest: dict[int, float] = {}
        best, i = math.inf, 0
        for c in self.commands:
            for j in range(i, c.sensors_before):
                if self.yaw[j] is not None:
                    newest[self.yaw[j]] = self.sensors[j].timestamp  # type: ignore[index]
            i = c.sensors_before
            if c.meas in newest:
                best = min(best, c.t - newest[c.meas])  # type: ignore[index]
        return best if math.isfinite(best) else 0.0

    def prefixes(self, node: ControllerNode, p: int, n: int) -> list[int]:
        """The numbers of logged sensor frames (from ``p``, what ``node`` has) that command ``n``'s
        cycle can have had, in the order they are preferred: those whose newest yaw-rate frame
        is the one its ``MeasCounter`` names (none new: the node's newest; ``NONE``: no new one),
        the most frames logged ``min_answer`` before the command first.  A burst of more than
        15 yaw-rate frames (a stall) names a counter twice: both are possible."""
        c = self.commands[n]
        newest: int | None = node.input(MSG_YAW).last_counter
        fits = []
        for k in range(p, c.sensors_before + 1):
            if k > p and self.yaw[k - 1] is not None:
                if c.meas in (MEAS_NONE, None):
                    break
                newest = self.yaw[k - 1]
            if c.meas in (MEAS_NONE, None) or newest == c.meas:
                fits.append(k)
        if not fits:
            return [p]  # a MeasCounter the log does not explain: nothing new, and the mismatch shows
        ripe = [k for k in fits if k == p or c.t - self.sensors[k - 1].timestamp >= self.min_answer]
        return [*reversed(ripe), *(k for k in fits if k not in ripe)]

    def _command(self, node: ControllerNode) -> tuple[float, int, int] | None:
        msg = node.bus.sent[-1]
        d = self.contract.decode(msg.arbitration_id, bytes(msg.data))
        if d is None or d.status is not E2EStatus.OK:
            return None
        s = d.signals
        return float(s[SIG_CMD_ANGLE]), int(s[SIG_CMD_STATE]), int(s[SIG_CMD_MEAS])

    def _trial(self, node: ControllerNode, n: int) -> bool:
        """Run ``node``'s cycle; True if it sends command ``n``'s angle, state and MeasCounter
        (the alive counter is no matter of grouping: a dropped command shows there)."""
        return self._distance(node, n) == (0, 0.0)

    def _distance(self, node: ControllerNode, n: int) -> tuple[int, float]:
        """Run ``node``'s cycle: how far its command is from command ``n``'s (fields of state and
        MeasCounter that differ, then the angle)."""
        node.control()
        sent = [m for m in node.bus.sent if m.arbitration_id == self.cmd_id]
        node.bus.sent[:] = sent[-1:]
        c, got = self.commands[n], self._command(node)
        if got is None:
            return 2, math.inf
        angle, state, meas = got
        return (state != c.state) + (meas != c.meas), abs(angle - c.angle) if math.isfinite(c.angle) else math.inf

    def choose(self, node: ControllerNode, p: int, n: int,
               lookahead: bool = True) -> tuple[Choice, ControllerNode | None]:
        """The frames command ``n``'s cycle had, given ``node`` with ``p`` frames received (it is
        advanced, not copied, where the log allows one prefix only); and a copy of the chosen
        node after its cycle when one reproduced the command."""
        order = self.prefixes(node, p, n)
        last = max(order)
        states: dict[int, ControllerNode] = {}
        for k in range(p, last + 1):
            if k in order:
                states[k] = fork(node) if k < last else node
            if k < last:
                node.receive(self.sensors[k])
        if len(order) == 1 and lookahead:
            return Choice(node, last, 1, True), None  # the replay's own cycle and comparison tell
        if len(order) == 1:
            return (Choice(node, last, 1, True), node) if self._trial(node, n) else (Choice(node, last, 1, False), None)
        matches: list[tuple[int, ControllerNode]] = []
        near: list[tuple[tuple[int, float], int]] = []  # (distance, k): the nearest where none reproduces
        for k in order:
            after = fork(states[k])
            near.append((self._distance(after, n), k))
            if near[-1][0] == (0, 0.0):
                matches.append((k, after))
                if not lookahead:
                    break
        if not matches:
            k = min(near)[1] if lookahead else order[0]
            return Choice(states[k], k, len(order), False), None
        first = min(order)
        tied = len(matches) > 1 and not (last - first == len(order) - 1
                                         and self._same_values(states[first], self.sensors[first:last]))
        k, after = self._longest(matches, n + 1) if tied else matches[0]
        return Choice(states[k], k, len(order), True, tied), after

    def _same_values(self, node: ControllerNode, frames: list[can.Message]) -> bool:
        """True if ``frames`` are driver-angle or speed frames that bring ``node`` (fresh in them)
        no new value: then whichever cycle took them, the law's inputs are the same."""
        for msg in frames:
            name = self.contract.name_of(msg.arbitration_id)
            if name not in (MSG_STEER, MSG_SPEED):
                return False
            d = self.contract.decode(msg.arbitration_id, bytes(msg.data))
            inp = node.input(name)
            if d is None or not inp.valid(node.cfg.e2e_fail_max) or d.signals[inp.signal] != inp.value:
                return False
        return True

    def _longest(self, matches: list[tuple[int, ControllerNode]], n: int) -> tuple[int, ControllerNode]:
        """Of several reproducing groupings, the one whose next commands are reproduced longest;
        of those reproducing as many, the one whose commands before rounding to the bus's
        resolution lie nearest the recorded ones (a state off by less than the resolution rounds
        to the same commands for a while, nearer one edge of it)."""
        best, score = matches[0], (-1, 0.0)
        for k, after in matches:
            kept, off = self.follow(fork(after), k, n, LOOKAHEAD)
            if (kept, -off) > score:
                best, score = (k, after), (kept, -off)
        return best

    def follow(self, node: ControllerNode, p: int, n: int, depth: int) -> tuple[int, float]:
        """How many commands from ``n`` on (at most ``depth``) ``node`` reproduces, each grouping
        the first one that does, and the sum of their squared distances before rounding."""
        off = 0.0
        for j in range(n, min(n + depth, len(self.commands))):
            if self.commands[j].final:
                return depth, off
            choice, after = self.choose(node, p, j, lookahead=False)
            if after is None:
                return j - n, off
            node, p = after, choice.k
            off += (node.command - self.commands[j].angle) ** 2
        return depth, off
