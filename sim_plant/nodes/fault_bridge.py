"""Fault-injecting bridge between the vehicle's bus and the controller's bus.

    python -m sim_plant.nodes.fault_bridge --vehicle CH_A --controller CH_B --fault JSON [--stats-out F]

Every frame seen on one side is forwarded to the other, except where the fault says otherwise,
inside its time window (seconds after the vehicle's first frame).  Frame contents are
changed through the DBC (cantools) and the contract's E2E functions, never by bit position.

Fault kinds (``kind``), applied to the frames of ``target`` (a message name, ``sensors`` for the
three sensor messages, ``redundant`` for MRS_RedundantSensors, or ``commands`` for MRS_AuxSteerCmd):

=================  ===================================================================
drop               drop each frame with probability ``param`` (1: a burst, all of them)
delay              hold each frame ``param`` seconds
duplicate          forward each frame twice
reorder            swap each pair of consecutive frames of a message
corrupt_payload    flip one bit of the last payload byte (the CRC then fails)
corrupt_crc        flip one bit of the CRC byte
corrupt_counter    alive counter set to 15 (never sent), CRC made valid again
wrong_length       drop the last byte
replay             after each frame, also send the frame of the same message ``param`` frames
                   earlier again (recorded traffic played back by an attacker)
substitute         send the frame of the same message ``param`` frames earlier *instead* (a
                   man in the middle; with ``param`` 15 the alive counter is what the receiver
                   expects, so E2E alone cannot tell); while fewer than ``param`` frames of the
                   message were seen, both forward the frame as it is and do not count it
out_of_range       first physical signal set to ``param`` (outside the DBC range), E2E valid
flood              also send 8-byte frames of an unused ID (0x7F0) on the controller side,
                   ``param`` per s (sent in bursts as they fall due)
spoof_command      after each real MRS_AuxSteerCmd (target ``commands``), also send a forged one
                   with angle ``param`` rad: the next alive counter and FV counter, a valid CRC
                   and a random MAC (the best a forger without the SecOC key can do)
sensor_stuck       a wrong sensor in well-formed frames (``signal``: which physical signal,
sensor_frozen      default the message's first): stuck at ``param``; frozen at its last value
sensor_bias        before the window (value-frozen: the alive counter advances); + ``param``;
sensor_scale       * ``param``; + ``param`` * (seconds into the window); + ``param`` * N(0, 1).
sensor_drift       The frame is re-encoded through the DBC with its own alive counter and the
sensor_noise       CRC made valid; its SecOC MAC cannot be (the bridge has no key), so with
                   SecOC on, inject sensor faults in the plant (``mrsteer plant --sensor-fault``)
=================  ===================================================================
"""

from __future__ import annotations

import collections
import heapq
import json
import random
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Sequence

import can

import mrsteer_dbc
from mrsteer_dbc import names
from firmware_py.platform.bus_open import BusOpenError, open_bus
from firmware_py.platform.cli import Parser, check_output_file, fail
from firmware_py.platform.lifecycle import run_node
from firmware_py.platform.rx_queue import deepen

SENSOR_KINDS = ("sensor_stuck", "sensor_frozen", "sensor_bias", "sensor_scale", "sensor_drift", "sensor_noise")
KINDS = ("none", "drop", "delay", "duplicate", "reorder", "corrupt_payload", "corrupt_crc", "corrupt_counter",
         "wrong_length", "replay", "substitute", "out_of_range", "flood", "spoof_command", *SENSOR_KINDS)
SENSORS = names.SENSORS
COMMAND = names.MSG_CMD
FLOOD_ID = 0x7F0
HISTORY = 1024  # frames kept per message for replay and substitution (2 s of commands at 500 Hz)
# E2E and SecOC fields (the DBC's naming): out_of_range sets the first signal that is none of these.
PROTECTION_SUFFIXES = ("_CRC", "_Counter", "_FvEpoch", "_FvCounter", "_MAC")


