"""The controller process: the firmware ``step()`` in a fixed-rate loop on a CAN bus.

Each cycle, in this order (the scheduling contract a port must keep):

1. drain every received frame; check length, E2E CRC, alive counter and DBC range; keep the
   newest accepted value of each input (driver angle, yaw rate, speed);
2. freshness: an input whose last accepted frame is older than ``timeout_cycles`` of its own
   DBC cycle time, or which has been rejected ``e2e_fail_max`` times in a row, is invalid;
3. run ``step()``; an invalid input is passed as NaN, which makes the firmware fade its
   command to zero and re-initialise bumplessly once the input is good again;
4. send ``MRS_AuxSteerCmd`` (and ``MRS_CtrlStatus`` at its DBC cycle time).

With a SecOC key (``--secoc``/``--secoc-key``) step 1 also takes the actuator's
``MRS_SecOCSync`` frames and verifies each sensor frame's MAC (after length, CRC and range,
before the alive counter; a failure counts as a rejected frame of cause ``CAUSE_AUTH``), and
step 4 signs each command (``mrsteer_dbc.secoc``); without a valid sync for
``SYNC_STALE_CYCLES`` of its cycle time the status reports ``CAUSE_AUTH``.

Two triggers: ``clock`` (default) runs on absolute deadlines of the monotonic clock, counting
overruns; ``sensors`` runs one cycle per received yaw-rate frame (for lockstep runs with the
plant, where simulated time is set by the plant; with no yaw-rate frame for
``SENSORS_WATCHDOG_S`` of wall time it runs a cycle anyway).  Freshness is counted in controller cycles
either way.  SIGINT/SIGTERM end the loop after the current cycle with a final zero command
marked inactive, and exit status 0.
"""

from __future__ import annotations

import argparse
import array
import gc
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Sequence

import can

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.bus_open import BusOpenError, open_bus
from firmware_py.cli_support import (Parser, add_secoc_args, check_output_file, model_delay_help, resolve_model_delay,
                                     run_node, secoc_key)
from mrsteer_dbc import secoc

MSG_STEER = "MRS_DriverSteer"
MSG_YAW = "MRS_YawRate"
MSG_SPEED = "MRS_VehicleSpeed"
MSG_CMD = "MRS_AuxSteerCmd"
MSG_STATUS = "MRS_CtrlStatus"

# CtrlStatus_Cause bits (documented in the DBC)
CAUSE_STEER_MISSING = 0x01
CAUSE_YAW_MISSING = 0x02
CAUSE_SPEED_MISSING = 0x04
CAUSE_E2E = 0x08
CAUSE_RANGE = 0x10
CAUSE_LOW_SPEED = 0x20
# SecOC on: no valid freshness sync (the actuator will not apply commands), or sensor frames failing their MAC
CAUSE_AUTH = 0x40
SYNC_STALE_CYCLES = 3  # MRS_SecOCSync cycle times without a valid sync before CAUSE_AUTH

MEAS_NONE = 15  # AuxSteerCmd_MeasCounter when the command answers no measurement
DEFAULT_RATE_HZ = 1.0 / mr.ControllerConfig().ts  # the rate the shipped calibration was tuned for
SENSORS_WATCHDOG_S = 1.0
DEFAULT_SYNC_OFFSET = 50e-6  # s after the yaw-rate frame's arrival that the cycle aims to start
SYNC_GAIN = 0.1  # fraction of the phase error corrected per cycle
SYNC_MAX_SLEW = 0.02  # largest correction per cycle, as a fraction of the period
SYNC_POLL_S = 20e-6  # polling step inside that window
SYNC_WINDOW = 0.25  # how long a cycle waits for a late yaw-rate frame, as a fraction of the period  # sensors trigger: wall time without a yaw-rate frame before a cycle runs anyway
TRIGGERS = ("clock", "sensors")


