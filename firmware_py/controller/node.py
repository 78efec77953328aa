"""The controller process: the firmware ``step()`` in a fixed-rate loop on a CAN bus.

Each cycle, in this order (the scheduling contract a port must keep):

1. drain every received frame; check length, E2E CRC, alive counter and DBC range; keep the
   newest accepted value of each input (driver angle, yaw rate, speed);
2. freshness: an input whose last accepted frame is older than ``timeout_cycles`` of its own
   DBC cycle time, or which has been rejected ``e2e_fail_max`` times in a row, is invalid;
3. run ``step()``; an invalid input is passed as NaN, which makes the firmware fade its
   command to zero and re-initialise bumplessly once the input is good again;
4. the plausibility monitor (``firmware_py.plausibility``) checks the inputs against each other,
   against ``MRS_RedundantSensors`` (lateral acceleration, the second steering channel; NaN when
   missing, which makes it report DEGRADED) and against the nominal car, given the command sent
   the period before.  Its clock is the yaw-rate sensor's: it steps once for each yaw-rate
   sample since the last cycle, counted by the frames' alive counter (``monitor_steps``: a lost
   or rejected frame's sample counts, at the next one's values), and holds its verdict in a
   cycle without one; with the yaw rate timed out it steps once to pause.  So a sender slower
   than the loop (a plant that cannot keep real time) does not stretch its filters, windows
   and derivatives, and a burst or a lost frame does not shorten them.  A redundant sample goes
   to the monitor with the next yaw-rate sample (the plant sends the two in the same step) and
   the driver's angle that came with it (``monitor_driver_angle``, for a burst), and the monitor
   differentiates over the yaw-rate samples between two of them, so a sample is withheld (NaN
   until the next one) when it arrived more than ``REDUNDANT_JITTER_CYCLES`` (``sample_clock``)
   yaw-rate samples away from what its alive counter says elapsed (delta x 50 ms): a stalled
   sender or receiver, whose bursts would read as a side slip.  The
   authority limiter (``firmware_py.authority``) bounds ``step()``'s command in magnitude, rate
   and time and fades it to zero on a plausibility fault (``CAUSE_PLAUSIBILITY``);
5. send ``MRS_AuxSteerCmd`` (and ``MRS_CtrlStatus`` at its DBC cycle time) with the reported
   state (``model_regulator.reported_state``): FAULT on a plausibility fault or when ``step()``
   faulted, DEGRADED when the monitor is degraded, else ``step()``'s INACTIVE, ACTIVE or
   SATURATED; and STARTING in place of all but a plausibility fault from power-up until every
   sensor message (the redundant one too: a clean start shows no DEGRADED either) has been
   accepted once.  The start state is bounded (``_still_starting``): an input still missing its
   own timeout after the first sensor frame was accepted, or any ``START_TIMEOUT_S`` after the
   first cycle, ends it, and the missing input is reported as it is later on.

Every frame goes through the node's links (``mrsteer_dbc.link``): ``RxLink`` checks a received
one and names the cause of a rejection, ``TxLink`` builds the command and the status.  With a
SecOC key (``--secoc``/``--secoc-key``) step 1 also takes the actuator's ``MRS_SecOCSync``
frames and verifies each sensor frame's MAC (a failure counts as a rejected frame of cause
``CAUSE_AUTH``), and step 4 signs each command (``mrsteer_dbc.secoc``); without a valid sync
for ``SYNC_STALE_CYCLES`` of its cycle time the status reports ``CAUSE_AUTH``.  Until the first
authentic sync (at power-up), and while the last one is that stale (the actuator restarted or
the syncs are lost), no command is sent at all (``cmd_withheld``): the actuator could not verify
it, and a rejected command is an alarm there.

Two triggers: ``clock`` (default) runs on absolute deadlines of the monotonic clock, counting
overruns; ``sensors`` runs one cycle per received yaw-rate frame (for lockstep runs with the
plant, where simulated time is set by the plant; with no yaw-rate frame for
``SENSORS_WATCHDOG_S`` of wall time it runs a cycle anyway).  Freshness is counted in controller cycles
either way.  SIGINT/SIGTERM end the loop after the current cycle (the sensors trigger
waits for frames in slices of ``STOP_POLL_S``, so it notices promptly) with a final zero command
marked inactive, and exit status 0.
"""

