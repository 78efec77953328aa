"""The C node's plausibility monitor and authority limiter (issue 18) against the Python
controller's.

In process, frame for frame: the same received frames into ``mrs_node_receive`` /
``mrs_node_control`` (through ``ports/c/build/secoc_check``) and into ``ControllerNode.receive``
/ ``control`` must give the same command and status frames, byte for byte, on a fault-free
drive, a yaw-rate sensor stuck at 0.01 rad/s (FAULT, ``CAUSE_PLAUSIBILITY``, fade to zero) and
a drive without ``MRS_RedundantSensors`` (DEGRADED: no cause bit, the command held to the
panic window).  No processes, no bus: one run is a fraction of a second.

On the car: a lockstep HIL run with the plant's yaw-rate sensor stuck (a scenario's
``[[sensor_fault]]``) gives the same commands from both nodes, and its log replays to them in
Python and in C (``mrsteer replay --impl both``); without its redundant frames the two replays
still agree with each other (the DEGRADED path)."""

from __future__ import annotations

import math
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import pytest

import mrsteer_dbc
from firmware_py import authority as au
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from firmware_py.controller import node as rt
from mrsteer_dbc import names
from conftest import lockstep_traffic
from sim_plant.harness import hil, launch, replay_c
from sim_plant.harness.replay import ReplaySettings, replay

ROOT = Path(__file__).resolve().parents[1]
RATE_HZ = 500.0
V = 20.0  # m/s
DISTURBANCE = 0.08  # rad/s of yaw rate the "car" adds from DIST_T on, so that the law acts
DIST_T = 0.3  # s
STUCK = 0.01  # rad/s: the stuck value of issue 18's first example
STUCK_T = 1.0  # s

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or shutil.which("make") is None,
                                reason="gcc and make are not installed (.ci/run installs them)")


@pytest.fixture(scope="module")
def secoc_check() -> Path:
    launch.controller_program("c")  # builds ports/c/build (the node and its test drivers)
    return ROOT / "ports" / "c" / "build" / "secoc_check"


class _Recorder:
    def __init__(self) -> None:
        self.sent: list[can.Message] = []

    def set_filters(self, filters: Any) -> None:
        self.filters = filters

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)


