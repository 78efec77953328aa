"""The controller process's cycle, driven by hand on python-can's in-process virtual bus."""

from __future__ import annotations

import math

import can
import pytest

import mrsteer_dbc
from mrsteer_dbc import names
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from firmware_py.controller import node as rt
from firmware_py.controller import timing

C = mrsteer_dbc.load()
#: RedundantSensors_LatAccel's LSB: a toggle of it makes a new redundant sample the monitor can tell
LAT_LSB = C.message(names.MSG_REDUNDANT).get_signal_by_name(names.SIG_LAT_ACCEL).scale
FADE = mr.ControllerConfig().fade_rate * 1e-3
#: ``Rig.cycle``'s default redundant frame: the car's a_y = v r and the driver's angle, as the plant sends them
CONSISTENT = (math.nan, math.nan)


class Rig:
    """A controller node plus a sensor node and a listener on one virtual channel."""

    def __init__(self, channel: str) -> None:
        self.ctl_bus = can.Bus(interface="virtual", channel=channel)
        self.sensors = can.Bus(interface="virtual", channel=channel)
        self.node = rt.ControllerNode(self.ctl_bus, rt.RuntimeConfig(rate_hz=1000.0))
        self.counters = {n: mrsteer_dbc.AliveCounter() for n in names.VEHICLE_SENSORS}
        self.k = 0
        self.statuses: list[dict] = []
        self.last = {"yaw": 0.0, "steer": 0.0, "speed": 20.0}  # the newest values sent

    def send(self, name: str, values: dict, *, counter: int | None = None, corrupt: bool = False,
             strict: bool = True) -> None:
        data = bytearray(C.encode(name, values, self.counters[name].next() if counter is None else counter,
                                  strict=strict))
        if corrupt:
            data[-1] ^= 0x40
        self.sensors.send(can.Message(arbitration_id=C.frame_id(name), data=bytes(data), is_extended_id=False))

    def cycle(self, yaw: float | None = 0.0, steer: float | None = 0.0, speed: float | None = 20.0,
              redundant: tuple[float, float] | None = CONSISTENT, speed_2: float | None = None,
              **kw) -> tuple[float, dict]:
        """One 1 ms cycle; ``redundant`` = (lateral acceleration, second steering channel), sent
        every 50 ms as the plant does (default ``CONSISTENT`` with the newest yaw rate, speed and
        angle; None: not sent), with the LSB toggling as a real sensor's noise does (the
        monitor takes an unchanged frame for no new sample), and ``speed_2`` in it (None: SNA)."""
        self.last.update({k: v for k, v in (("yaw", yaw), ("steer", steer), ("speed", speed)) if v is not None})
        if redundant is CONSISTENT:
            redundant = (self.last["speed"] * self.last["yaw"], self.last["steer"])
        if steer is not None:
            self.send(names.MSG_STEER, {"DriverSteer_Angle": steer})
        if speed is not None and self.k % 10 == 0:
            self.send(names.MSG_SPEED, {"VehicleSpeed_Speed": speed})
        if redundant is not None and self.k % 50 == 0:
            lsb = LAT_LSB * ((self.k // 50) % 2)
            values = {names.SIG_LAT_ACCEL: redundant[0] + lsb, names.SIG_STEER_ANGLE_2: redundant[1]}
            if speed_2 is not None:
                values[names.SIG_SPEED_2] = speed_2
            self.send(names.MSG_REDUNDANT, values)
        if yaw is not None:
            self.send(names.MSG_YAW, {"YawRate_YawRate": yaw}, **kw)
        self.k += 1
        self.node.drain()
        self.node.control()
        cmd = None
        while (m := self.sensors.recv(0.0)) is not None:
            if m.arbitration_id == C.frame_id(names.MSG_CMD):
                cmd = C.decode(m.arbitration_id, bytes(m.data))
            elif m.arbitration_id == C.frame_id(names.MSG_STATUS):
                status = C.decode(m.arbitration_id, bytes(m.data))
                assert status is not None
                self.statuses.append(status.signals)
        assert cmd is not None and cmd.status is mrsteer_dbc.E2EStatus.OK
        return cmd.signals["AuxSteerCmd_Angle"], cmd.signals

    def close(self) -> None:
        self.ctl_bus.shutdown()
        self.sensors.shutdown()


@pytest.fixture
def rig(channel: str):
    r = Rig(channel)
    yield r
    r.close()


def test_healthy_inputs_give_an_active_command_answering_the_yaw_frame(rig: Rig) -> None:
    for _ in range(20):
        u, sig = rig.cycle(yaw=0.02)
    assert sig["AuxSteerCmd_State"] == mr.STATUS_ACTIVE
    assert u < 0  # counter-steers a positive yaw rate
    assert sig["AuxSteerCmd_MeasCounter"] == rig.counters[names.MSG_YAW].value
    assert rig.node.cause == 0


def test_silenced_yaw_sensor_faults_fades_and_recovers_without_jump(rig: Rig) -> None:
    for _ in range(300):
        u, _ = rig.cycle(yaw=0.05)
    assert abs(u) > math.radians(1.0)
    states, outs = [], [u]
    for _ in range(700):  # the yaw-rate sensor goes quiet (a 3 deg command fades in 0.5 s)
        u, sig = rig.cycle(yaw=None)
        states.append(sig["AuxSteerCmd_State"])
        outs.append(u)
    limit = rig.node.input(names.MSG_YAW).limit
    assert limit == 10  # 10 of its own 1 ms cycles
    assert all(s == mr.STATUS_ACTIVE for s in states[:limit])
    assert all(s == mr.STATUS_FAULT for s in states[limit + 1:])
    assert rig.node.cause & names.CAUSE_YAW_MISSING
    assert outs[-1] == 0.0
    steps = [abs(b - a) for a, b in zip(outs[limit:], outs[limit + 1:])]
    assert max(steps) <= FADE + 2e-6  # bounded fade (plus the DBC's 1e-6 rad resolution)
    prev = outs[-1]
    for _ in range(600):  # back again
        u, sig = rig.cycle(yaw=0.05)
        assert abs(u - prev) <= FADE + 2e-6
        prev = u
    assert sig["AuxSteerCmd_State"] in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED) and rig.node.cause == 0


def test_corrupted_frames_are_rejected_and_fault_after_three(rig: Rig) -> None:
    for _ in range(20):
        rig.cycle(yaw=0.01)
    for i in range(3):
        _, sig = rig.cycle(yaw=0.01, corrupt=True)
    assert rig.node.stats.rx_rejected == 3
    assert sig["AuxSteerCmd_State"] == mr.STATUS_FAULT and rig.node.cause & names.CAUSE_E2E
    for _ in range(5):
        _, sig = rig.cycle(yaw=0.01)
    assert sig["AuxSteerCmd_State"] == mr.STATUS_ACTIVE


def test_repeated_counter_is_stale_and_rejected(rig: Rig) -> None:
    for _ in range(5):
        rig.cycle(yaw=0.01)
    stuck = rig.counters[names.MSG_YAW].value
    for _ in range(3):
        rig.cycle(yaw=0.3, counter=stuck)  # a frozen sender repeating itself
    assert rig.node.stats.rx_rejected == 3
    assert rig.node.input(names.MSG_YAW).value == pytest.approx(0.01)  # the stale value was never used


def test_out_of_range_value_is_rejected_with_range_cause(rig: Rig) -> None:
    for _ in range(5):
        rig.cycle(yaw=0.01)
    for _ in range(3):
        _, sig = rig.cycle(yaw=3.2, strict=False)
    assert rig.node.stats.rx_rejected == 3 and rig.node.cause & names.CAUSE_RANGE
    assert sig["AuxSteerCmd_State"] == mr.STATUS_FAULT


def test_other_traffic_is_ignored(rig: Rig) -> None:
    for fid in (0x7FF, 0x123, C.frame_id(names.MSG_CMD)):
        rig.sensors.send(can.Message(arbitration_id=fid, data=b"\x00" * 8, is_extended_id=False))
    _, sig = rig.cycle(yaw=0.0)
    assert rig.node.stats.rx_rejected == 0


def test_status_message_reports_state_cause_and_counts(rig: Rig) -> None:
    statuses: list[dict] = []
    for i in range(250):
        rig.cycle(yaw=None if i > 120 else 0.0)
    for _ in range(100):  # one more status period, catching its frame
        rig.send(names.MSG_STEER, {"DriverSteer_Angle": 0.0})
        rig.node.drain()
        rig.node.control()
        while (m := rig.sensors.recv(0.0)) is not None:
            if m.arbitration_id == C.frame_id(names.MSG_STATUS):
                statuses.append(C.decode(m.arbitration_id, bytes(m.data)).signals)
    assert statuses, "a status frame every 100 ms"
    s = statuses[-1]
    assert s["CtrlStatus_State"] == mr.STATUS_FAULT
    assert int(s["CtrlStatus_Cause"]) & names.CAUSE_YAW_MISSING


def test_final_command_is_zero_and_inactive(rig: Rig) -> None:
    for _ in range(50):
        rig.cycle(yaw=0.05)
    rig.node.finish()
    m = rig.sensors.recv(1.0)
    d = C.decode(m.arbitration_id, bytes(m.data))
    assert d.name == names.MSG_CMD and d.signals["AuxSteerCmd_Angle"] == 0.0
    assert d.signals["AuxSteerCmd_State"] == mr.STATUS_INACTIVE


def test_lateness_histogram_percentiles_and_constant_memory() -> None:
    import numpy as np

    rng = np.random.default_rng(7)
    values = np.concatenate([rng.exponential(80e-6, 20_000), [0.0, -1e-6, 0.2]])  # negative: early; 0.2: overflow
    h = timing.LatenessHistogram()
    size = len(h.counts)
    for v in values:
        h.add(float(v))
    assert len(h.counts) == size and h.n == len(values)
    assert h.max == 0.2 and h.percentile(1.0) == 0.2
    for q in (0.5, 0.9, 0.99):
        exact = float(np.sort(np.maximum(values, 0.0))[int(np.ceil(q * len(values))) - 1])
        assert exact <= h.percentile(q) <= exact + h.BIN_S


def test_phase_lock_moves_cycle_starts_toward_the_frame_arrival_and_converges() -> None:
    period, offset = 2e-3, 150e-6
    # Frames arrive 0.3 ms into each period; a loop starting at 0.9 ms moves earlier, by at most
    # the slew limit per cycle; one starting at 1.7 ms is nearer the next frame and moves later.
    assert timing.phase_correction(0.3e-3, 0.9e-3, period, offset) == pytest.approx(-timing.SYNC_MAX_SLEW * period)
    assert timing.phase_correction(0.3e-3, 1.7e-3, period, offset) == pytest.approx(timing.SYNC_MAX_SLEW * period)
    for start in (0.9e-3, 1.7e-3):
        for k in range(400):
            start += timing.phase_correction(0.3e-3 + k * period, start + k * period, period, offset)
        assert math.remainder(start - (0.3e-3 + offset), period) == pytest.approx(0.0, abs=1e-7)
    # The error wraps: a frame 0.1 ms *after* the cycle start of the previous period is close.
    assert timing.phase_correction(1.95e-3, 0.0, period, 0.0) == pytest.approx(timing.SYNC_GAIN * -0.05e-3)


def test_the_sensors_trigger_keeps_its_watchdog_and_stops_promptly(channel: str) -> None:
    """Lockstep end of run: with no yaw-rate frame the sensors-triggered loop still runs its
    watchdog cycle, not before SENSORS_WATCHDOG_S, and a stop while it waits for frames ends it
    at once: nothing sent after the stop but the final zero command (a loop that finished its
    wait first would send the next watchdog cycle's command before it).  No upper time bound:
    a loaded machine delays every wake-up."""
    import threading
    import time

    with can.Bus(interface="virtual", channel=channel) as ctl, can.Bus(interface="virtual", channel=channel) as ear:
        node = rt.ControllerNode(ctl, rt.RuntimeConfig(rate_hz=500.0, trigger="sensors"))
        start = time.monotonic()
        loop = threading.Thread(target=node.run)
        loop.start()
        try:
            first = ear.recv(30.0)  # the watchdog cycle's command
            waited = time.monotonic() - start
            assert first is not None and first.arbitration_id == C.frame_id(names.MSG_CMD)
            assert waited >= timing.SENSORS_WATCHDOG_S - 0.05
            time.sleep(0.3)  # inside the next watchdog wait (on a quiet machine)
            stopped = time.time()  # the virtual bus stamps frames with time.time()
            node.stop()
            loop.join(30.0)
            assert not loop.is_alive()
        finally:
            node.stop()
        after = [m for m in iter(lambda: ear.recv(0.05), None) if m.timestamp >= stopped]
    assert len(after) == 1
    d = C.decode(after[0].arbitration_id, bytes(after[0].data))
    assert d.name == names.MSG_CMD and d.signals["AuxSteerCmd_Angle"] == 0.0
    assert d.signals["AuxSteerCmd_State"] == mr.STATUS_INACTIVE


# ------------------------------------------------------------ plausibility and bounded authority

AUTH_FADE = math.radians(30.0) * 1e-3  # firmware_py.authority's fade on a plausibility fault, per 1 ms period
RESOLUTION = 2e-6  # the DBC's 1e-6 rad, twice


def test_consistent_inputs_with_the_redundant_frame_raise_no_plausibility_bit(rig: Rig) -> None:
    for _ in range(1000):
        u, sig = rig.cycle(yaw=0.05, redundant=(0.05 * 20.0, 0.0))
        assert sig["AuxSteerCmd_State"] != mr.STATUS_FAULT
    assert abs(u) > math.radians(0.5)
    assert rig.node.plausibility == 0 and rig.node.cause == 0
    assert rig.statuses and all(s[names.SIG_STATUS_PLAUS] == 0 for s in rig.statuses)


def test_without_the_redundant_frame_the_node_reports_degraded_but_no_fault(rig: Rig) -> None:
    # The start state waits for the redundant frame its own timeout (10 x 50 ms) from the first
    # sensor frame; then the node says what it is: DEGRADED, on the wire, every cycle.
    limit = rig.node.input(names.MSG_REDUNDANT).limit
    assert limit == 500
    states = [rig.cycle(yaw=0.02, redundant=None)[1]["AuxSteerCmd_State"] for _ in range(limit + 300)]
    assert states == [mr.STATUS_STARTING] * (limit + 1) + [mr.STATUS_DEGRADED] * 299
    assert rig.statuses[-1][names.SIG_STATUS_PLAUS] == names.PLAUS_DEGRADED
    assert rig.statuses[-1][names.SIG_STATUS_STATE] == mr.STATUS_DEGRADED
    assert rig.node.cause == 0  # a missing redundant input is no reason to stop
    assert rig.node.stats.faults_entered == 0


def test_a_clean_start_is_starting_until_every_input_came_never_fault_or_degraded(rig: Rig) -> None:
    # Five cycles before any frame (a controller up before the car), then the sensors one by one:
    # driver's angle and yaw rate every period, the speed from 30 periods on, the redundant
    # frame at 45: STARTING until it came, then ACTIVE; never FAULT or DEGRADED.
    node = rig.node

    def states() -> list[int]:
        return [d.signals["AuxSteerCmd_State"] for m in iter(lambda: rig.sensors.recv(0.0), None)
                if (d := C.decode(m.arbitration_id, bytes(m.data))) is not None and d.name == names.MSG_CMD]

    seen = []
    for k in range(-5, 80):
        if k >= 0:
            rig.send(names.MSG_STEER, {names.SIG_STEER_ANGLE: 0.0})
            if k >= 30 and k % 10 == 0:
                rig.send(names.MSG_SPEED, {names.SIG_SPEED: 20.0})
            if k == 45:
                rig.send(names.MSG_REDUNDANT, {names.SIG_LAT_ACCEL: 0.4, names.SIG_STEER_ANGLE_2: 0.0})
            rig.send(names.MSG_YAW, {names.SIG_YAW_RATE: 0.02})
        node.drain()
        node.control()
        seen += states()
        if k == -1:
            assert node.cause == 0x07  # every input missing, and the cause says so
    assert seen == [mr.STATUS_STARTING] * 50 + [mr.STATUS_ACTIVE] * 35
    assert node.cause == 0 and not node.starting and node.stats.faults_entered == 0


def test_an_input_that_never_comes_is_reported_after_its_timeout_from_the_first_frame(rig: Rig) -> None:
    limit = rig.node.input(names.MSG_SPEED).limit
    assert limit == 200  # 10 of its 20 ms cycles
    states, causes = [], []
    for _ in range(limit + 50):
        _, sig = rig.cycle(yaw=0.02, speed=None, redundant=(0.4, 0.0))
        states.append(sig["AuxSteerCmd_State"])
        causes.append(rig.node.cause)
    assert states == [mr.STATUS_STARTING] * (limit + 1) + [mr.STATUS_FAULT] * 49
    assert all(c == names.CAUSE_SPEED_MISSING for c in causes)  # said from the first cycle on
    assert rig.node.stats.faults_entered == 1


def test_a_silent_bus_is_reported_after_the_start_timeout(rig: Rig) -> None:
    node = rig.node
    assert node.start_limit == round(rt.START_TIMEOUT_S * 1000.0)
    for _ in range(node.start_limit):
        node.control()
        assert node.reported_state == mr.STATUS_STARTING
    node.control()
    assert node.reported_state == mr.STATUS_FAULT and node.cause == 0x07 and node.stats.faults_entered == 1


def test_the_reported_state_puts_a_plausibility_fault_first_then_the_start() -> None:
    F, D = names.PLAUS_YAW, names.PLAUS_DEGRADED
    for law in (mr.STATUS_INACTIVE, mr.STATUS_ACTIVE, mr.STATUS_SATURATED, mr.STATUS_FAULT):
        assert mr.reported_state(law, F | D, True) == mr.STATUS_FAULT
        assert mr.reported_state(law, names.PLAUS_STEER, False) == mr.STATUS_FAULT
        assert mr.reported_state(law, D, True) == mr.STATUS_STARTING
        assert mr.reported_state(law, 0, True) == mr.STATUS_STARTING
        assert mr.reported_state(law, D, False) == (mr.STATUS_FAULT if law == mr.STATUS_FAULT else mr.STATUS_DEGRADED)
        assert mr.reported_state(law, 0, False) == law


def test_yaw_rate_that_disagrees_with_lateral_acceleration_faults_fades_and_latches(rig: Rig) -> None:
    for _ in range(300):  # a consistent intervention first
        u, _ = rig.cycle(yaw=0.05, redundant=(1.0, 0.0))
    assert abs(u) > math.radians(0.5) and rig.node.plausibility == 0
    outs, states, k_fault = [u], [], None
    for k in range(1500):  # the yaw-rate sensor sticks at 0.05 while the car yaws at 0.25 rad/s
        u, sig = rig.cycle(yaw=0.05, redundant=(0.25 * 20.0, 0.0))
        outs.append(u)
        states.append(sig["AuxSteerCmd_State"])
        if k_fault is None and sig["AuxSteerCmd_State"] == mr.STATUS_FAULT:
            k_fault = k
    assert k_fault is not None and k_fault <= 300  # reported within 300 ms
    assert all(s == mr.STATUS_FAULT for s in states[k_fault:])
    assert rig.node.cause & names.CAUSE_PLAUSIBILITY
    assert rig.statuses[-1][names.SIG_STATUS_PLAUS] & names.PLAUS_YAW
    assert rig.statuses[-1][names.SIG_STATUS_CAUSE] & names.CAUSE_PLAUSIBILITY
    steps = [abs(b - a) for a, b in zip(outs[k_fault:], outs[k_fault + 1:])]
    assert max(steps) <= AUTH_FADE + RESOLUTION
    u_at = abs(outs[k_fault])
    assert outs[k_fault + math.ceil(u_at / AUTH_FADE) + 2] == 0.0  # back at zero within the fade time
    for _ in range(300):  # consistent again: the fault stays latched until the next start
        u, sig = rig.cycle(yaw=0.05, redundant=(1.0, 0.0))
    assert u == 0.0 and sig["AuxSteerCmd_State"] == mr.STATUS_FAULT


def test_steering_channels_that_disagree_fault_with_the_steering_bit(rig: Rig) -> None:
    for k in range(400):
        _, sig = rig.cycle(yaw=0.0, steer=0.02, redundant=(0.0, 0.0))
        if sig["AuxSteerCmd_State"] == mr.STATUS_FAULT:
            break
    assert k <= 300 and rig.node.plausibility & names.PLAUS_STEER
    assert not rig.node.plausibility & names.PLAUS_YAW


def test_a_second_speed_that_disagrees_faults_with_the_yaw_bit_and_cuts_the_command(rig: Rig) -> None:
    # 20 m/s against a second speed of 17.4: 2.6 m/s apart, over the pair's 1.0 + 5 % of 17.4
    # (1.87 m/s); the node must pass RedundantSensors_Speed2 to the monitor.
    for _ in range(300):
        _, sig = rig.cycle(yaw=0.0, redundant=(0.0, 0.0), speed_2=20.1)
    assert rig.node.plausibility == 0 and sig["AuxSteerCmd_State"] != mr.STATUS_FAULT
    assert rig.node.redundant_inputs()[2] == pytest.approx(20.1)
    for k in range(300):
        _, sig = rig.cycle(yaw=0.0, redundant=(0.0, 0.0), speed_2=17.4)
        if sig["AuxSteerCmd_State"] == mr.STATUS_FAULT:
            break
    # the first frame at 17.4 goes out in the loop's first cycle (the rig sends every 50th), and
    # the pair trips on its speed_pair_time / period = 100th sample over the bound
    assert k == round(pl.PlausibilityConfig().speed_pair_time / rig.node.period) - 1
    assert rig.node.monitor.flags & pl.CHECK_SPEED_PAIR and rig.node.plausibility & names.PLAUS_YAW


def test_a_redundant_sample_off_its_alive_counters_time_is_withheld_from_the_monitor(rig: Rig) -> None:
    # The monitor differentiates over the periods between samples and pairs each with the yaw
    # rate of its cycle: a sample that a stall delivered late (its counter says 50 ms, the node
    # counted 70) would read as a side slip, so it is withheld (NaN: DEGRADED) for its hold.
    for _ in range(300):
        rig.cycle(yaw=0.0, redundant=(0.0, 0.0))
    assert not math.isnan(rig.node.redundant_inputs()[0]) and rig.node.plausibility == 0
    rig.k -= 30  # the next redundant frame comes 30 periods late (its counter one on)
    seen = []
    for _ in range(140):
        rig.cycle(yaw=0.0, redundant=(0.0, 0.0))
        seen.append(math.isnan(rig.node.redundant_inputs()[0]))
    assert not any(seen[:30])  # the last sample in time, still held
    assert all(seen[30:80])  # the late one (80 periods after it), for its whole hold
    assert not any(seen[80:])  # the next, 50 periods on: in time again
    assert rig.node.plausibility == 0 and rig.node.cause == 0  # DEGRADED came and went, no fault


def test_the_monitor_steps_on_the_yaw_rate_samples_not_on_the_cycles(rig: Rig) -> None:
    # A sender two periods per step (a plant behind real time) that also loses a frame now and
    # then: the monitor must step once per yaw-rate sample by the frames' alive counter (a lost
    # sample at the next one's values), as a monitor fed the samples alone does, and hold its
    # verdict between them; stepped every cycle its lag filter and windows would run twice as
    # fast as the car, stepped once per frame they would skip the lost samples.
    from firmware_py import plausibility as pl

    node = rig.node
    ref_c, ref_s = pl.configure(pl.PlausibilityConfig(ts=node.period)), pl.MonitorState()
    lost = 0
    for j in range(600):
        if j % 7 == 3:  # this sample's frames are lost: its yaw-rate counter value is skipped
            rig.counters[names.MSG_YAW].next()
            node.drain()
            assert node.monitor_steps() == 0
            lost += 1
        else:
            t = j * node.period  # the sender's time: one period per sample
            yaw = 0.05 * math.sin(2 * math.pi * t)
            steer = 0.01 * math.sin(2 * math.pi * t)
            rig.send(names.MSG_STEER, {"DriverSteer_Angle": steer})
            if j % 10 == 0:
                rig.send(names.MSG_SPEED, {"VehicleSpeed_Speed": 20.0})
            if j % 50 == 0:
                rig.send(names.MSG_REDUNDANT, {names.SIG_LAT_ACCEL: 20.0 * yaw + LAT_LSB * ((j // 50) % 2),
                                               names.SIG_STEER_ANGLE_2: steer})
            rig.send(names.MSG_YAW, {"YawRate_YawRate": yaw})
            node.drain()
            steps = 2 if j % 7 == 4 else 1
            assert node.monitor_steps() == steps
            d, r, v = (node.input(n).value for n in (names.MSG_STEER, names.MSG_YAW, names.MSG_SPEED))
            lat, d2, _ = node.redundant_inputs()
            for _ in range(steps):
                expected = pl.monitor_step(ref_c, ref_s, d, d2, r, lat, v, node.command)
        node.control()
        assert node.plausibility == expected
        held = (node.plausibility, node.monitor.r_model, node.monitor.kin_err)
        node.control()  # the period with no new sample
        assert node.monitor_steps() == 0 and (node.plausibility, node.monitor.r_model, node.monitor.kin_err) == held
        while rig.sensors.recv(0.0) is not None:
            pass
    assert lost > 50 and ref_s.kin_n == pl.KIN_WINDOW  # the kinematic check ran on full windows
    for slot in ("r_model", "kin_err", "model_err", "kin_raw", "kin_comp", "flags", "kin_count", "model_count"):
        assert getattr(node.monitor, slot) == getattr(ref_s, slot), slot
