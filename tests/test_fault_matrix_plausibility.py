"""The fault matrix's sensor rows and their verdicts (issue 18, item 4), on synthetic evidence:
a run's traffic built frame by frame, with the detection, fade and latch each test varies, so
that each verdict is seen to pass what it should and fail what it should."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest
from scipy import signal

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.plausibility import PLAUS_FAULT, PlausibilityConfig
from mrsteer_dbc import names
from mrsteer_dbc.e2e import COUNTER_MODULO
from sim_plant.car import scenario as scn
from sim_plant.car.nonlinear import NonlinearPlant
from sim_plant.car.vehicle import VehicleParams, steering_tf
from sim_plant.harness import faults as F
from sim_plant.harness.faults.caused_yaw import caused_yaw
from sim_plant.harness.faults.evidence import Evidence, Status, Trace
from sim_plant.harness.faults.settings import CURVE, RATE_LIMIT, scenario_spec
from sim_plant.harness.faults.verdicts import Verdict, check_command_rate, judge
from sim_plant.harness.faults.verdicts_plausibility import (check_plausibility, check_quiet_monitor, error_series,
                                                            exceeded_at)
from sim_plant.nodes.fault_bridge import SENSOR_KINDS

C = mrsteer_dbc.load()
TS = 0.002
ONSET = 1.0
END = 2.6
R = 0.0203  # rad/s: paper-fig9's yaw rate from 1.0 s
U0 = math.radians(-1.81)
FADE = math.radians(30.0)  # the authority limiter's fade on a plausibility fault


def _row(name: str = "yaw-rate offset +3 deg/s") -> F.Row:
    return next(r for r in F.ROWS if r.name == name)


def _yaw(t: float, value: float, k: int) -> tuple[float, int, bytes]:
    return (t, C.frame_id(names.MSG_YAW), C.encode(names.MSG_YAW, {names.SIG_YAW_RATE: value}, k % 15))


def _speed(t: float, k: int, value: float = 20.0) -> tuple[float, int, bytes]:
    return (t, C.frame_id(names.MSG_SPEED), C.encode(names.MSG_SPEED, {names.SIG_SPEED: value}, k % 15))


def evidence(row: F.Row, *, error=lambda t: 0.0524, detect: float | None = 0.2, fade: float = FADE,
             unlatch_at: float | None = None, cause: int = names.CAUSE_PLAUSIBILITY, plaus: int | None = None,
             early_alarm: float | None = None, status_plaus_quiet: int = 0, end: float = END,
             status_lag: float = 0.0, episode: tuple[float, float] | None = None, gap: bool = False,
             redundant_lost: tuple[int, ...] | None = None, speed_error=lambda t: 0.0,
             speed_2: float | None = None) -> Evidence:
    """A run of ``row``: yaw-rate frames (truth R on the vehicle's bus, R + error(t) from
    ONSET on the controller's; the speed likewise, 20 m/s + speed_error(t)), a command every
    period (U0, FAULT from ONSET + ``detect``, faded at ``fade``), a status every 100 ms; with
    ``redundant_lost``, the redundant frame every 50 ms on the controller's bus but for those
    samples (counted from 0 s); with ``speed_2``, the vehicle's redundant frame every 50 ms with
    that second speed (the car has it)."""
    n = int(round(end / TS))
    vehicle, ctl, cmds, angles, statuses = [], [], [], [], []
    t_fault = None if detect is None else ONSET + detect
    u = U0
    bits = row.plausibility if plaus is None else plaus
    for k in range(n):
        t = k * TS
        stall = gap and episode is not None and episode[0] - 0.03 <= t < episode[0]  # the plant went quiet
        if not stall:
            vehicle.append(_yaw(t, R, k))
            ctl.append(_yaw(t + 1e-4, R + (error(t) if t >= ONSET else 0.0), k))
        if redundant_lost is not None and k % 25 == 0 and k // 25 not in redundant_lost:
            ctl.append((t + 2e-4, C.frame_id(names.MSG_REDUNDANT), C.encode(
                names.MSG_REDUNDANT, {names.SIG_LAT_ACCEL: 0.4, names.SIG_STEER_ANGLE_2: 0.0}, (k // 25) % 15)))
        if speed_2 is not None and k % 25 == 0:
            vehicle.append((t + 2e-4, C.frame_id(names.MSG_REDUNDANT), C.encode(
                names.MSG_REDUNDANT, {names.SIG_LAT_ACCEL: 0.4, names.SIG_STEER_ANGLE_2: 0.0,
                                      names.SIG_SPEED_2: speed_2}, (k // 25) % 15)))
        if k % 5 == 0 and not stall:
            vehicle.append(_speed(t, k // 5))
            ctl.append(_speed(t + 1e-4, k // 5, 20.0 + (speed_error(t) if t >= ONSET else 0.0)))
        faulted = (t_fault is not None and t >= t_fault) or (episode is not None and episode[0] <= t < episode[1])
        if t_fault is not None and t >= t_fault:
            u = min(0.0, u + fade * TS)
        # as the node reports the row's fault: FAULT on a fault bit, DEGRADED on the degraded bit alone
        stalled = episode is not None and episode[0] <= t < episode[1]  # an input timed out: the law's FAULT
        reported = mr.STATUS_FAULT if row.plausibility & PLAUS_FAULT or stalled else mr.STATUS_DEGRADED
        state = reported if faulted else mr.STATUS_ACTIVE
        if unlatch_at is not None and t >= unlatch_at:
            state = mr.STATUS_ACTIVE
        cmds.append((t + 5e-4, float(state)))
        angles.append((t + 5e-4, round(u, 6)))
        if k % 50 == 0:
            on = (t_fault is not None and t >= t_fault + status_lag) or (
                early_alarm is not None and abs(t - early_alarm) < TS / 2)
            statuses.append(Status(t + 6e-4, reported if on else mr.STATUS_ACTIVE,
                                   bits if on else status_plaus_quiet, cause if on else 0))
    bridge = {"first_affected": ONSET + 1e-4, "last_affected": end, "affected": n // 2}
    trace = Trace([0.0], [0.0], [0.0], [0.0])
    first_active = cmds[0][0]
    faults_after = [t for t, s in cmds if s == mr.STATUS_FAULT and t > first_active]
    return Evidence(row, F.Setup(), 0, None, None, trace, bridge, {}, {}, {}, vehicle, ctl, cmds, angles,
                    [k % COUNTER_MODULO for k in range(len(angles))],
                    [(s.t, s.cause) for s in statuses], faults_after, statuses, end)


def _judge(e: Evidence) -> tuple[list[str], list[str], int | None]:
    fails: list[str] = []
    observed: list[str] = []
    return fails, observed, check_plausibility(e, fails, observed)


def test_a_fault_found_in_time_faded_and_latched_passes() -> None:
    fails, observed, cycles = _judge(evidence(_row()))
    assert fails == [], fails
    assert cycles == pytest.approx(0.2 / TS, abs=2)
    text = "; ".join(observed)
    assert "FAULT 200 ms" in text and "faded 1.81 deg to 0" in text and "latched" in text


def test_late_detection_fails_and_the_status_cycle_is_allowed_only_to_the_status() -> None:
    fails, _, _ = _judge(evidence(_row(), detect=0.35))
    assert any("reported late" in f for f in fails)
    fails, _, _ = _judge(evidence(_row(), detect=0.29))
    assert fails == []


def test_a_redundant_sample_missing_before_the_report_is_shown_beside_the_detection() -> None:
    # Each costs the kinematic check time: a late row must say whether that is why.
    _, observed, _ = _judge(evidence(_row(), redundant_lost=()))
    assert not any("redundant frame" in o for o in observed), observed
    _, observed, _ = _judge(evidence(_row(), redundant_lost=(22,)))  # 1.1 s: after the onset, before 1.2 s
    assert any("redundant frame before the report: 0 status frames DEGRADED, largest gap 100 ms" in o
               for o in observed), observed


@pytest.mark.parametrize("kwargs,needle", [
    (dict(unlatch_at=2.0), "not latched"),
    (dict(fade=FADE / 2), "faded in"),
    (dict(cause=names.CAUSE_E2E), "lack a fault bit"),
    (dict(plaus=names.PLAUS_DEGRADED), "no status frame reported"),
    (dict(plaus=names.PLAUS_STEER), "never gave bit 0x1"),  # the wrong check tripped
    (dict(early_alarm=0.5), "before the fault's onset"),
    (dict(detect=None), "no plausibility fault reported"),
    (dict(status_lag=0.15), "the first status after the FAULT command did not report it"),
])
def test_each_broken_promise_fails_its_verdict(kwargs: dict, needle: str) -> None:
    fails, _, _ = _judge(evidence(_row(), **kwargs))
    assert any(needle in f for f in fails), fails


def test_a_growing_error_is_timed_from_when_it_left_its_bound() -> None:
    row = _row("yaw-rate drift 1 deg/s per s")
    drift = lambda t: math.radians(1.0) * (t - ONSET)  # noqa: E731
    bound = PlausibilityConfig().yaw_bound + PlausibilityConfig().yaw_rel * R
    leaves = ONSET + bound / math.radians(1.0)  # about 2.1 s after onset
    fails, observed, _ = _judge(evidence(row, error=drift, detect=leaves - ONSET + 0.25, end=4.2))
    assert fails == [], fails
    over_ms = float("; ".join(observed).split("error over its bound ")[1].split(" ms")[0])
    assert over_ms == pytest.approx(1e3 * (leaves - ONSET), abs=3)
    fails, _, _ = _judge(evidence(row, error=drift, detect=leaves - ONSET + 0.4, end=4.2))
    assert any("reported late" in f for f in fails)
    # found before the error left the bound: early, not late
    fails, observed, _ = _judge(evidence(row, error=drift, detect=leaves - ONSET - 0.5, end=4.2))
    assert fails == [] and "reported before the error stayed over its bound" in "; ".join(observed)


def test_an_error_within_its_bound_and_no_report_says_the_row_tests_nothing() -> None:
    fails, _, _ = _judge(evidence(_row(), error=lambda t: 0.01, detect=None))
    assert any("does not test the monitor" in f for f in fails), fails


def test_error_series_pairs_the_frames_and_bounds_the_yaw_rate() -> None:
    series = error_series(evidence(_row()))
    after = [s for s in series if s[0] >= ONSET]
    assert all(err == pytest.approx(0.0524, abs=2e-6) for _, err, _ in after)
    cfg = PlausibilityConfig()
    assert all(b == pytest.approx(cfg.yaw_bound + cfg.yaw_rel * R, abs=1e-6) for *_, b in series)
    assert exceeded_at(after, until=None) == pytest.approx(ONSET, abs=0.01)
    assert exceeded_at([(0.0, 1.0, 0.5), (0.1, 0.0, 0.5), (0.2, 1.0, 0.5)], until=0.25) == 0.2  # a blip does not count
    assert exceeded_at([(0.0, 1.0, 0.5), (0.1, 0.0, 0.5)], until=None) is None


def test_a_fault_free_row_must_keep_the_monitor_quiet() -> None:
    """No fault bit, and no DEGRADED latched to the end (the monitor's OUTSIDE_MODEL); a
    missing frame's DEGRADED, which comes and goes, is counted, not failed."""
    clean = replace(_row("baseline"), plausibility=0)
    for bits, alarm in ((0, False), (names.PLAUS_DEGRADED, True), (names.PLAUS_YAW, True)):
        e = evidence(clean, detect=None, status_plaus_quiet=bits)
        fails: list[str] = []
        observed: list[str] = []
        check_quiet_monitor(e, fails, observed)
        assert bool(fails) == alarm and (alarm or "monitor quiet" in observed[0])
        assert not alarm or "false plausibility alarm" in fails[0]
    e = evidence(clean, detect=None)
    e = replace(e, statuses=[replace(s, plausibility=names.PLAUS_DEGRADED) if 0.5 <= s.t < 0.8 else s
                             for s in e.statuses])
    fails, observed = [], []
    check_quiet_monitor(e, fails, observed)
    assert fails == [] and observed == ["monitor quiet (3 status frames degraded)"]


def test_sensor_rows_are_the_issues_kinds() -> None:
    sensor = [r for r in F.ROWS if r.fault.kind in SENSOR_KINDS]
    assert {r.fault.kind for r in sensor} == set(SENSOR_KINDS) - {"sensor_noise"}
    # the a_y row's report is DEGRADED (the yaw rate's second element confirms the yaw rate)
    lat = [r for r in sensor if r.fault.signal == names.SIG_LAT_ACCEL]
    assert lat and all(r.plausibility == names.PLAUS_DEGRADED for r in lat)
    assert all(r.plausibility in (names.PLAUS_YAW, names.PLAUS_STEER) for r in sensor if r not in lat)
    # each lasts to its run's end: the fault latches, so there is nothing to recover from
    assert all(r.fault.stop == r.duration and not r.no_fault and r.detect_within is None for r in sensor)
    targets = {(r.fault.target, r.fault.signal) for r in sensor}
    assert {(names.MSG_YAW, None), (names.MSG_STEER, None), (names.MSG_REDUNDANT, names.SIG_LAT_ACCEL),
            (names.MSG_REDUNDANT, names.SIG_STEER_ANGLE_2), (names.MSG_SPEED, None)} <= targets
    # an offset of 3 deg/s, a gain of 0.5 and 1.5, a drift of 1 deg/s per s: the issue's ranges
    params = {(r.fault.kind, round(r.fault.param, 6)) for r in sensor}
    assert {("sensor_bias", round(math.radians(3.0), 6)), ("sensor_scale", 0.5), ("sensor_scale", 1.5),
            ("sensor_drift", round(math.radians(1.0), 6))} <= params


def test_a_speed_row_is_judged_against_the_speed_checks_jump() -> None:
    # On a car without the second speed (none in this traffic) the speed has no error bound but
    # the jump its check lets pass (speed_step 1.5 m/s): a step fault's error leaves it at the
    # onset, so detection counts from there.
    row = _row("curve: speed gain 0.5")
    assert (row.fault.target, row.fault.kind, row.plausibility) == (names.MSG_SPEED, "sensor_scale", names.PLAUS_YAW)
    halved = dict(error=lambda t: 0.0, speed_error=lambda t: -10.0)
    series = [s for s in error_series(evidence(row, **halved)) if s[0] >= ONSET]
    assert series and all(err == pytest.approx(-10.0, abs=0.002) and bound == 1.5 for _, err, bound in series)
    fails, observed, _ = _judge(evidence(row, **halved))
    assert fails == [], fails
    assert "error over its bound 0 ms after onset (peak 6.7x)" in "; ".join(observed)
    fails, _, _ = _judge(evidence(row, detect=0.35, **halved))
    assert any("reported late" in f for f in fails)
    # an offset the jump check lets pass does not test the monitor
    fails, _, _ = _judge(evidence(row, error=lambda t: 0.0, speed_error=lambda t: 1.0, detect=None))
    assert any("reached 0.67 of its bound" in f for f in fails), fails


def test_a_speed_drift_is_judged_against_the_speed_pair_on_a_car_with_the_second_speed() -> None:
    # The pair bounds the speed's error: 1.0 m/s + 5 % of the true 20 m/s, + half the second
    # speed's 0.3 m/s LSB with its 5 % = 2.1575 m/s, which a drift of -2 m/s per s passes 1.08 s
    # after its onset; without the second speed in the traffic the bound is the jump check's 1.5.
    row = _row("curve: speed drift -2 m/s per s")
    assert (row.fault.target, row.fault.kind, row.fault.param) == (names.MSG_SPEED, "sensor_drift", -2.0)
    drift = dict(error=lambda t: 0.0, speed_error=lambda t: -2.0 * (t - ONSET))
    series = [s for s in error_series(evidence(row, speed_2=20.1, **drift)) if s[0] >= ONSET]
    assert series and all(bound == pytest.approx(2.1575) for _, _, bound in series)
    assert {bound for _, _, bound in error_series(evidence(row, **drift))} == {1.5}
    fails, observed, _ = _judge(evidence(row, speed_2=20.1, detect=1.2, **drift))
    assert fails == [], fails
    fails, _, _ = _judge(evidence(row, speed_2=20.1, detect=1.42, **drift))
    assert any("reported late" in f for f in fails), fails


def test_the_curve_scenario_is_a_driver_steering_1_5_deg(tmp_path) -> None:
    sc = scn.load(scenario_spec(CURVE, tmp_path))
    assert sc.v == 20.0 and sc.mu == 1.0 and sc.driver.mode == "hold" and not sc.sensor_faults
    steer = [e for e in sc.events if e.kind == "steer"]
    assert steer[-1].value == pytest.approx(math.radians(1.5)) and steer[0].t == 0.5 and steer[-1].t < 0.95
    assert all(b.value > a.value for a, b in zip(steer, steer[1:]))  # turned at a steady rate, not a step
    assert scenario_spec("paper-fig9", tmp_path) == "paper-fig9"


def test_under_secoc_the_plant_injects_the_sensor_rows_faults(tmp_path) -> None:
    secured = {r.name: r for r in F.secured_rows()}
    sensor = [r for r in F.ROWS if r.fault.kind in SENSOR_KINDS]
    assert all(secured[r.name].at_plant and secured[r.name].secoc for r in sensor)
    assert not any(r.at_plant for r in F.ROWS)  # without SecOC the bridge injects them
    drift = secured["yaw-rate drift 1 deg/s per s"]
    sc = scn.load(scenario_spec(drift.scenario, tmp_path, F.rows.plant_fault(drift)))
    (fault,) = sc.sensor_faults
    assert (fault.sensor, fault.kind, fault.start, fault.value) == ("yaw_rate", "drift", 1.0, math.radians(1.0))
    assert sc.events == scn.load("paper-fig9").events and sc.duration == scn.load("paper-fig9").duration
    channel2 = F.rows.plant_fault(secured["curve: steering channel 2 stuck at 0"])
    frozen = F.rows.plant_fault(secured["yaw rate frozen (value, counter runs)"])
    assert (channel2.sensor, channel2.value) == ("steer_redundant", 0.0) and frozen.value is None


def test_a_speed_fault_the_plant_injects_is_measured_from_the_traced_speed() -> None:
    row = {r.name: r for r in F.secured_rows()}["curve: speed gain 0.5"]
    assert row.at_plant and F.rows.plant_fault(row).sensor == "speed"
    e = evidence(row, error=lambda t: 0.0)
    n = int(round(END / TS))
    t = [k * TS for k in range(n)]
    columns = {"t_s": t, "wall_s": t, "yaw_rate_rad_s": [R] * n, "v_m_s": [20.0] * n,
               "speed_measured_m_s": [10.0 if tk >= ONSET else 20.0 for tk in t]}
    e = replace(e, bridge={"first_affected": None, "last_affected": None, "affected": 0},
                trace=Trace(t, [0.0] * n, [0.0] * n, t, columns))
    series = error_series(e)
    assert [err for tk, err, _ in series if tk >= ONSET] == [-10.0] * sum(tk >= ONSET for tk in t)
    assert {b for _, _, b in series} == {1.5} and max(abs(err) for tk, err, _ in series if tk < ONSET) == 0.0


def test_a_fault_the_plant_injects_is_timed_and_measured_from_its_trace() -> None:
    row = {r.name: r for r in F.secured_rows()}["yaw-rate offset +3 deg/s"]
    e = evidence(row)
    n = int(round(END / TS))
    t = [k * TS for k in range(n)]
    true = [R] * n
    measured = [R + (0.0524 if tk >= ONSET else 0.0) for tk in t]
    columns = {"t_s": t, "wall_s": t, "yaw_rate_rad_s": true, "yaw_rate_measured_rad_s": measured,
               "v_m_s": [20.0] * n}
    # the bridge only forwarded: it falsified nothing, and the traffic on both sides agrees
    e = replace(e, bridge={"first_affected": None, "last_affected": None, "affected": 0},
                vehicle_frames=e.frames, trace=Trace(t, [0.0] * n, [0.0] * n, t, columns))
    fails, observed, cycles = _judge(e)
    assert fails == [], fails
    assert "error over its bound 0 ms after onset" in "; ".join(observed) and cycles == pytest.approx(100, abs=2)


def test_a_fault_that_comes_and_goes_is_not_latched_unless_a_stall_explains_it() -> None:
    # FAULT for 10 ms at 1.1 s, ACTIVE again, then the plausibility fault at 1.2 s
    fails, _, _ = _judge(evidence(_row(), episode=(1.1, 1.11)))
    assert any("not latched" in f for f in fails), fails
    # the same after 30 ms without sensor frames: an input timed out, the right answer
    fails, _, _ = _judge(evidence(_row(), episode=(1.1, 1.11), gap=True))
    assert fails == [], fails


def test_command_rate_verdict_counts_cycles_by_the_commands_alive_counter() -> None:
    base = evidence(_row())
    step = 1.5 * RATE_LIMIT * TS  # more than one cycle's limit, less than two cycles'
    angles = [(0.0, 0.0), (TS, step)]

    def judged(counters: list[int]) -> list[str]:
        v = Verdict()
        check_command_rate(replace(base, angles=angles, cmd_counters=counters), v)
        return v.fails

    assert judged([3, 4])[0].startswith("command stepped")  # one cycle apart: over the limit
    assert judged([3, 5]) == []  # a command between them the log did not accept: two cycles
    assert judged([14, 1]) == []  # two cycles across the counter's wrap (0..14)
    assert judged([14, 0])  # one cycle across it


def _step_trace(delta: float, t_on: float = 1.01, end: float = 4.0, dt: float = 1e-3,
                width: int | None = None) -> Trace:
    """The applied angle U0, then U0 + delta from t_on (for ``width`` steps only, if given)."""
    t = [k * dt for k in range(int(round(end / dt)) + 1)]
    k_on = int(round(t_on / dt))
    applied = [U0 + (delta if k >= k_on and (width is None or k < k_on + width) else 0.0) for k in range(len(t))]
    wall = [1000.0 + x for x in t]
    cols = {"t_s": t, "aux_applied_rad": applied, "aux_cmd_rad": applied, "wall_s": wall,
            "v_m_s": [20.0] * len(t), "mu": [1.0] * len(t)}
    return Trace(t, applied, applied, wall, cols)


def _peak(u: list[float], dt: float = 1e-3) -> float:
    """The continuous linear car's (20 m/s, mu 1) peak |r| for the input u held over each step."""
    tf = steering_tf(VehicleParams(v=20.0, mu=1.0))
    _, r, _ = signal.lsim(signal.lti(tf.num, tf.den), u, [k * dt for k in range(len(u))], interp=False)
    return float(max(abs(r)))


def test_caused_yaw_is_the_linear_cars_response_to_the_commands_excursion_since_the_onset() -> None:
    delta = math.radians(-1.0)  # away from zero, beyond the onset's U0 (-1.81 deg)
    e = replace(evidence(_row()), trace=_step_trace(delta, width=20))
    # A 20 ms pulse: its peak shows a step too many or too few (5 % each) that a step's would not.
    pulse = [0.0] * 10 + [delta] * 20 + [0.0] * 2960
    assert caused_yaw(e, 1001.0).value == pytest.approx(_peak(pulse), rel=2e-3)
    # The car's step is the trace's: a 2 ms trace, the same pulse in 10 steps.
    coarse = replace(e, trace=_step_trace(delta, dt=2e-3, width=10))
    assert caused_yaw(coarse, 1001.0).value == pytest.approx(_peak([0.0] * 5 + [delta] * 10 + [0.0] * 1480, 2e-3),
                                                             rel=2e-3)
    # The held value is the last step's at or before the onset, not the next one's, which may
    # already apply the answer to the first falsified frame.
    answered = replace(e, trace=_step_trace(delta, t_on=1.001, width=20))
    assert caused_yaw(answered, 1001.0005).value == pytest.approx(_peak([delta] * 20 + [0.0] * 2980), rel=2e-3)
    # Past zero the excursion counts from zero: U0 + 2.31 deg is 0.5 deg beyond it.
    past = caused_yaw(replace(e, trace=_step_trace(-U0 + math.radians(0.5))), 1001.0).value
    assert past == pytest.approx(_peak([0.0] * 10 + [math.radians(0.5)] * 2980), rel=2e-3)
    # Between the held value and zero (a fade, the safe state) nothing counts; nor a change
    # before the onset.
    assert caused_yaw(replace(e, trace=_step_trace(-U0)), 1001.0).value == 0.0
    assert caused_yaw(replace(e, trace=_step_trace(0.5 * -U0)), 1001.0).value == 0.0
    assert caused_yaw(replace(e, trace=_step_trace(delta, t_on=0.5)), 1001.0).value == 0.0


def test_caused_yaw_says_why_it_gives_no_figure() -> None:
    e = replace(evidence(_row()), trace=_step_trace(math.radians(-1.0)))
    assert caused_yaw(e, 2000.0).reason == "the plant's trace does not span the onset"
    # A command still moving at the onset (0.6 deg in its last 0.1 s): the healthy one is unknown.
    moving = replace(e, trace=_step_trace(math.radians(-0.6), t_on=0.95))
    assert caused_yaw(moving, 1001.0).reason == "the command was moving at the onset"
    assert caused_yaw(moving, 1001.06).value == 0.0  # 0.1 s after that step: steady again
    # The nonlinear car is replayed from the onset's state: a trace without it gives no figure.
    nonlinear = replace(e, setup=replace(e.setup, plant="nonlinear"))
    assert caused_yaw(nonlinear, 1001.0).reason == (
        "the plant's trace has no beta_rad, yaw_rate_rad_s, driver_angle_rad, m_z_nm")
    assert caused_yaw(replace(e, trace=Trace([0.0], [0.0], [0.0], [0.0])), 1001.0).value is None


def test_on_the_realistic_car_the_caused_yaw_is_the_nonlinear_cars() -> None:
    # The realistic car and actuator (faults run --plant nonlinear --actuator default): the
    # trace's applied angle is the actuator's position. From straight running with nothing held,
    # a 20 ms pulse of 0.25 deg keeps the tyres on their zero-slip slope, where the nonlinear car
    # is the linear one.
    delta = math.radians(-0.25)
    base = _step_trace(delta, width=20)
    n = len(base.t)
    pulse = [a - U0 for a in base.applied]

    def realistic(applied: list[float], driver: float, mu: float, beta: float, r: float) -> Evidence:
        columns = {**base.columns, "aux_applied_rad": applied, "mu": [mu] * n, "driver_angle_rad": [driver] * n,
                   "beta_rad": [beta] * n, "yaw_rate_rad_s": [r] * n, "m_z_nm": [0.0] * n}
        e = evidence(_row())
        return replace(e, trace=replace(base, applied=applied, columns=columns),
                       setup=replace(e.setup, plant="nonlinear", actuator="default"))

    straight = realistic(pulse, 0.0, 1.0, 0.0, 0.0)
    assert caused_yaw(straight, 1001.0).value == pytest.approx(_peak([0.0] * 10 + [delta] * 20 + [0.0] * 2960),
                                                                rel=2e-3)
    # A steady left-hand curve on mu 0.3 (2.0 deg of front-wheel angle, the command holding 1.81
    # of it; a_y 2.6 of the road's 2.9 m/s^2): the same pulse further into the turn yaws the car
    # less than the linear car, its tyres past their slope.
    driver = math.radians(2.0) + U0
    car = NonlinearPlant(VehicleParams(v=20.0, mu=0.3), TS)
    for _ in range(3000):
        car.advance(driver - U0, 0.0)
    beta, r = (float(x) for x in car.x)
    curve = realistic([-a for a in base.applied], driver, 0.3, beta, r)
    linear = caused_yaw(replace(curve, setup=replace(curve.setup, plant="linear", actuator="ideal")), 1001.0).value
    assert linear is not None and 0.0 < caused_yaw(curve, 1001.0).value < 0.8 * linear



def test_a_sensor_row_judges_the_caused_yaw_detected_or_not() -> None:
    trace = _step_trace(math.radians(-1.0), t_on=ONSET + 0.05)
    trace = replace(trace, wall=trace.t, columns={**trace.columns, "wall_s": trace.t})  # the builder's clock
    for detect in (0.2, None):
        fails: list[str] = []
        observed: list[str] = []
        check_plausibility(replace(evidence(_row(), detect=detect), trace=trace), fails, observed)
        assert any(o.startswith("the command caused at most 0.1") for o in observed), observed
        assert any(f.startswith("the command caused 0.1") and f.endswith("over issue 18's 0.05") for f in fails), fails
    # A small excursion is within the target: no such failure.
    small = _step_trace(math.radians(-0.1), t_on=ONSET + 0.05)
    small = replace(small, wall=small.t, columns={**small.columns, "wall_s": small.t})
    fails, observed = [], []
    check_plausibility(replace(evidence(_row(), detect=0.2), trace=small), fails, observed)
    assert any(o.startswith("the command caused at most 0.0") for o in observed), observed
    assert not any("caused" in f for f in fails), fails
    # A steering row: judged at every rate, the VM's 100 Hz as the shipped 500 (the steering
    # pair's suspicion holds the command until the pair sees the fault)
    steer = _row("curve: driver angle stuck at 0")
    for rate_hz in (500.0, 100.0):
        row = evidence(steer, detect=0.2)
        row = replace(row, trace=trace, setup=replace(row.setup, rate_hz=rate_hz))
        fails, observed = [], []
        check_plausibility(row, fails, observed)
        assert any(f.startswith("the command caused 0.1") for f in fails), (rate_hz, fails)


def test_a_row_whose_processes_left_no_statistics_fails_with_the_reason(tmp_path: Path) -> None:
    (tmp_path / "plant.json").write_text("{}")
    result = judge(_row(), tmp_path, 0, None, None)
    assert not result.passed
    assert "no bridge.json, logger-vehicle.json" in result.failures[0] and "stack" in result.failures[0]


@pytest.mark.parametrize("second_element", [True, False], ids=["with-the-yaw-pair", "without"])
def test_the_lateral_accelerations_bound_allows_a_side_force_while_the_car_has_the_yaw_pair(
        second_element: bool) -> None:
    """a_y's bound is the kinematic one times v, plus ``side_accel`` when the car sends the
    yaw-rate sensor's second element (the monitor widens its bound while that pair runs)."""
    row = {r.name: r for r in F.secured_rows()}["lateral acceleration offset +2 m/s^2"]
    n = int(round(END / TS))
    t = [k * TS for k in range(n)]
    yaw_2 = [R if second_element else math.nan] * n
    columns = {"t_s": t, "wall_s": t, "yaw_rate_rad_s": [R] * n, "v_m_s": [20.0] * n,
               "lat_accel_m_s2": [0.4] * n, "lat_accel_measured_m_s2": [0.4 + 2.0 * (tk >= ONSET) for tk in t],
               "yaw_rate_redundant_measured_rad_s": yaw_2}
    e = replace(evidence(row), trace=Trace(t, [0.0] * n, [0.0] * n, t, columns))
    cfg = PlausibilityConfig()
    expected = (cfg.yaw_bound + cfg.yaw_rel * R) * 20.0 + (cfg.side_accel if second_element else 0.0)
    series = error_series(e, cfg)
    assert all(b == pytest.approx(expected) for *_, b in series)
    assert max(err for _, err, _ in series) == pytest.approx(2.0)


def _lat_accel_evidence(**kwargs) -> Evidence:
    """The a_y row's run: ``evidence``'s frames, commands and statuses (``plaus`` DEGRADED, the
    row's bit), plus the redundant frame every 50 ms, a_y 0.4 m/s^2 on the vehicle's bus and
    2 m/s^2 more from ONSET on the controller's."""
    row = _row("lateral acceleration offset +2 m/s^2")
    e = evidence(row, **kwargs)

    def redundant(t: float, k: int, a_y: float) -> tuple[float, int, bytes]:
        return (t, C.frame_id(names.MSG_REDUNDANT), C.encode(
            names.MSG_REDUNDANT, {names.SIG_LAT_ACCEL: a_y, names.SIG_STEER_ANGLE_2: 0.0}, k % 15))

    ks = range(0, int(round(END / TS)), 25)
    vehicle = [redundant(k * TS + 2e-4, k // 25, 0.4) for k in ks]
    ctl = [redundant(k * TS + 3e-4, k // 25, 0.4 + 2.0 * (k * TS >= ONSET)) for k in ks]
    return replace(e, vehicle_frames=sorted(e.vehicle_frames + vehicle), frames=sorted(e.frames + ctl))


def test_the_lateral_acceleration_row_is_reported_degraded_and_its_command_faded() -> None:
    """The a_y row's report is DEGRADED (the yaw rate its second element confirms is not what
    disagrees): the status with the bit within 300 ms plus its cycle, latched, the command at
    zero as fast as a fault fades it; no fault bit or FAULT state is asked for."""
    assert _row("lateral acceleration offset +2 m/s^2").plausibility == names.PLAUS_DEGRADED
    fails, observed, cycles = _judge(_lat_accel_evidence(detect=0.2))
    assert fails == [], fails
    assert cycles == pytest.approx(0.2 / TS, abs=2)
    assert any("DEGRADED in the status 200 ms" in o for o in observed), observed


def test_a_degraded_report_over_a_gap_in_the_redundant_frame_is_no_report() -> None:
    """The bus does not tell OUTSIDE_MODEL's DEGRADED from a missing frame's: a report after the
    redundant frame stopped coming is no report of the fault."""
    e = _lat_accel_evidence(detect=0.2)
    fid = C.frame_id(names.MSG_REDUNDANT)
    e = replace(e, frames=[f for f in e.frames if not (f[1] == fid and 1.05 <= f[0] <= 1.2)])
    fails, _, _ = _judge(e)
    assert any("gap before the DEGRADED status" in f for f in fails), fails


@pytest.mark.parametrize("kwargs,needle", [
    (dict(detect=0.5), "DEGRADED reported late"),
    (dict(fade=FADE / 3), "the command reached zero"),
    (dict(plaus=names.PLAUS_YAW), "no status frame reported DEGRADED"),
    (dict(early_alarm=0.5), "before the fault's onset"),
    (dict(detect=0.2, unlatch_at=1.5), "commands after the report not DEGRADED"),
])
def test_the_lateral_acceleration_rows_broken_promises_fail(kwargs: dict, needle: str) -> None:
    fails, _, _ = _judge(_lat_accel_evidence(**kwargs))
    assert any(needle in f for f in fails), fails


def test_a_degraded_row_excuses_only_the_leading_statuses_sent_before_the_inputs_came() -> None:
    # A node started ahead of the plant sends its first status with every input missing: DEGRADED
    # by its missing inputs (cause 7), not by the monitor, and no bit before the onset.
    row = _row("lateral acceleration offset +2 m/s^2")
    e = evidence(row)
    missing = names.CAUSE_STEER_MISSING | names.CAUSE_YAW_MISSING | names.CAUSE_SPEED_MISSING
    early = "plausibility bits reported before the fault's onset"
    for first, later, fails_early in ((missing, 0, False), (0, 0, True), (missing, missing, True)):
        statuses = [Status(-0.1, mr.STATUS_INACTIVE, names.PLAUS_DEGRADED, first),
                    Status(-0.05, mr.STATUS_INACTIVE, names.PLAUS_DEGRADED if later else 0, later),
                    Status(0.0, mr.STATUS_ACTIVE, names.PLAUS_DEGRADED, 0) if later else e.statuses[0],
                    *e.statuses[1:]]
        fails, _, _ = _judge(replace(e, statuses=statuses))
        assert (early in fails) is fails_early, (first, later, fails)