@dataclass(frozen=True)
class Drive:
    """A synthetic drive, open loop: the driver weaves gently, the car's yaw rate follows the
    nominal steady-state gain plus a disturbance, a_y = v r; sensors as named."""

    seconds: float = 1.6
    stuck_yaw: bool = False
    redundant: bool = True
    jitter: bool = False  # every 3rd redundant frame 10 periods late, the yaw frame of every 4th's period lost
    slow: int = 1  # the sender steps once every `slow` control periods (a plant behind real time)
    burst: int = 0  # every 2nd redundant frame comes in one drain with the frames of the `burst` periods before it
    burst_after: int = 0  # every 2nd redundant frame comes in one drain with the `burst_after` periods' after it
    weave: tuple[float, float] = (0.01, 0.5)  # the driver's angle: amplitude (rad) and frequency (Hz) of its sine
    steer_2_offset: float = 0.0  # rad the second steering channel reads above the first from steer_2_from
    steer_2_from: float = STUCK_T  # s
    second_yaw: bool = False  # the yaw-rate frames carry the sensor's second element (the car's r); else SNA
    second_yaw_lost: float = math.inf  # s from which the second element is SNA (the element failed)
    second_yaw_offset: float = 0.0  # rad/s the second element reads below the car's r
    second_speed: float = math.nan  # RedundantSensors_Speed2 (NaN: SNA, a car without it)
    second_speed_drift: float = 0.0  # m/s per s it drifts by from STUCK_T
    second_speed_lost: float = math.inf  # s from which it is SNA (the source failed)
    speed: bool = True  # the speed frames sent (else the sensor never comes)
    idle: int = 0  # control periods before the first frame (a node up before the car)

    def frames(self, contract: mrsteer_dbc.Contract) -> list[list[tuple[int, bytes]]]:
        """The frames received before each control period (the plant's order and cycle times)."""
        every = {m: max(1, round((contract.cycle_time_s(m, 1 / RATE_HZ) or 1 / RATE_HZ) * RATE_HZ))
                 for m in (names.MSG_STEER, names.MSG_SPEED, names.MSG_REDUNDANT, names.MSG_YAW)}
        gain = V / (2.54 + 0.0023 * V * V)  # close to the nominal car's K_n(v); the monitor's bounds are wide
        alive = dict.fromkeys(every, 0)
        late: dict[int, list[tuple[int, bytes]]] = {}
        out: list[list[tuple[int, bytes]]] = [[] for _ in range(self.idle)]
        for k in range(int(self.seconds * RATE_HZ)):
            t = k / RATE_HZ
            delta = self.weave[0] * math.sin(2 * math.pi * self.weave[1] * t)
            r = gain * delta + (DISTURBANCE if t >= DIST_T else 0.0)
            r_meas = STUCK if self.stuck_yaw and t >= STUCK_T else r
            values = {names.MSG_STEER: {names.SIG_STEER_ANGLE: delta}, names.MSG_SPEED: {names.SIG_SPEED: V},
                      names.MSG_REDUNDANT: {names.SIG_LAT_ACCEL: V * r, names.SIG_STEER_ANGLE_2: delta
                                            + (self.steer_2_offset if t >= self.steer_2_from else 0.0),
                                            names.SIG_SPEED_2: self.second_speed
                                            + self.second_speed_drift * max(0.0, t - STUCK_T)
                                            if t < self.second_speed_lost else math.nan},
                      names.MSG_YAW: {names.SIG_YAW_RATE: r_meas,
                                      names.SIG_YAW_RATE_2: r - self.second_yaw_offset
                                      if self.second_yaw and t < self.second_yaw_lost else math.nan}}
            period = []
            for msg, n in every.items():
                if k % n or (msg == names.MSG_REDUNDANT and not self.redundant) or (
                        msg == names.MSG_SPEED and not self.speed):
                    continue
                frame = (contract.frame_id(msg), contract.encode(msg, values[msg], alive[msg]))
                sample = k // every[names.MSG_REDUNDANT]
                alive[msg] = (alive[msg] + 1) % 15
                if self.jitter and msg == names.MSG_REDUNDANT and sample % 3 == 1:
                    late.setdefault(k + 10, []).append(frame)  # a stalled sender
                    continue
                if self.jitter and msg == names.MSG_YAW and k % every[names.MSG_REDUNDANT] == 0 and sample % 4 == 2:
                    continue  # this period's yaw-rate frame lost
                period.append(frame)
            out.append(late.pop(k, []) + period)
            out += [[] for _ in range(self.slow - 1)]  # the sender's step took this many periods more
        n = every[names.MSG_REDUNDANT]
        for k in range(n, len(out), 2 * n) if self.burst else ():  # a stall, then its frames at once
            stalled = [f for period in out[k - self.burst:k] for f in period]
            out[k - self.burst:k] = [[] for _ in range(self.burst)]
            out[k] = stalled + out[k]
        for k in range(n, len(out) - self.burst_after, 2 * n) if self.burst_after else ():  # the skew: a
            stalled = [f for period in out[k:k + self.burst_after] for f in period]  # stall from the frame on
            out[k:k + self.burst_after] = [[] for _ in range(self.burst_after)]
            out[k + self.burst_after] = stalled + out[k + self.burst_after]
        return out


def _python(periods: list[list[tuple[int, bytes]]]) -> list[list[str]]:
    node = rt.ControllerNode(_Recorder(), rt.RuntimeConfig(rate_hz=RATE_HZ))  # type: ignore[arg-type]
    out = []
    for period in periods:
        for fid, data in period:
            node.receive(can.Message(arbitration_id=fid, data=data, is_extended_id=False))
        before = len(node.bus.sent)  # type: ignore[attr-defined]
        node.control()
        out.append([f"{m.arbitration_id:03X}#{bytes(m.data).hex().upper()}" for m in node.bus.sent[before:]])  # type: ignore[attr-defined]
    return out


def _c(exe: Path, periods: list[list[tuple[int, bytes]]], all_accepted: bool = True) -> list[list[str]]:
    lines = ["plain"]
    for period in periods:
        lines += [f"rx {fid:X} {data.hex()}" for fid, data in period] + ["ctl"]
    proc = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    answers = proc.stdout.splitlines()
    assert answers[0] == "ok"
    rows = iter(answers[1:])
    out = []
    for period in periods:
        verdicts = [next(rows) for _ in period]
        assert all(v == "1" for v in verdicts) or not all_accepted  # every frame accepted
        out.append(next(rows).split())
    return out