@dataclass(frozen=True)
class Fault:
    kind: str = "none"
    target: str = names.MSG_YAW
    start: float = 1.0
    stop: float = 1.3
    param: float = 1.0
    signal: str | None = None  # sensor_* kinds: the signal to falsify (default: the first physical one)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"fault kind must be one of {', '.join(KINDS)}; got {self.kind!r}")
        if self.signal is not None and self.kind not in SENSOR_KINDS:
            raise ValueError(f"'signal' is for the sensor_* kinds only, not {self.kind!r}")
        if not (0.0 <= self.start < self.stop):
            raise ValueError(f"fault window must satisfy 0 <= start < stop, got {self.start}..{self.stop}")

    def targets(self) -> tuple[str, ...]:
        if self.target == "sensors":
            return SENSORS
        if self.target == "redundant":
            return names.REDUNDANT_SENSORS
        if self.target == "commands":
            return (COMMAND,)
        return (self.target,)


@dataclass
class BridgeStats:
    forwarded_to_controller: int = 0
    forwarded_to_vehicle: int = 0
    seen_on_vehicle: int = 0
    seen_on_controller: int = 0
    injected_to_controller: int = 0
    injected_to_vehicle: int = 0
    affected: int = 0
    first_affected: float | None = None  # epoch s
    last_affected: float | None = None
    t0: float | None = None  # epoch s of the vehicle's first frame: the fault window's origin
    rx_queue_bytes: int | None = None  # each side's kernel receive queue (None: no kernel socket)


def first_physical_signal(contract: mrsteer_dbc.Contract, name: str) -> Any:
    """The signal ``out_of_range`` sets: the message's first that is no protection field."""
    return next(s for s in contract.message(name).signals if not s.name.endswith(PROTECTION_SUFFIXES))