from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import can

import mrsteer_dbc
from firmware_py import authority as au
from firmware_py import cycle as cy
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from firmware_py.controller.inputs import Input
from firmware_py.controller.sample_clock import SampleClock
from firmware_py.controller.stats import LoopStats
from firmware_py.controller.timing import (DEFAULT_SYNC_OFFSET, SENSORS_WATCHDOG_S, STOP_POLL_S, SYNC_POLL_S,
                                           SYNC_WINDOW, phase_correction)
from firmware_py.platform.realtime import rss_kb
from mrsteer_dbc import secoc
from mrsteer_dbc.link import Rejected, RxLink, TxLink
from mrsteer_dbc.names import (CAUSE_AUTH, CAUSE_LOW_SPEED, CAUSE_PLAUSIBILITY, CAUSE_RANGE,
                               CAUSE_SPEED_MISSING, CAUSE_STEER_MISSING, CAUSE_YAW_MISSING, MEAS_NONE, MSG_CMD,
                               MSG_REDUNDANT, MSG_SPEED, MSG_STATUS, MSG_STEER, MSG_SYNC, MSG_YAW, SIG_CMD_ANGLE,
                               SIG_CMD_MEAS, SIG_CMD_STATE, SIG_LAT_ACCEL, SIG_SPEED, SIG_STATUS_CAUSE,
                               SIG_STATUS_FLAGS, SIG_STATUS_LATENESS, SIG_STATUS_OVERRUNS, SIG_STATUS_PLAUS,
                               SIG_STATUS_REJECTED, SIG_STATUS_STATE, SIG_SPEED_2, SIG_STEER_ANGLE, SIG_STEER_ANGLE_2,
                               SIG_YAW_RATE, SIG_YAW_RATE_2)

SYNC_STALE_CYCLES = 3  # MRS_SecOCSync cycle times without a valid sync before CAUSE_AUTH
# The longest the start state lasts, from the first cycle (what ends it for a bus silent from
# power-up); ``hil run`` starts the plant after the controller, seconds later on a loaded machine.
START_TIMEOUT_S = 10.0
DEFAULT_RATE_HZ = 1.0 / mr.ControllerConfig().ts  # the rate the shipped calibration was tuned for
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
    duration: float | None = None  # s of wall time; None runs until a signal
    # Wall time per period over the period (a slow machine's bench): the law's step and every
    # count in cycles stay those of ``rate_hz``; only the loop's clock is stretched.
    slow_motion: float = 1.0
    secoc_key: bytes | None = None  # sign the commands, verify the sensor frames (mrsteer_dbc.secoc) when given
    controller: mr.ControllerConfig = field(default_factory=mr.ControllerConfig)