def _decoded(contract: mrsteer_dbc.Contract, sent: list[list[str]], msg: str) -> list[dict[str, float]]:
    fid = contract.frame_id(msg)
    rows = []
    for period in sent:
        for frame in period:
            i, data = frame.split("#")
            if int(i, 16) == fid:
                d = contract.decode(fid, bytes.fromhex(data))
                assert d is not None
                rows.append(dict(d.signals))
    return rows


def _run(exe: Path, drive: Drive) -> tuple[list[dict[str, float]], list[dict[str, float]]]:
    contract = mrsteer_dbc.load()
    periods = drive.frames(contract)
    c_sent, py_sent = _c(exe, periods), _python(periods)
    assert c_sent == py_sent  # every command and status frame, byte for byte
    return _decoded(contract, c_sent, names.MSG_CMD), _decoded(contract, c_sent, names.MSG_STATUS)


def test_fault_free_drive_equals_python_and_raises_nothing(secoc_check: Path) -> None:
    cmds, statuses = _run(secoc_check, Drive())
    assert {s[names.SIG_STATUS_PLAUS] for s in statuses} == {0}
    assert not any(int(s[names.SIG_STATUS_CAUSE]) & names.CAUSE_PLAUSIBILITY for s in statuses)
    assert {c[names.SIG_CMD_STATE] for c in cmds[-100:]} <= {mr.STATUS_ACTIVE, mr.STATUS_SATURATED}
    assert max(abs(c[names.SIG_CMD_ANGLE]) for c in cmds) > 1e-3  # the law acted on the disturbance