def out_of_range_problem(contract: mrsteer_dbc.Contract, fault: Fault) -> str | None:
    """Why ``out_of_range``'s value cannot be put in a target's frame (its raw field too
    narrow), or None."""
    if fault.kind != "out_of_range":
        return None
    for name in fault.targets():
        sig = first_physical_signal(contract, name)
        raw = round((fault.param - sig.offset) / sig.scale)
        lo, hi = (-(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1) if sig.is_signed else (0, (1 << sig.length) - 1)
        if not lo <= raw <= hi:
            return (f"{fault.param:g} does not fit {sig.name}'s {sig.length}-bit field "
                    f"({lo * sig.scale + sig.offset:g} to {hi * sig.scale + sig.offset:g})")
    return None


class Bridge:
    def __init__(self, vehicle: can.BusABC, controller: can.BusABC, fault: Fault, seed: int = 1) -> None:
        self.vehicle, self.controller, self.fault = vehicle, controller, fault
        self.contract = mrsteer_dbc.load()
        self.ids = {self.contract.frame_id(n) for n in fault.targets()}
        self.stats = BridgeStats()
        self.rng = random.Random(seed)
        self._running = True
        self._stopped_at = float("inf")
        self._lock = threading.Lock()
        self._history: dict[int, collections.deque[tuple[float, bytes]]] = collections.defaultdict(collections.deque)
        self._held: dict[int, can.Message] = {}
        self._frozen: dict[int, float] = {}  # sensor_frozen: the value held, per frame ID
        if fault.signal is not None:
            for name in fault.targets():
                self.contract.message(name).get_signal_by_name(fault.signal)  # KeyError: not this message's

    def stop(self, *_: Any) -> None:
        self._stopped_at = min(self._stopped_at, time.time())
        self._running = False

    # ------------------------------------------------------------------ fault logic

    def _active(self, now: float) -> bool:
        t0 = self.stats.t0
        return t0 is not None and self.fault.start <= now - t0 < self.fault.stop

    def _mark(self, now: float) -> None:
        with self._lock:
            self.stats.affected += 1
            if self.stats.first_affected is None:
                self.stats.first_affected = now
            self.stats.last_affected = now

    def _reencode(self, msg: can.Message, changes: dict[str, float]) -> bytes:
        name = self.contract.name_of(msg.arbitration_id)
        m = self.contract.message(name)
        values = m.decode(bytes(msg.data), decode_choices=False)
        values.update(changes)
        data = bytearray(m.encode(values, strict=False))
        e2e = self.contract.e2e(name)
        if e2e is not None:
            data[e2e.crc_byte] = self.contract.e2e_crc(name, bytes(data))
        return bytes(data)

    def transform(self, msg: can.Message, now: float) -> list[tuple[float, can.Message]]:
        """Frames to send for one frame received at ``now`` (epoch s), each with its send time:
        the fault applied if the frame is a target and the window is open (``stats.t0`` set)."""
        f = self.fault
        hist = self._history[msg.arbitration_id]
        hist.append((now, bytes(msg.data)))
        while len(hist) > HISTORY:
            hist.popleft()
        if msg.arbitration_id not in self.ids or not self._active(now):
            return [(now, msg)]
        kind = f.kind
        if kind in ("none", "flood"):
            return [(now, msg)]
        if kind in ("replay", "substitute") and len(hist) <= int(f.param):
            return [(now, msg)]  # not that many frames yet: forwarded as it is, and not counted
        self._mark(now)
        data = bytearray(msg.data)
        if kind == "drop":
            return [] if self.rng.random() < f.param else [(now, msg)]
        if kind == "delay":
            return [(now + f.param, msg)]
        if kind == "duplicate":
            return [(now, msg), (now, _copy(msg, bytes(msg.data)))]
        if kind == "reorder":
            held = self._held.pop(msg.arbitration_id, None)
            if held is None:
                self._held[msg.arbitration_id] = msg
                return []
            return [(now, msg), (now, held)]
        if kind == "corrupt_payload":
            data[-1] ^= 0x01
        elif kind == "corrupt_crc":
            data[0] ^= 0x80
        elif kind == "corrupt_counter":
            e2e = self.contract.e2e(self.contract.name_of(msg.arbitration_id))
            data = bytearray(self._reencode(msg, {e2e.counter_signal: 15}))
        elif kind == "wrong_length":
            data = data[:-1]
        elif kind == "replay":
            return [(now, msg), (now, _copy(msg, hist[-1 - int(f.param)][1]))]
        elif kind == "substitute":
            data = bytearray(hist[-1 - int(f.param)][1])
        elif kind == "spoof_command":
            return [(now, msg), (now, _copy(msg, self._forge(msg)))]
        elif kind == "out_of_range":
            first = first_physical_signal(self.contract, self.contract.name_of(msg.arbitration_id))
            data = bytearray(self._reencode(msg, {first.name: f.param}))
        elif kind in SENSOR_KINDS:
            data = bytearray(self._falsify(msg, now))
        return [(now, _copy(msg, bytes(data)))]

    def _signal_of(self, msg: can.Message) -> str:
        m = self.contract.message(self.contract.name_of(msg.arbitration_id))
        if self.fault.signal is not None:
            return m.get_signal_by_name(self.fault.signal).name
        return next(s.name for s in m.signals if not s.name.endswith(PROTECTION_SUFFIXES))

    def _falsify(self, msg: can.Message, now: float) -> bytes:
        """The frame with its sensor value made wrong (the counter kept, the CRC valid)."""
        f, name = self.fault, self._signal_of(msg)
        m = self.contract.message(self.contract.name_of(msg.arbitration_id))
        value = float(m.decode(bytes(msg.data), decode_choices=False)[name])
        if f.kind == "sensor_stuck":
            value = f.param
        elif f.kind == "sensor_frozen":
            held = self._frozen.get(msg.arbitration_id)
            if held is None:
                hist = self._history[msg.arbitration_id]  # this frame is its last entry
                before = hist[-2][1] if len(hist) > 1 else bytes(msg.data)
                held = self._frozen[msg.arbitration_id] = float(m.decode(before, decode_choices=False)[name])
            value = held
        elif f.kind == "sensor_bias":
            value += f.param
        elif f.kind == "sensor_scale":
            value *= f.param
        elif f.kind == "sensor_drift":
            value += f.param * (now - (self.stats.t0 or now) - f.start)
        else:  # sensor_noise
            value += f.param * self.rng.gauss(0.0, 1.0)
        return self._reencode(msg, {name: value})

    def _forge(self, real: can.Message) -> bytes:
        name = self.contract.name_of(real.arbitration_id)
        m = self.contract.message(name)
        values = m.decode(bytes(real.data), decode_choices=False)
        e2e = self.contract.e2e(name)
        changes = {e2e.counter_signal: (values[e2e.counter_signal] + 1) % mrsteer_dbc.COUNTER_MODULO,
                   "AuxSteerCmd_Angle": self.fault.param, "AuxSteerCmd_State": 1,
                   "AuxSteerCmd_MAC": self.rng.getrandbits(m.get_signal_by_name("AuxSteerCmd_MAC").length)}
        fv = m.get_signal_by_name("AuxSteerCmd_FvCounter")
        changes[fv.name] = (values[fv.name] + 1) % (1 << fv.length)
        return self._reencode(real, changes)

    # ------------------------------------------------------------------ threads

    def _pump(self, src: can.BusABC, dst: can.BusABC, to_controller: bool) -> None:
        pending: list[tuple[float, int, can.Message]] = []
        seq = 0
        while self._running:
            now = time.time()
            while pending and pending[0][0] <= now:
                self._send(dst, heapq.heappop(pending)[2], to_controller)
            wait = 0.05 if not pending else max(0.0, min(0.05, pending[0][0] - now))
            msg = src.recv(wait)
            if msg is None:
                continue
            now = time.time()
            self._saw(msg, to_controller, now)
            for when, out in self.transform(msg, now):
                if when <= now:
                    self._send(dst, out, to_controller)
                else:
                    seq += 1
                    heapq.heappush(pending, (when, seq, out))
        # Stopped: what was on the bus before the stop may still be queued for us (all of it,
        # when this process lagged behind); forward it unchanged.  Later frames are not ours.
        while (msg := src.recv(0.05)) is not None and msg.timestamp <= self._stopped_at:
            self._saw(msg, to_controller, time.time())
            self._send(dst, msg, to_controller)
        for _, _, out in sorted(pending):
            self._send(dst, out, to_controller)

    def _saw(self, msg: can.Message, on_vehicle: bool, now: float) -> None:
        """Count a frame seen on one side; the vehicle's first frame starts the fault clock."""
        with self._lock:
            if on_vehicle:
                self.stats.seen_on_vehicle += 1
                if self.stats.t0 is None:
                    self.stats.t0 = now
            else:
                self.stats.seen_on_controller += 1

    def _send(self, dst: can.BusABC, msg: can.Message, to_controller: bool, injected: bool = False) -> None:
        dst.send(msg)
        with self._lock:
            if injected:
                if to_controller:
                    self.stats.injected_to_controller += 1
                else:
                    self.stats.injected_to_vehicle += 1
            elif to_controller:
                self.stats.forwarded_to_controller += 1
            else:
                self.stats.forwarded_to_vehicle += 1

    def flood(self) -> None:
        """Send the flood's frames to the controller side while the fault window is open, until
        stopped (``run`` gives it a thread of its own when the fault is a flood)."""
        # Keeps count of what is due since the window opened and sends it in bursts: a sleep
        # per frame would cap the rate at the scheduler's granularity, far below ``param``.
        period = 1.0 / max(self.fault.param, 1.0)
        began, sent = None, 0
        while self._running:
            now = time.time()
            if self._active(now):
                began = now if began is None else began
                due = int((now - began) / period) + 1
                while sent < due and self._running:
                    self._send(self.controller, can.Message(arbitration_id=FLOOD_ID, data=bytes(8),
                                                            is_extended_id=False), True, injected=True)
                    self._mark(now)
                    sent += 1
            time.sleep(min(period, 0.001))

    def run(self) -> BridgeStats:
        threads = [threading.Thread(target=self._pump, args=(self.vehicle, self.controller, True), daemon=True),
                   threading.Thread(target=self._pump, args=(self.controller, self.vehicle, False), daemon=True)]
        if self.fault.kind == "flood":
            threads.append(threading.Thread(target=self.flood, daemon=True))
        for t in threads:
            t.start()
        while self._running and all(t.is_alive() for t in threads):
            time.sleep(0.05)
        self.stop()  # a pump that died stops the other: both drain what came before
        for t in threads:
            t.join()  # the drain ends: it takes only frames from before the stop
        return self.stats


def _copy(msg: can.Message, data: bytes) -> can.Message:
    return can.Message(arbitration_id=msg.arbitration_id, data=data, is_extended_id=msg.is_extended_id)


def main(argv: Sequence[str] | None = None, prog: str = "mrsteer faults bridge") -> int:
    p = Parser(prog=prog, description="Forward frames between the vehicle's and the controller's bus, injecting "
               "one fault in a time window (kinds: " + ", ".join(KINDS[1:]) + ").")
    p.add_argument("--interface", default="mrsteer", help="python-can interface of both sides (default mrsteer)")
    p.add_argument("--vehicle", required=True, help="channel of the vehicle side (plant)")
    p.add_argument("--controller", required=True, help="channel of the controller side")
    p.add_argument("--fault", default="{}", help='fault as JSON, e.g. \'{"kind": "drop", "target": "MRS_YawRate", '
                   '"start": 1.0, "stop": 1.3, "param": 1.0}\'')
    p.add_argument("--seed", type=int, default=1, help="random seed of probabilistic faults (default 1)")
    p.add_argument("--stats-out", type=Path, help="write the bridge's counts as JSON here on exit")
    args = p.parse_args(argv)
    try:
        spec = json.loads(args.fault)
        if not isinstance(spec, dict):
            raise ValueError("the fault must be a JSON object")
        fault = Fault(**spec)
        for name in fault.targets():
            if name not in {m.name for m in mrsteer_dbc.load().db.messages}:
                raise ValueError(f"no message {name!r} in the DBC")
            if fault.signal is not None and fault.signal not in {
                    sig.name for sig in mrsteer_dbc.load().message(name).signals}:
                raise ValueError(f"{name} has no signal {fault.signal!r}")
        if (problem := out_of_range_problem(mrsteer_dbc.load(), fault)) is not None:
            raise ValueError(problem)
    except (ValueError, TypeError) as exc:
        p.error(f"--fault: {exc}")
    if args.vehicle == args.controller:
        p.error("--vehicle and --controller must be different channels")
    check_output_file(p, "--stats-out", args.stats_out)
    try:
        a = open_bus(args.interface, args.vehicle, notice=lambda m: None)
    except BusOpenError as exc:
        return fail(prog, str(exc))
    try:
        b = open_bus(args.interface, args.controller, notice=lambda m: None)
    except BusOpenError as exc:
        a.shutdown()
        return fail(prog, str(exc))
    bridge = Bridge(a, b, fault, args.seed)
    queues = [deepen(a), deepen(b)]
    bridge.stats.rx_queue_bytes = None if None in queues else min(queues)  # type: ignore[type-var]
    return run_node(prog, (a, b), bridge.run, bridge.stop,
                    [(args.stats_out, lambda: json.dumps(asdict(bridge.stats), indent=2))],
                    ready=f"bridging {args.vehicle} <-> {args.controller}, fault {fault.kind}")


if __name__ == "__main__":
    sys.exit(main())