@dataclass(frozen=True)
class RuntimeConfig:
    rate_hz: float = DEFAULT_RATE_HZ
    timeout_cycles: int = 10  # per input, in units of that input's DBC cycle time
    e2e_fail_max: int = 3  # consecutive rejected frames of one input that fault it at once
    max_counter_delta: int = 3
    trigger: str = "clock"
    # Clock trigger: phase-lock the cycle start to this long after the yaw-rate frames'
    # arrival, so a measurement waits ~this long for its command (None: free-running grid).
    sync_offset: float | None = DEFAULT_SYNC_OFFSET
    duration: float | None = None  # s; None runs until a signal
    secoc_key: bytes | None = None  # sign the commands, verify the sensor frames (mrsteer_dbc.secoc) when given
    controller: mr.ControllerConfig = field(default_factory=mr.ControllerConfig)


class _Input:
    """Receive state of one sensor message (the C port's per-signal RX record)."""

    __slots__ = ("name", "signal", "missing_cause", "value", "age", "limit", "rejects", "receiver",
                 "last_counter", "bad_cause")

    def __init__(self, name: str, signal_name: str, missing_cause: int, limit_cycles: int, max_delta: int) -> None:
        self.name = name
        self.signal = signal_name
        self.missing_cause = missing_cause
        self.value = math.nan
        self.age = limit_cycles + 1  # never received: invalid until the first good frame
        self.limit = limit_cycles
        self.rejects = 0
        self.receiver = mrsteer_dbc.E2EReceiver(max_delta)
        self.last_counter = 0
        self.bad_cause = 0


class LatenessHistogram:
    """Cycle-start lateness in fixed 1 us bins up to 50 ms, preallocated: a run of any length
    costs no memory (a C port keeps the same uint32 array)."""

    BIN_S = 1e-6
    BINS = 50_000

    def __init__(self) -> None:
        self.counts = array.array("I", bytes(4 * (self.BINS + 1)))  # the last bin is overflow
        self.n = 0
        self.max = 0.0

    def add(self, late: float) -> None:
        i = int(late / self.BIN_S) if late > 0.0 else 0
        self.counts[i if i < self.BINS else self.BINS] += 1
        self.n += 1
        if late > self.max:
            self.max = late

    def percentile(self, q: float) -> float:
        """Upper edge of the bin holding the q-quantile (the max if it lies in the overflow)."""
        if self.n == 0:
            return 0.0
        rank = min(self.n, max(1, math.ceil(q * self.n)))
        seen = 0
        for i, c in enumerate(self.counts):
            seen += c
            if seen >= rank:
                return self.max if i == self.BINS else min((i + 1) * self.BIN_S, self.max)
        return self.max