def test_stuck_yaw_rate_is_a_plausibility_fault_faded_to_zero_as_in_python(secoc_check: Path) -> None:
    cmds, statuses = _run(secoc_check, Drive(seconds=2.2, stuck_yaw=True))
    k_stuck = int(STUCK_T * RATE_HZ)
    states = [int(c[names.SIG_CMD_STATE]) for c in cmds]
    assert mr.STATUS_FAULT not in states[:k_stuck]
    k_fault = states.index(mr.STATUS_FAULT)
    # Issue 18's 300 ms is judged on the car (HIL); here the kinematic window (4 samples of 50 ms)
    # and the count over the bound take 300 ms of this drive: a bound, not a target.
    assert k_fault - k_stuck <= 0.35 * RATE_HZ
    assert set(states[k_fault:]) == {mr.STATUS_FAULT}  # latched
    # The limiter fades at its fault rate from where the command was: zero within |u| / 30 deg/s.
    fade = math.radians(30.0)
    u0 = abs(cmds[k_fault - 1][names.SIG_CMD_ANGLE])
    k_zero = k_fault + int(math.ceil(u0 / fade * RATE_HZ)) + 1
    assert u0 > 1e-3 and all(c[names.SIG_CMD_ANGLE] == 0.0 for c in cmds[k_zero:])
    per_status = round(len(cmds) / len(statuses))
    late = statuses[k_fault // per_status + 1:]
    assert late and all(int(s[names.SIG_STATUS_STATE]) == mr.STATUS_FAULT for s in late)
    assert all(int(s[names.SIG_STATUS_PLAUS]) & pl.PLAUS_YAW for s in late)
    assert all(int(s[names.SIG_STATUS_CAUSE]) & names.CAUSE_PLAUSIBILITY for s in late)


def test_the_yaw_rate_pair_finds_a_stuck_element_at_once_and_cuts_the_command_as_in_python(secoc_check: Path) -> None:
    clean_cmds, clean_statuses = _run(secoc_check, Drive(second_yaw=True))
    assert {s[names.SIG_STATUS_PLAUS] for s in clean_statuses} == {0}  # the pair agrees: no alarm
    cmds, statuses = _run(secoc_check, Drive(seconds=1.4, stuck_yaw=True, second_yaw=True))
    k_stuck = int(STUCK_T * RATE_HZ)
    states = [int(c[names.SIG_CMD_STATE]) for c in cmds]
    k_fault = states.index(mr.STATUS_FAULT)
    # r - r2 is -0.07 rad/s from the onset: the 5-sample mean passes 0.03 with the 3rd stuck sample
    assert k_fault - k_stuck == 2
    assert set(states[k_fault:]) == {mr.STATUS_FAULT}
    # Removed at the limiter's rate bound (10 rad/s), not faded at 30 deg/s.
    u0 = abs(cmds[k_fault - 1][names.SIG_CMD_ANGLE])
    k_zero = k_fault + int(math.ceil(u0 / au.AuthorityConfig().rate_max * RATE_HZ)) - 1  # from the fault's period
    assert u0 > 1e-3 and all(c[names.SIG_CMD_ANGLE] == 0.0 for c in cmds[k_zero:])
    assert k_zero == k_fault or abs(cmds[k_zero - 1][names.SIG_CMD_ANGLE]) > 0.0  # not sooner
    late = [s for s in statuses if int(s[names.SIG_STATUS_STATE]) == mr.STATUS_FAULT]
    assert late and all(int(s[names.SIG_STATUS_PLAUS]) & pl.PLAUS_YAW for s in late)


def test_the_speed_pair_finds_a_drifting_second_speed_and_cuts_the_command_as_in_python(secoc_check: Path) -> None:
    _, clean_statuses = _run(secoc_check, Drive(second_speed=V))
    assert {s[names.SIG_STATUS_PLAUS] for s in clean_statuses} == {0}  # the speeds agree: no alarm
    cmds, statuses = _run(secoc_check, Drive(seconds=1.6, second_speed=V, second_speed_drift=-10.0))
    states = [int(c[names.SIG_CMD_STATE]) for c in cmds]
    k_fault = states.index(mr.STATUS_FAULT)
    # The second speed falls at 10 m/s per s, sent every 50 ms: 20 - v2 > 1.0 + 0.05 v2 from
    # v2 = 18.1 (0.19 s after STUCK_T, the frame at 0.2 s), then speed_pair_time 0.1 s
    assert k_fault == int((STUCK_T + 0.2 + 0.1) * RATE_HZ) - 1
    assert set(states[k_fault:]) == {mr.STATUS_FAULT}
    late = [s for s in statuses if int(s[names.SIG_STATUS_STATE]) == mr.STATUS_FAULT]
    assert late and all(int(s[names.SIG_STATUS_PLAUS]) & pl.PLAUS_YAW for s in late)
    assert all(c[names.SIG_CMD_ANGLE] == 0.0 for c in cmds[-50:])  # removed, latched


def test_a_second_speed_lost_on_the_bus_is_degraded_as_in_python(secoc_check: Path) -> None:
    # Sent, then SNA from 0.8 s: the speed pair pauses and both nodes report DEGRADED, no fault.
    lost = 0.8
    cmds, statuses = _run(secoc_check, Drive(seconds=1.4, second_speed=V, second_speed_lost=lost))
    plaus = [int(s[names.SIG_STATUS_PLAUS]) for s in statuses]
    per_status = round(len(cmds) / len(statuses))
    k_lost = int(lost * RATE_HZ) // per_status
    # the first SNA frame comes at the redundant frame's next 50 ms after the loss
    assert set(plaus[:k_lost]) == {0} and set(plaus[k_lost + 1:]) == {pl.PLAUS_DEGRADED}
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds}


def test_a_second_yaw_rate_element_lost_on_the_bus_is_degraded_as_in_python(secoc_check: Path) -> None:
    # The element sent, then SNA from 0.8 s (a failed element): the pair check pauses, and the
    # node reports DEGRADED from the loss on, no fault; a sender that never sends it stays clean
    # (test_fault_free_drive_equals_python_and_raises_nothing).
    lost = 0.8
    cmds, statuses = _run(secoc_check, Drive(seconds=1.4, second_yaw=True, second_yaw_lost=lost))
    per_status = round(len(cmds) / len(statuses))
    k_lost = int(lost * RATE_HZ) // per_status  # the status frames sent before the loss
    plaus = [int(s[names.SIG_STATUS_PLAUS]) for s in statuses]
    assert set(plaus[:k_lost]) == {0} and set(plaus[k_lost + 1:]) == {pl.PLAUS_DEGRADED}
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds}