class ControllerNode:
    """One controller on one bus.  ``cycle()`` is the periodic body; ``run()`` the loop."""

    def __init__(self, bus: can.BusABC, config: RuntimeConfig, contract: mrsteer_dbc.Contract | None = None) -> None:
        self.bus = bus
        self.cfg = config
        self.contract = contract or mrsteer_dbc.load()
        period = 1.0 / config.rate_hz
        self.period = period
        self.wall_period = period * config.slow_motion
        c = self.contract
        # The firmware's input ranges are the DBC's: one source of truth for what is valid.
        ctrl = replace(config.controller, ts=period,
                       driver_angle_max=c.signal_range(MSG_STEER, SIG_STEER_ANGLE)[1],
                       yaw_rate_max=c.signal_range(MSG_YAW, SIG_YAW_RATE)[1],
                       speed_max=c.signal_range(MSG_SPEED, SIG_SPEED)[1],
                       aux_limit=min(config.controller.aux_limit, c.signal_range(MSG_CMD, SIG_CMD_ANGLE)[1]))
        self.cycle_coeffs = cy.configure(ctrl, pl.PlausibilityConfig(ts=period),
                                         au.AuthorityConfig(ts=period, u_max=ctrl.aux_limit))
        self.cycle_state = cy.CycleState()
        self._cycle_in = cy.CycleInputs()
        self._init_inputs()
        keyed = config.secoc_key is not None
        self.signer = secoc.CommandSigner(c, config.secoc_key) if keyed else None
        self.sensor_verifier = secoc.SensorVerifier(c, config.secoc_key) if keyed else None
        self.sync_id = c.frame_id(MSG_SYNC) if keyed else None
        self.sync_limit = self._limit(MSG_SYNC, SYNC_STALE_CYCLES)
        self.start_limit = max(1, int(math.ceil(START_TIMEOUT_S / period - 1e-9)))  # cycles
        self.starting = True  # the start state (``_still_starting``)
        self._since_first = -1  # cycles since the one that drained the first sensor frame; -1: none yet
        self._sync_age = self.sync_limit + 1
        verifiers: dict[str, secoc.FrameVerifier] = {}
        if self.signer is not None and self.sensor_verifier is not None:
            verifiers = {MSG_SYNC: self.signer, **dict.fromkeys(self._by_name, self.sensor_verifier)}
        self.rx = RxLink(c, [*self._by_name, *([MSG_SYNC] if keyed else [])], verifiers, config.max_counter_delta)
        bus.set_filters(self.rx.filters())
        self.tx = TxLink(c, (MSG_CMD, MSG_STATUS), self.signer)
        self._init_status()
        self.stats = LoopStats()
        self.cause = 0
        self._max_lateness = 0.0
        self._running = True
        self._was_fault = False
        self._answers = MEAS_NONE
        self._yaw_stamp = 0.0  # bus timestamp (epoch s) of the newest accepted yaw-rate frame
        # The driver's angle when the newest redundant frame arrived (the plant sends it first in
        # the same step), and whether the monitor has yet to step over that redundant sample.
        self._steer_at_redundant = math.nan
        self._redundant_unstepped = False

    def _limit(self, name: str, cycles: int | None = None) -> int:
        """``cycles`` (the configured timeout's by default) of the message's own cycle time, in
        controller periods (rounded up; the 1e-9 keeps 3 * 0.1 / 1e-3 = 300.00000000000006 at 300)."""
        cycles = self.cfg.timeout_cycles if cycles is None else cycles
        cycle = self.contract.cycle_time_s(name, self.period) or self.period
        return max(1, int(math.ceil(cycles * cycle / self.period - 1e-9)))

    def _init_inputs(self) -> None:
        """The four sensor frames' inputs, their timeouts, and the monitor's sample clock."""
        c, period = self.contract, self.period
        self.inputs = {  # by frame ID
            c.frame_id(MSG_STEER): Input(MSG_STEER, SIG_STEER_ANGLE, CAUSE_STEER_MISSING, self._limit(MSG_STEER)),
            c.frame_id(MSG_YAW): Input(MSG_YAW, SIG_YAW_RATE, CAUSE_YAW_MISSING, self._limit(MSG_YAW),
                                       (SIG_YAW_RATE_2,)),
            c.frame_id(MSG_SPEED): Input(MSG_SPEED, SIG_SPEED, CAUSE_SPEED_MISSING, self._limit(MSG_SPEED)),
            # Missing, it is no cause: the monitor reports DEGRADED and the authority limit tightens.
            c.frame_id(MSG_REDUNDANT): Input(MSG_REDUNDANT, SIG_LAT_ACCEL, 0, self._limit(MSG_REDUNDANT),
                                             (SIG_STEER_ANGLE_2, SIG_SPEED_2)),
        }
        self._by_name = {inp.name: inp for inp in self.inputs.values()}
        self._steer, self._yaw, self._speed, self._redundant = self.inputs.values()
        self.redundant_id = c.frame_id(MSG_REDUNDANT)
        # The monitor's clock: yaw-rate samples (one per period by MRS_ControlLoop) per redundant one.
        self.clock = SampleClock((c.cycle_time_s(MSG_REDUNDANT, period) or period) / period, self._yaw.limit)
        self.yaw_id = c.frame_id(MSG_YAW)

    def _init_status(self) -> None:
        """The status frame's rate and its counters' ranges (the DBC's)."""
        c = self.contract
        status_cycle = c.cycle_time_s(MSG_STATUS) or 0.1
        # The status's counters wrap at their DBC widths; its lateness saturates at the DBC maximum.
        self._rejected_wrap = int(c.signal_range(MSG_STATUS, SIG_STATUS_REJECTED)[1]) + 1
        self._overruns_wrap = int(c.signal_range(MSG_STATUS, SIG_STATUS_OVERRUNS)[1]) + 1
        self._lateness_max = c.signal_range(MSG_STATUS, SIG_STATUS_LATENESS)[1]
        self.status_every = max(1, int(round(status_cycle / self.period)))

    # The cycle's pieces and what it leaves, by the names the node's readers use.
    @property
    def coeffs(self) -> mr.Coefficients:
        return self.cycle_coeffs.law

    @property
    def monitor_coeffs(self) -> pl.MonitorCoefficients:
        return self.cycle_coeffs.monitor

    @property
    def authority_coeffs(self) -> au.AuthorityCoefficients:
        return self.cycle_coeffs.authority

    @property
    def state(self) -> mr.State:
        return self.cycle_state.law

    @property
    def monitor(self) -> pl.MonitorState:
        return self.cycle_state.monitor

    @property
    def authority(self) -> au.AuthorityState:
        return self.cycle_state.authority

    @property
    def command(self) -> float:
        """The angle sent last: what acts on the car during the next period."""
        return self.cycle_state.command

    @property
    def plausibility(self) -> int:
        """The monitor's CtrlStatus_Plausibility bits."""
        return self.cycle_state.plausibility

    @property
    def reported_state(self) -> int:
        """``model_regulator.reported_state``, sent last."""
        return self.cycle_state.reported

    # ---------------------------------------------------------------- receive

    def input(self, name: str) -> Input:
        """The receive state of sensor message ``name`` (``MSG_STEER``, ``MSG_YAW``, ``MSG_SPEED``,
        ``MSG_REDUNDANT``)."""
        return self._by_name[name]

    def receive(self, msg: can.Message) -> bool:
        """Check one frame through the link and store it; True if it was an accepted yaw-rate frame."""
        self.stats.rx_frames += 1
        got = self.rx.accept(msg)
        frame_id = msg.arbitration_id
        if type(got) is Rejected:  # not isinstance: an Enum class check costs 4 times as much
            if got is Rejected.IGNORED:
                self.stats.rx_ignored += 1
            elif frame_id == self.sync_id:
                self.stats.syncs_rejected += 1
            else:
                self.stats.rx_rejected += 1
                if got is Rejected.MAC:
                    if self.signer is not None and self.signer.epoch is None:
                        self.stats.rx_unsynced += 1
                    else:
                        self.stats.rx_auth_failed += 1
                inp = self.inputs[frame_id]
                inp.rejects += 1
                inp.bad_cause = got.cause
            return False
        if frame_id == self.sync_id:
            assert self.signer is not None and self.signer.epoch is not None and self.sensor_verifier is not None
            self._sync_age = 0
            self.sensor_verifier.adopt(self.signer.epoch)
            return False
        inp = self.inputs[frame_id]
        inp.rejects = 0
        inp.value = got.signals[inp.signal]
        for i, name in enumerate(inp.extra_signals):
            inp.extra[i] = got.signals[name]
        if frame_id == self.redundant_id:
            self.clock.redundant_frame(got.counter)
            # a timed-out angle is no pair for it
            self._steer_at_redundant = self._steer.value if self._steer.valid(self.cfg.e2e_fail_max) else math.nan
            self._redundant_unstepped = True
        inp.last_counter = got.counter
        inp.age = 0
        inp.seen = True
        if frame_id == self.yaw_id:
            self._yaw_stamp = msg.timestamp or 0.0
            self.clock.yaw_frame(got.counter)
            return True
        return False

    def redundant_inputs(self) -> tuple[float, float, float]:
        """(lateral acceleration, second steering channel, second speed) for the monitor this
        cycle (the second speed NaN also when the sender has none: SNA): NaN when
        ``MRS_RedundantSensors`` is not fresh, or its sample arrived off its alive counter's
        time (``SampleClock.redundant_in_time``, kept for the sample's hold).  Pure."""
        red = self._redundant
        if self.clock.redundant_in_time and red.valid(self.cfg.e2e_fail_max):
            return red.value, red.extra[0], red.extra[1]
        return math.nan, math.nan, math.nan

    def monitor_driver_angle(self, delta_driver: float) -> float:
        """The driver's angle for the monitor's first step this cycle, given the valid newest one
        (NaN: invalid): the angle that came with a redundant sample the monitor has not stepped
        over yet (the plant sends the two in the same step), else ``delta_driver``.  Drained in a
        burst, the newest angle is several samples younger than the redundant sample, and the
        steering pair would read the driver's movement since as the channels' disagreement.  Pure."""
        if self._redundant_unstepped and not math.isnan(delta_driver) and not math.isnan(self._steer_at_redundant):
            return self._steer_at_redundant
        return delta_driver

    def monitor_steps(self) -> int:
        """How many yaw-rate samples the plausibility monitor steps over in this cycle: those
        since the last cycle by the accepted frames' alive counter, at most the yaw rate's
        timeout (a longer gap times the input out); 1 with the yaw rate invalid (the monitor's
        pause), else 0 without a new frame.  Pure, like ``redundant_inputs``."""
        if self.clock.samples:
            return self.clock.samples
        return 0 if self._yaw.valid(self.cfg.e2e_fail_max) else 1

    def drain(self) -> bool:
        got_yaw = False
        recv = self.bus.recv
        while True:
            msg = recv(0.0)
            if msg is None:
                return got_yaw
            got_yaw = self.receive(msg) or got_yaw

    # ---------------------------------------------------------------- control

    def _still_starting(self) -> bool:
        """Whether this cycle is still in the start state: some sensor input has not been
        accepted once yet, and none of those is overdue.  One is overdue once it has been missing
        for longer than its own timeout counted from the cycle that drained the first sensor frame
        (as if it had come with that one), and every one is after ``start_limit`` cycles.  Called
        once per cycle while starting (it counts the cycles since the first frame)."""
        if self.stats.cycles >= self.start_limit:
            return False
        first = self._since_first >= 0 or any(inp.seen for inp in self.inputs.values())
        if first:
            self._since_first += 1
        pending = False
        for inp in self.inputs.values():
            if not inp.seen:
                if first and self._since_first > inp.limit:
                    return False
                pending = True
        return pending

    def control(self) -> None:
        """Steps 2-5 of the cycle, after the receive queue has been drained."""
        if self.starting:
            self.starting = self._still_starting()
        lat, steer_2, speed_2 = self.redundant_inputs()  # before the ages move on
        steps = self.monitor_steps()
        self._redundant.age += 1
        self.clock.tick()
        values: list[float] = []
        cause = self._primary_values(values)
        # Which measurement this command answers; NONE when no valid yaw rate went into it.
        self._answers = MEAS_NONE if math.isnan(values[1]) else self._yaw.last_counter
        i = self._cycle_in
        i.delta_driver, i.yaw_rate, i.speed = values
        i.lat_accel, i.delta_driver_redundant, i.speed_redundant = lat, steer_2, speed_2
        i.yaw_rate_redundant = math.nan if math.isnan(values[1]) else self._yaw.extra[0]  # NaN: SNA, no element
        i.monitor_steps = steps
        i.monitor_driver = self.monitor_driver_angle(values[0])  # the first step's: a new redundant sample's
        i.starting = self.starting
        if steps:
            self._redundant_unstepped = False
        u = cy.step(self.cycle_coeffs, self.cycle_state, i)
        cause = self._cycle_cause(cause)
        state = self.reported_state
        fault = state == mr.STATUS_FAULT
        if fault and not self._was_fault:
            self.stats.faults_entered += 1
        self._was_fault = fault
        self.cause = cause
        self._send_command(u, state)
        self.stats.cycles += 1
        if self.stats.cycles % self.status_every == 0:
            self._send_status()

    def _primary_values(self, values: list[float]) -> int:
        """The driver's angle, the yaw rate and the speed appended to ``values`` (NaN where stale or
        rejected too often), each one period older after; returns the causes of those missing."""
        cause = 0
        fail_max = self.cfg.e2e_fail_max
        for inp in (self._steer, self._yaw, self._speed):
            ok = inp.age <= inp.limit and inp.rejects < fail_max
            if not ok:
                cause |= inp.missing_cause if inp.rejects < fail_max else inp.bad_cause
            values.append(inp.value if ok else math.nan)
            inp.age += 1
        return cause

    def _cycle_cause(self, cause: int) -> int:
        """``cause`` with what the cycle found: the law's range fault or low speed (when no input
        is to blame), a stale SecOC sync, a plausibility fault."""
        law = self.cycle_state.law
        if law.fault_flags and not cause:
            cause |= CAUSE_RANGE
        if law.status == mr.STATUS_INACTIVE and not cause:
            cause |= CAUSE_LOW_SPEED
        if self.signer is not None:
            self._sync_age += 1
            if self._sync_age > self.sync_limit or not self.signer.synced:
                cause |= CAUSE_AUTH
        if self.plausibility & pl.PLAUS_FAULT:
            cause |= CAUSE_PLAUSIBILITY
        return cause

    def _send_command(self, u: float, state: int) -> None:
        if self.signer is not None and (not self.signer.synced or self._sync_age > self.sync_limit):
            # No freshness, or none fresh (no valid sync for SYNC_STALE_CYCLES: the actuator has
            # moved on, or restarted and will issue a new epoch): the actuator would reject the
            # command, and a rejected command is an alarm there. AUTOSAR SecOC sends no PDU
            # without freshness; the actuator's own timeout holds it at zero meanwhile.
            self.stats.cmd_withheld += 1
            return
        self.bus.send(self.tx.frame(MSG_CMD, {SIG_CMD_STATE: state, SIG_CMD_ANGLE: u, SIG_CMD_MEAS: self._answers}))
        self.stats.tx_frames += 1

    def _send_status(self) -> None:
        self.bus.send(self.tx.frame(MSG_STATUS, {
            SIG_STATUS_STATE: self.reported_state,
            SIG_STATUS_FLAGS: self.state.fault_flags,
            SIG_STATUS_PLAUS: self.plausibility,
            SIG_STATUS_CAUSE: self.cause,
            SIG_STATUS_REJECTED: self.stats.rx_rejected % self._rejected_wrap,
            SIG_STATUS_OVERRUNS: self.stats.overruns % self._overruns_wrap,
            SIG_STATUS_LATENESS: min(self._max_lateness, self._lateness_max),
        }))
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
        self.stats.rss_kb_loop_start = rss_kb()
        try:
            if self.cfg.trigger == "sensors":
                self._run_on_sensors(end)
            else:
                self._run_on_clock(end)
        finally:
            self.stats.rss_kb_loop_end = rss_kb()
            gc.enable()
            gc.unfreeze()
        self.finish()

    def _run_on_clock(self, end: float | None) -> None:
        period = self.wall_period
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
                        got_yaw = self.receive(msg)
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
        wait = max(self._yaw.limit * self.wall_period, SENSORS_WATCHDOG_S)
        while self._running:
            got = False
            msg = self._recv_unless_stopped(wait)
            if not self._running:
                break  # stopped while waiting: no cycle on a frame or a watchdog that ended the run
            if msg is not None:
                got = self.receive(msg)
            got = self.drain() or got
            if got or msg is None:
                self.control()
            if end is not None and time.monotonic() >= end:
                break

    def _recv_unless_stopped(self, wait: float) -> can.Message | None:
        """The next frame within ``wait`` s, or None after ``wait`` s without one or once
        ``stop()`` was called: waited in slices of ``STOP_POLL_S``, because a signal does not
        interrupt a blocking receive (the call is retried with the time that was left)."""
        until = time.monotonic() + wait
        while self._running:
            left = until - time.monotonic()
            if left <= 0.0:
                return None
            msg = self.bus.recv(min(left, STOP_POLL_S))
            if msg is not None:
                return msg
        return None

    def finish(self) -> None:
        """Final zero command marked inactive, as on an orderly shutdown."""
        try:
            self._send_command(0.0, mr.STATUS_INACTIVE)
        except can.CanError:
            pass  # the bus is already gone: nothing more can be said on it