def _rss_kb() -> int:
    """Resident set size now, in KiB (Linux /proc; 0 where unavailable)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") // 1024)
    except (OSError, ValueError, IndexError):
        return 0


@dataclass
class LoopStats:
    cycles: int = 0
    overruns: int = 0
    missed_cycles: int = 0
    rx_frames: int = 0
    rx_rejected: int = 0
    rx_ignored: int = 0
    syncs_rejected: int = 0  # MRS_SecOCSync frames that failed their MAC or were not newer
    rx_auth_failed: int = 0  # sensor frames that failed SecOC (also counted in rx_rejected)
    tx_frames: int = 0
    faults_entered: int = 0
    lateness: LatenessHistogram = field(default_factory=LatenessHistogram)
    rss_kb_loop_start: int = 0
    rss_kb_loop_end: int = 0
    platform: dict[str, Any] = field(default_factory=dict)  # what real-time features were applied

    def summary(self) -> dict[str, Any]:
        lat = self.lateness
        return {
            "cycles": self.cycles, "overruns": self.overruns, "missed_cycles": self.missed_cycles,
            "rx_frames": self.rx_frames, "rx_rejected": self.rx_rejected, "rx_ignored": self.rx_ignored,
            "syncs_rejected": self.syncs_rejected, "rx_auth_failed": self.rx_auth_failed,
            "tx_frames": self.tx_frames, "faults_entered": self.faults_entered,
            "lateness_p50_s": lat.percentile(0.5), "lateness_p99_s": lat.percentile(0.99), "lateness_max_s": lat.max,
            "rss_kb_loop_start": self.rss_kb_loop_start, "rss_kb_loop_end": self.rss_kb_loop_end,
            "rss_kb_growth": self.rss_kb_loop_end - self.rss_kb_loop_start, **self.platform,
        }


def phase_correction(arrival: float, cycle_start: float, period: float, offset: float) -> float:
    """Shift of the next deadline that moves cycle starts toward ``arrival + offset``.

    The error is wrapped into half a period either way (the grid may lock onto the nearest
    frame), a fraction SYNC_GAIN of it is corrected, at most SYNC_MAX_SLEW of a period per
    cycle, so sensor jitter cannot drag the loop around.
    """
    err = arrival + offset - cycle_start
    err -= period * round(err / period)
    limit = SYNC_MAX_SLEW * period
    return max(-limit, min(limit, SYNC_GAIN * err))


class ControllerNode:
    """One controller on one bus.  ``cycle()`` is the periodic body; ``run()`` the loop."""

    def __init__(self, bus: can.BusABC, config: RuntimeConfig, contract: mrsteer_dbc.Contract | None = None) -> None:
        self.bus = bus
        self.cfg = config
        self.contract = contract or mrsteer_dbc.load()
        period = 1.0 / config.rate_hz
        self.period = period
        c = self.contract
        # The firmware's input ranges are the DBC's: one source of truth for what is valid.
        ctrl = replace(config.controller, ts=period,
                       driver_angle_max=c.signal_range(MSG_STEER, "DriverSteer_Angle")[1],
                       yaw_rate_max=c.signal_range(MSG_YAW, "YawRate_YawRate")[1],
                       speed_max=c.signal_range(MSG_SPEED, "VehicleSpeed_Speed")[1],
                       aux_limit=min(config.controller.aux_limit, c.signal_range(MSG_CMD, "AuxSteerCmd_Angle")[1]))
        self.coeffs = mr.configure(ctrl)
        self.state = mr.State()

        def limit(name: str, cycles: int = config.timeout_cycles) -> int:
            """``cycles`` of the message's own cycle time, in controller periods (rounded up; the
            1e-9 keeps 3 * 0.1 / 1e-3 = 300.00000000000006 at 300)."""
            cycle = c.cycle_time_s(name, period) or period
            return max(1, int(math.ceil(cycles * cycle / period - 1e-9)))

        self.inputs = {
            c.frame_id(MSG_STEER): _Input(MSG_STEER, "DriverSteer_Angle", CAUSE_STEER_MISSING, limit(MSG_STEER),
                                          config.max_counter_delta),
            c.frame_id(MSG_YAW): _Input(MSG_YAW, "YawRate_YawRate", CAUSE_YAW_MISSING, limit(MSG_YAW),
                                        config.max_counter_delta),
            c.frame_id(MSG_SPEED): _Input(MSG_SPEED, "VehicleSpeed_Speed", CAUSE_SPEED_MISSING, limit(MSG_SPEED),
                                          config.max_counter_delta),
        }
        self._steer, self._yaw, self._speed = self.inputs.values()
        self.yaw_id = c.frame_id(MSG_YAW)
        self.signer = secoc.CommandSigner(c, config.secoc_key) if config.secoc_key is not None else None
        self.sensor_verifier = secoc.SensorVerifier(c, config.secoc_key) if config.secoc_key is not None else None
        self.sync_id = c.frame_id(secoc.SYNC) if self.signer is not None else None
        self.sync_limit = limit(secoc.SYNC, SYNC_STALE_CYCLES)
        self._sync_age = self.sync_limit + 1
        wanted = [*self.inputs, *([self.sync_id] if self.sync_id is not None else [])]
        bus.set_filters([{"can_id": fid, "can_mask": 0x7FF, "extended": False} for fid in wanted])
        self.cmd_id = c.frame_id(MSG_CMD)
        self.status_id = c.frame_id(MSG_STATUS)
        self.cmd_counter = mrsteer_dbc.AliveCounter()
        status_cycle = c.cycle_time_s(MSG_STATUS) or 0.1
        self.status_every = max(1, int(round(status_cycle / period)))
        self.stats = LoopStats()
        self.cause = 0
        self.command = 0.0
        self._max_lateness = 0.0
        self._running = True
        self._was_fault = False
        self._answers = MEAS_NONE
        self._yaw_stamp = 0.0  # bus timestamp (epoch s) of the newest accepted yaw-rate frame

    # ---------------------------------------------------------------- receive

    def _receive(self, msg: can.Message) -> bool:
        """Check and store one frame; True if it was an accepted yaw-rate frame."""
        self.stats.rx_frames += 1
        if msg.arbitration_id == self.sync_id and not (msg.is_extended_id or msg.is_error_frame):
            self._receive_sync(bytes(msg.data))
            return False
        inp = self.inputs.get(msg.arbitration_id)
        if inp is None or msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame:
            self.stats.rx_ignored += 1
            return False
        data = bytes(msg.data)
        decoded = self.contract.decode(msg.arbitration_id, data)
        status = decoded.status if decoded is not None else mrsteer_dbc.E2EStatus.BAD_LENGTH
        # Authenticate before the counter check: a forged frame must not advance the sequence.
        if status is mrsteer_dbc.E2EStatus.OK and self.sensor_verifier is not None and not self.sensor_verifier.verify(
                msg.arbitration_id, data, decoded.signals):
            self.stats.rx_auth_failed += 1
            return self._reject(inp, CAUSE_AUTH)
        if status is mrsteer_dbc.E2EStatus.OK:
            status = inp.receiver.check(decoded.counter)
        if not status.accepted:
            return self._reject(inp, CAUSE_RANGE if status is mrsteer_dbc.E2EStatus.OUT_OF_RANGE else CAUSE_E2E)
        inp.rejects = 0
        inp.value = decoded.signals[inp.signal]
        inp.last_counter = decoded.counter
        inp.age = 0
        if msg.arbitration_id == self.yaw_id:
            self._yaw_stamp = msg.timestamp or 0.0
            return True
        return False

    def _reject(self, inp: _Input, cause: int) -> bool:
        self.stats.rx_rejected += 1
        inp.rejects += 1
        inp.bad_cause = cause
        return False

    def _receive_sync(self, data: bytes) -> None:
        decoded = self.contract.decode(self.sync_id, data)
        if decoded is not None and decoded.status.accepted and self.signer.accept_sync(data):
            self._sync_age = 0
            self.sensor_verifier.adopt(self.signer.epoch)
        else:
            self.stats.syncs_rejected += 1

    def drain(self) -> bool:
        got_yaw = False
        recv = self.bus.recv
        while True:
            msg = recv(0.0)
            if msg is None:
                return got_yaw
            got_yaw = self._receive(msg) or got_yaw

    # ---------------------------------------------------------------- control

    def control(self) -> None:
        """Steps 2-4 of the cycle, after the receive queue has been drained."""
        cause = 0
        values = []
        for inp in (self._steer, self._yaw, self._speed):
            ok = inp.age <= inp.limit and inp.rejects < self.cfg.e2e_fail_max
            if not ok:
                cause |= inp.missing_cause if inp.rejects < self.cfg.e2e_fail_max else inp.bad_cause
            values.append(inp.value if ok else math.nan)
            inp.age += 1
        # Which measurement this command answers; NONE when no valid yaw rate went into it.
        self._answers = MEAS_NONE if math.isnan(values[1]) else self._yaw.last_counter
        u = mr.step(self.coeffs, self.state, values[0], values[1], values[2])
        if self.state.fault_flags and not cause:
            cause |= CAUSE_RANGE
        if self.state.status == mr.STATUS_INACTIVE and not cause:
            cause |= CAUSE_LOW_SPEED
        if self.signer is not None:
            self._sync_age += 1
            if self._sync_age > self.sync_limit or not self.signer.synced:
                cause |= CAUSE_AUTH
        fault = self.state.status == mr.STATUS_FAULT
        if fault and not self._was_fault:
            self.stats.faults_entered += 1
        self._was_fault = fault
        self.cause = cause
        self.command = u
        self._send_command(u, self.state.status)
        self.stats.cycles += 1
        if self.stats.cycles % self.status_every == 0:
            self._send_status()

    def _send_command(self, u: float, state: int) -> None:
        values = {"AuxSteerCmd_State": state, "AuxSteerCmd_Angle": u, "AuxSteerCmd_MeasCounter": self._answers}
        if self.signer is not None:
            data = self.signer.sign(values, self.cmd_counter.next())
        else:
            data = self.contract.encode(MSG_CMD, values, self.cmd_counter.next())
        self.bus.send(can.Message(arbitration_id=self.cmd_id, data=data, is_extended_id=False))
        self.stats.tx_frames += 1

    def _send_status(self) -> None:
        data = self.contract.encode(MSG_STATUS, {
            "CtrlStatus_State": self.state.status,
            "CtrlStatus_InputFlags": self.state.fault_flags,
            "CtrlStatus_Cause": self.cause,
            "CtrlStatus_Rejected": self.stats.rx_rejected % 65536,
            "CtrlStatus_Overruns": self.stats.overruns % 65536,
            "CtrlStatus_MaxLateness": min(self._max_lateness, 0.65535),
        })
        self.bus.send(can.Message(arbitration_id=self.status_id, data=data, is_extended_id=False))
        self.stats.tx_frames += 1
        self._max_lateness = 0.0

    # ---------------------------------------------------------------- loop

    def stop(self, *_: Any) -> None:
        self._running = False

    def run(self) -> None:
        end = None if self.cfg.duration is None else time.monotonic() + self.cfg.duration
        gc.collect()
        gc.freeze()  # keep start-up objects out of the collector's way during the loop
        gc.disable()  # the loop makes no reference cycles: reference counting frees everything
        self.stats.platform["gc_disabled_in_loop"] = True
        self.stats.rss_kb_loop_start = _rss_kb()
        try:
            if self.cfg.trigger == "sensors":
                self._run_on_sensors(end)
            else:
                self._run_on_clock(end)
        finally:
            self.stats.rss_kb_loop_end = _rss_kb()
            gc.enable()
            gc.unfreeze()
        self.finish()

    def _run_on_clock(self, end: float | None) -> None:
        period = self.period
        deadline = time.monotonic()
        lateness = self.stats.lateness
        sync = self.cfg.sync_offset
        window = SYNC_WINDOW * period
        epoch_to_mono = time.monotonic() - time.time()
        while self._running:
            now = time.monotonic()
            if now < deadline:
                time.sleep(deadline - now)
                now = time.monotonic()
            late = now - deadline
            lateness.add(late)
            if late > self._max_lateness:
                self._max_lateness = late
            if late >= period:
                # Whole periods were lost: count them and restart the grid from now.
                missed = int(late / period)
                self.stats.overruns += 1
                self.stats.missed_cycles += missed
                deadline += missed * period
            got_yaw = self.drain()
            if sync is not None and not got_yaw:
                # This period's frame is late: give it a bounded window rather than answer it a
                # whole period later.
                # Polled in short sleeps: socket timeouts round up to whole milliseconds.
                until = now + window
                while not got_yaw and (left := until - time.monotonic()) > 0.0:
                    msg = self.bus.recv(0.0)
                    if msg is None:
                        time.sleep(min(left, SYNC_POLL_S))
                    else:
                        got_yaw = self._receive(msg)
            self.control()
            deadline += period
            if sync is not None and got_yaw and self._yaw_stamp > 0.0:
                deadline += phase_correction(self._yaw_stamp + epoch_to_mono, now, period, sync)
            if end is not None and now >= end:
                break

    def _run_on_sensors(self, end: float | None) -> None:
        # One cycle per accepted yaw-rate frame; if none comes for a while, run a cycle anyway
        # so that the fault path (fade to zero) still executes.  Simulated time is the plant's
        # here: a plant that is merely slow (an emulated CPU, a debugger) must not look like
        # lost input, so the wait is at least SENSORS_WATCHDOG_S of wall time.
        wait = max(self._yaw.limit * self.period, SENSORS_WATCHDOG_S)
        while self._running:
            got = False
            msg = self.bus.recv(wait)
            if msg is not None:
                got = self._receive(msg)
            got = self.drain() or got
            if got or msg is None:
                self.control()
            if end is not None and time.monotonic() >= end:
                break

    def finish(self) -> None:
        """Final zero command marked inactive, as on an orderly shutdown."""
        try:
            self._send_command(0.0, mr.STATUS_INACTIVE)
        except can.CanError:
            pass  # the bus is already gone: nothing more can be said on it


def build_parser(prog: str = "mrsteer controller") -> argparse.ArgumentParser:
    d = mr.ControllerConfig()
    p = Parser(prog=prog, description="Run the model-regulator controller on a CAN bus: read driver angle, "
               "yaw rate and speed, send the auxiliary steering command.")
    p.add_argument("--interface", help="python-can interface (default: python-can config, else SocketCAN vcan0 "
                   "if present, else the mrsteer fallback bus)")
    p.add_argument("--channel", help="channel for the interface (default vcan0 / mrsteer0)")
    p.add_argument("--rate-hz", type=float, default=DEFAULT_RATE_HZ,
                   help=f"control rate in Hz (default {DEFAULT_RATE_HZ:g}, the rate the default gains were tuned for)")
    p.add_argument("--trigger", choices=TRIGGERS, default="clock",
                   help="clock: fixed rate on the monotonic clock (default); sensors: one cycle per yaw-rate frame")
    p.add_argument("--sync-offset-us", type=float, default=DEFAULT_SYNC_OFFSET * 1e6, metavar="US",
                   help="clock trigger: start each cycle this long after the yaw-rate frame arrives, by "
                   f"phase-locking the loop to the frames (default {DEFAULT_SYNC_OFFSET * 1e6:g})")
    p.add_argument("--no-sync", action="store_true", help="clock trigger: free-running grid, no phase lock")
    p.add_argument("--timeout-cycles", type=int, default=10,
                   help="an input missing for more than this many of its own cycle times is a fault (default 10)")
    p.add_argument("--controller", choices=(mr.Q_LIMITED, mr.Q_STANDARD), default=d.q_form,
                   help="Q filter: limited (eq. 22, default) or standard (eq. 17)")
    p.add_argument("--k", type=float, default=d.k, help=f"eq. (22) gain K (default {d.k:g})")
    p.add_argument("--tau", type=float, default=d.tau, help=f"eq. (22) time constant in s (default {d.tau:g})")
    p.add_argument("--tau-n", type=float, default=d.tau_n, help=f"eq. (18) time constant in s (default {d.tau_n:g})")
    p.add_argument("--method", choices=(mr.METHOD_TUSTIN, mr.METHOD_ZOH), default=d.method)
    p.add_argument("--model-delay", type=int, default=None, metavar="M",
                   help=model_delay_help(d.model_delay_steps, mr.MAX_MODEL_DELAY))
    p.add_argument("--rate-limit", type=float, default=0.0, metavar="RAD_S",
                   help="command rate limit in rad/s (default 0: off)")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds")
    p.add_argument("--stats-out", type=Path, default=None, metavar="FILE",
                   help="write loop statistics as JSON here on exit")
    add_secoc_args(p)
    p.add_argument("--rt-priority", type=int, default=0, metavar="P",
                   help="run under SCHED_FIFO at priority P (1..99) where permitted; 0 (default) leaves the "
                   "scheduler alone; what was applied is reported in --stats-out")
    p.add_argument("--cpu", type=int, default=None, metavar="N",
                   help="pin the process to CPU N where permitted (reported in --stats-out)")
    return p


def apply_platform(rt_priority: int, cpu: int | None) -> dict[str, Any]:
    """Real-time priority and CPU pinning, where the OS permits them; says what happened."""
    out: dict[str, Any] = {"rt_priority": 0, "cpu_affinity": sorted(os.sched_getaffinity(0))}
    if rt_priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt_priority))
            out["rt_priority"] = rt_priority
        except (OSError, AttributeError) as exc:
            out["rt_priority_denied"] = str(exc)
    if cpu is not None:
        try:
            os.sched_setaffinity(0, {cpu})
        except (OSError, ValueError) as exc:
            out["cpu_denied"] = str(exc)
        out["cpu_affinity"] = sorted(os.sched_getaffinity(0))
    return out


def main(argv: Sequence[str] | None = None, prog: str = "mrsteer controller") -> int:
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    resolve_model_delay(args)
    if not (math.isfinite(args.rate_hz) and 1.0 <= args.rate_hz <= 10000.0):
        parser.error(f"--rate-hz must be in [1, 10000], got {args.rate_hz}")
    if args.timeout_cycles < 1:
        parser.error("--timeout-cycles must be at least 1")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        parser.error("--duration must be positive")
    if not 0 <= args.rt_priority <= 99:
        parser.error(f"--rt-priority must be in 0..99, got {args.rt_priority}")
    if args.cpu is not None and not 0 <= args.cpu < (os.cpu_count() or 1):
        parser.error(f"--cpu must be in 0..{(os.cpu_count() or 1) - 1}, got {args.cpu}")
    try:
        ctrl = mr.ControllerConfig(q_form=args.controller, k=args.k, tau=args.tau, tau_n=args.tau_n,
                                   method=args.method, rate_limit=args.rate_limit, ts=1.0 / args.rate_hz,
                                   model_delay_steps=args.model_delay)
        mr.configure(ctrl)
    except ValueError as exc:
        parser.error(str(exc))
    if not (math.isfinite(args.sync_offset_us) and 0.0 <= args.sync_offset_us * 1e-6 < 1.0 / args.rate_hz):
        parser.error(f"--sync-offset-us must be in [0, one period), got {args.sync_offset_us}")
    check_output_file(parser, "--stats-out", args.stats_out)
    cfg = RuntimeConfig(rate_hz=args.rate_hz, timeout_cycles=args.timeout_cycles, trigger=args.trigger,
                        sync_offset=None if args.no_sync else args.sync_offset_us * 1e-6,
                        duration=args.duration, secoc_key=secoc_key(args, parser), controller=ctrl)
    try:
        bus = open_bus(args.interface, args.channel)
    except BusOpenError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    node = ControllerNode(bus, cfg)
    node.stats.platform.update(apply_platform(args.rt_priority, args.cpu))
    auth = ", commands and sensor frames authenticated (SecOC)" if cfg.secoc_key is not None else ""
    return run_node(prog, bus, node.run, node.stop,
                    [(args.stats_out, lambda: json.dumps(node.stats.summary(), indent=2))],
                    ready=f"running at {args.rate_hz:g} Hz ({args.trigger} trigger{auth}) on {bus.channel_info}")