def test_the_pair_s_suspicion_holds_the_law_in_both_nodes_without_a_fault(secoc_check: Path) -> None:
    # The elements 0.025 rad/s apart: every sample over yaw_pair_hold (0.02), the window's mean
    # under the bound (0.03).  The law's command is held (it may not grow) for 5 samples at a
    # time, re-armed only by 5 samples within the threshold, which never come: held once, from
    # the first sample, and then free.  No fault, no bus bit; both nodes byte for byte.
    free, _ = _run(secoc_check, Drive(second_yaw=True))
    cmds, statuses = _run(secoc_check, Drive(second_yaw=True, second_yaw_offset=0.025))
    assert {int(s[names.SIG_STATUS_PLAUS]) for s in statuses} == {0}
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds}
    u_free = [c[names.SIG_CMD_ANGLE] for c in free]
    u_held = [c[names.SIG_CMD_ANGLE] for c in cmds]
    differ = [k for k, (a, b) in enumerate(zip(u_free, u_held)) if a != b]
    assert differ and differ[0] < pl.YAW_PAIR_WINDOW  # held from the start
    assert all(abs(u_held[k]) <= abs(u_held[k - 1]) for k in range(1, pl.YAW_PAIR_WINDOW))
    # and free after the cap: the command follows the law again, closing on the free drive's
    assert abs(u_held[-1]) > 1e-4 and abs(u_held[-1] - u_free[-1]) < 0.1 * abs(u_free[-1])


def test_without_the_redundant_frame_the_node_is_degraded_and_time_limited_as_in_python(secoc_check: Path) -> None:
    window = au.AuthorityConfig().panic_window
    cmds, statuses = _run(secoc_check, Drive(seconds=window + 1.0, redundant=False))
    assert {int(s[names.SIG_STATUS_PLAUS]) for s in statuses} == {pl.PLAUS_DEGRADED}
    # STARTING while the redundant frame may still come (its timeout from the first frame), then DEGRADED
    limit = 250  # 10 of its 50 ms cycles at 500 Hz
    assert [int(c[names.SIG_CMD_STATE]) for c in cmds] == [mr.STATUS_STARTING] * (limit + 1) + [
        mr.STATUS_DEGRADED] * (len(cmds) - limit - 1)
    assert {int(s[names.SIG_STATUS_STATE]) for s in statuses[-5:]} == {mr.STATUS_DEGRADED}
    # A missing redundant input is no cause bit and no fault.
    assert all(int(s[names.SIG_STATUS_CAUSE]) & (names.CAUSE_PLAUSIBILITY | 0x0F) == 0 for s in statuses[1:])
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds}
    # The law holds its command against the disturbance; the limiter ends it after the window.
    k_dist = int(DIST_T * RATE_HZ)
    assert abs(cmds[k_dist + int(0.5 * RATE_HZ)][names.SIG_CMD_ANGLE]) > 1e-3
    assert all(c[names.SIG_CMD_ANGLE] == 0.0 for c in cmds[-int(0.3 * RATE_HZ):])


def test_a_clean_start_after_idle_periods_is_starting_then_active_as_in_python(secoc_check: Path) -> None:
    cmds, statuses = _run(secoc_check, Drive(seconds=0.3, idle=7))
    states = [int(c[names.SIG_CMD_STATE]) for c in cmds]
    assert states[:7] == [mr.STATUS_STARTING] * 7 and set(states[7:]) == {mr.STATUS_ACTIVE}
    assert int(statuses[0][names.SIG_STATUS_STATE]) == mr.STATUS_ACTIVE


def test_a_speed_that_never_comes_is_starting_then_a_fault_as_in_python(secoc_check: Path) -> None:
    cmds, statuses = _run(secoc_check, Drive(seconds=0.6, idle=3, speed=False))
    limit = 100  # 10 of its 20 ms cycles at 500 Hz, counted from the first frame
    states = [int(c[names.SIG_CMD_STATE]) for c in cmds]
    assert states == [mr.STATUS_STARTING] * (3 + limit + 1) + [mr.STATUS_FAULT] * (len(states) - limit - 4)
    assert {int(s[names.SIG_STATUS_CAUSE]) & 0x0F for s in statuses} == {names.CAUSE_SPEED_MISSING}


def test_a_silent_bus_is_starting_for_the_start_timeout_then_a_fault_as_in_python(secoc_check: Path) -> None:
    limit = round(rt.START_TIMEOUT_S * RATE_HZ)
    cmds, statuses = _run(secoc_check, Drive(seconds=0.0, idle=limit + 3))
    assert [int(c[names.SIG_CMD_STATE]) for c in cmds] == [mr.STATUS_STARTING] * limit + [mr.STATUS_FAULT] * 3
    assert int(statuses[-1][names.SIG_STATUS_CAUSE]) == 0x07


def test_redundant_samples_off_time_are_withheld_as_in_python(secoc_check: Path) -> None:
    # A late redundant frame (a stalled sender) and one whose period lost its yaw-rate frame are
    # withheld from the monitor for their hold: DEGRADED then, never a fault.
    from firmware_py.controller.sample_clock import REDUNDANT_JITTER_CYCLES

    header = (ROOT / "ports" / "c" / "mrs_node_core.h").read_text()
    assert f"#define MRS_REDUNDANT_JITTER_CYCLES {REDUNDANT_JITTER_CYCLES}\n" in header
    cmds, statuses = _run(secoc_check, Drive(seconds=2.0, jitter=True))
    plaus = [int(s[names.SIG_STATUS_PLAUS]) for s in statuses]
    assert pl.PLAUS_DEGRADED in plaus and 0 in plaus[5:]
    assert not any(p & pl.PLAUS_FAULT for p in plaus)
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds[50:]}


def test_a_sender_slower_than_the_loop_keeps_the_monitors_clock_as_in_python(secoc_check: Path) -> None:
    # The plant two periods per step (a VM's): the monitor steps on the yaw-rate samples, so the
    # redundant frames, 25 samples apart by their counters, stay in time and nothing is withheld
    # (counted in control periods they would be 50 apart: DEGRADED for good).
    cmds, statuses = _run(secoc_check, Drive(seconds=2.0, slow=2))
    plaus = [int(s[names.SIG_STATUS_PLAUS]) for s in statuses]
    assert set(plaus[1:]) == {0}
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds}


def test_a_redundant_frame_drained_in_a_burst_with_the_samples_before_it_stays_in_time_as_in_python(
        secoc_check: Path) -> None:
    # A stall of 5 periods ends with its frames drained at once: the yaw-rate samples before the
    # redundant frame belong to its interval (25 samples by the counters), not to the next one's.
    # Counted at the period's end instead, this sample (21 of 25) and the next (29) were both
    # withheld: DEGRADED for 100 ms and, in a fault, the kinematic window restarted (200 ms).
    cmds, statuses = _run(secoc_check, Drive(seconds=2.0, burst=5))
    plaus = [int(s[names.SIG_STATUS_PLAUS]) for s in statuses]
    assert set(plaus[1:]) == {0}
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds}


HAND = (0.04, 4.0)  # a weave of 0.04 rad at 4 Hz: 1 rad/s of wheel angle at its fastest, a fast hand
SKEW = 10  # periods of a stall that begins with a redundant frame (20 ms: the yaw rate times out after 24)


def test_a_redundant_frame_drained_ahead_of_the_drivers_angle_is_paired_with_its_own_as_in_python(
        secoc_check: Path) -> None:
    # The frames of a stall that begins at a redundant frame come at once: the newest driver's
    # angle is 20 ms younger than the second channel's, 0.02 rad apart at this hand, five times
    # the steering pair's 0.004 rad.  Compared with the newest angle, the pair found a steering
    # fault in 0.17 s; with the angle that came with the redundant frame, nothing.
    cmds, statuses = _run(secoc_check, Drive(seconds=2.0, burst_after=SKEW, weave=HAND))
    plaus = [int(s[names.SIG_STATUS_PLAUS]) for s in statuses]
    assert set(plaus[1:]) == {0}
    assert mr.STATUS_FAULT not in {int(c[names.SIG_CMD_STATE]) for c in cmds}


def test_a_steering_channel_offset_is_still_found_in_the_skewed_bursts_as_in_python(secoc_check: Path) -> None:
    # 0.006 rad, 1.5 times the pair's bound, from a redundant frame that begins a stall: found by
    # the drain that ends the stall, the first cycle that steps over that sample, and not before
    onset = 21 * 25  # period of a redundant frame (every 25) that begins a stall (every 2nd from the 1st)
    drive = Drive(seconds=2.0, burst_after=SKEW, weave=HAND, steer_2_offset=0.006, steer_2_from=onset / RATE_HZ)
    _, statuses = _run(secoc_check, drive)  # Python and C frame for frame
    assert pl.PLAUS_STEER in {int(s[names.SIG_STATUS_PLAUS]) for s in statuses}
    node = rt.ControllerNode(_Recorder(), rt.RuntimeConfig(rate_hz=RATE_HZ))  # type: ignore[arg-type]
    found = None
    for k, period in enumerate(drive.frames(mrsteer_dbc.load())):
        for fid, data in period:
            node.receive(can.Message(arbitration_id=fid, data=data, is_extended_id=False))
        node.control()
        if node.plausibility & pl.PLAUS_STEER:
            found = k
            break
    assert found == onset + SKEW


def test_a_redundant_frame_is_not_paired_with_a_driver_s_angle_that_had_timed_out_as_in_python(
        secoc_check: Path) -> None:
    # The driver's angle lost for 11 periods (timed out) up to a redundant frame, and that
    # period's and the next's yaw-rate frames lost, so the monitor steps over the redundant sample
    # only when the angle is back: paired with the timed-out angle, 22 ms old at a fast hand, the
    # pair would find a steering fault in a healthy drive.
    contract = mrsteer_dbc.load()
    periods = Drive(seconds=2.0, weave=HAND).frames(contract)
    at = 21 * 25  # a redundant frame's period
    for k in range(at - 10, at + 1):
        periods[k] = [f for f in periods[k] if f[0] != contract.frame_id(names.MSG_STEER)]
    for k in (at, at + 1):
        periods[k] = [f for f in periods[k] if f[0] != contract.frame_id(names.MSG_YAW)]
    c_sent = _c(secoc_check, periods, all_accepted=False)  # the angle's first frame back may be rejected
    assert c_sent == _python(periods)
    statuses = _decoded(contract, c_sent, names.MSG_STATUS)
    assert not any(int(s[names.SIG_STATUS_PLAUS]) & pl.PLAUS_FAULT for s in statuses[1:])


def test_a_log_with_the_skewed_bursts_replays_to_its_commands_in_python_and_in_c(tmp_path: Path) -> None:
    # The skewed drive with a steering channel offset, as a clocked controller's candump log:
    # each period's received frames, then what the Python node sent.  Both replays must give the
    # recorded commands, so each must pair the burst's redundant sample with its own angle.
    contract = mrsteer_dbc.load()
    periods = Drive(seconds=2.0, burst_after=SKEW, weave=HAND, steer_2_offset=0.006).frames(contract)
    node = rt.ControllerNode(_Recorder(), rt.RuntimeConfig(rate_hz=RATE_HZ))  # type: ignore[arg-type]
    sent: list[can.Message] = node.bus.sent  # type: ignore[attr-defined]
    lines = []
    for k, period in enumerate(periods):
        t = 1e6 + k / RATE_HZ
        lines += [f"({t:.6f}) vcan0 {fid:03X}#{data.hex().upper()}" for fid, data in period]
        for fid, data in period:
            node.receive(can.Message(arbitration_id=fid, data=data, is_extended_id=False))
        before = len(sent)
        if k + 1 < len(periods):
            node.control()
        else:
            node.finish()  # the log ends on the shutdown's command
        lines += [f"({t + 1e-4:.6f}) vcan0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}" for m in sent[before:]]
    log = tmp_path / "skewed.log"
    log.write_text("\n".join(lines) + "\n")
    result = replay(log, ReplaySettings(rate_hz=RATE_HZ, trigger="clock"))
    c_result = replay_c.replay_c(result)
    assert result.agrees and c_result.agrees, (result.mismatches[:3], c_result.mismatches[:3])
    paired = [s for s in result.steps
              if s.kind != "final" and not math.isnan(s.monitor_driver) and s.monitor_driver != s.inputs[0]]
    assert len(paired) >= 5  # a burst's pairing took the older angle (one per skewed redundant frame)
    assert any(s.out.state == mr.STATUS_FAULT for s in c_result.steps)  # the offset found


STUCK_SCENARIO = """
name = "fig9-yaw-stuck"
description = "paper-fig9 with the yaw-rate sensor stuck at 0.01 rad/s from 0.3 s"
duration = 1.5
v = 20.0
mu = 1.0

[[events]]
t = 0.5
yaw_moment = 4000.0

[[sensor_fault]]
sensor = "yaw_rate"
kind = "stuck"
value = 0.01
start = 0.3
"""


def _hil(out: Path, scenario: Path, program: tuple[str, ...] | None) -> dict[str, list]:
    """A lockstep run's traffic (``lockstep_traffic``), run again (twice at most) when the plant
    stalled for a watchdog cycle: the machine's load, not the controller."""
    for _ in range(3):
        hil.run(hil.HilConfig(scenario=str(scenario), mode="lockstep", out=out, controller_program=program))
        traffic = lockstep_traffic(out / "traffic.log")
        if not traffic["stalls"]:
            break
    return traffic


def _statuses(log: Path) -> list[tuple[int, int, int]]:
    """(state, plausibility, cause) of the status frames, repeats merged: their phase against the
    plant's frames depends on the watchdog cycles before the plant started."""
    c = mrsteer_dbc.load()
    sid = c.frame_id(names.MSG_STATUS)
    out: list[tuple[int, int, int]] = []
    for line in log.read_text().splitlines():
        fid, data = line.split()[2].split("#")
        if int(fid, 16) == sid:
            d = c.decode(sid, bytes.fromhex(data))
            assert d is not None
            s = d.signals
            row = (int(s[names.SIG_STATUS_STATE]), int(s[names.SIG_STATUS_PLAUS]), int(s[names.SIG_STATUS_CAUSE]))
            if not out or out[-1] != row:
                out.append(row)
    return out


def test_lockstep_with_a_stuck_yaw_rate_sensor_and_its_replay_equal_python(secoc_check: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "stuck.toml"
    scenario.write_text(STUCK_SCENARIO)
    py = _hil(tmp_path / "py", scenario, None)
    c = _hil(tmp_path / "c", scenario, launch.controller_program("c"))
    assert c == py and len(c["commands"]) > 700  # every command's state, angle and measurement
    states = [int(cmd[0]) for cmd in c["commands"]]
    k_fault = states.index(mr.STATUS_FAULT)
    assert 0.3 * RATE_HZ < k_fault < 1.2 * RATE_HZ  # after the onset, before the end
    assert max(abs(cmd[1]) for cmd in c["commands"][:k_fault]) > 1e-3  # the law was acting on the stuck value
    assert all(cmd[1] == 0.0 for cmd in c["commands"][-100:])  # faded to zero
    st = _statuses(tmp_path / "c" / "traffic.log")
    assert st == _statuses(tmp_path / "py" / "traffic.log")
    assert (mr.STATUS_FAULT, pl.PLAUS_YAW, names.CAUSE_PLAUSIBILITY) in st

    # The C run's log through both replays: each gives the recorded commands.
    log = tmp_path / "c" / "traffic.log"
    result = replay(log)
    c_result = replay_c.replay_c(result)
    assert result.agrees and c_result.agrees, (result.mismatches[:3], c_result.mismatches[:3])
    assert any(s.out.state == mr.STATUS_FAULT for s in c_result.steps)

    # Without MRS_RedundantSensors the node runs degraded: other commands than recorded, the
    # same in Python and in C.
    red = f"{mrsteer_dbc.load().frame_id(names.MSG_REDUNDANT):03X}#"
    stripped = tmp_path / "no-redundant.log"
    stripped.write_text("".join(ln for ln in log.read_text().splitlines(keepends=True) if red not in ln))
    result = replay(stripped)
    c_result = replay_c.replay_c(result)
    assert all(math.isnan(s.inputs[3]) for s in result.steps)
    assert not result.agrees
    assert [(s.out.angle, s.out.state) for s in c_result.steps] == [(s.out.angle, s.out.state) for s in result.steps]
