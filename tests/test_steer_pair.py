"""The steering pair in closed loop (issue 18): one redundant sample over the bound trips it, and
the limiter removes the command at its rate bound, so that a driver's angle stuck at 0 in the
fault matrix's curve keeps the yaw its command causes under the target at every onset phase
(docs/decisions/0003-a-second-yaw-rate-element-and-the-cut.md)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from firmware_py import plausibility as pl
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.vehicle import VehicleParams
from sim_plant.judge.caused_yaw import CAUSED_YAW_TARGET
from sim_plant.harness.faults.settings import CURVE_SCENARIO, PLAUS_START
from sim_plant.offline import plausibility_runs as pr

#: Onsets after a redundant sample (ms): the shipped monitor's worst (2: a whole frame to wait),
#: the earlier one's (24) and the next sample at once (48).
PHASES_MS = (2, 24, 48)


def _caused(phase_ms: int, monitor: pl.PlausibilityConfig, cut: int) -> tuple[float, float | None]:
    start = PLAUS_START + phase_ms / 1000
    sc = replace(CURVE_SCENARIO, sensor_faults=(SensorFault("steer", "stuck", start, 0.0),), duration=start + 0.6)
    run = pr.run(sc, monitor=monitor, cut=cut)
    car = VehicleParams(v=sc.v, mu=sc.mu, mass=sc.mass)
    return run.caused_yaw(start, car), None if run.fault_time is None else run.fault_time - start


def test_a_stuck_driver_angle_causes_less_than_the_target_at_every_onset_phase() -> None:
    shipped = [_caused(p, pl.PlausibilityConfig(), pl.CUT_CHECKS) for p in PHASES_MS]
    for (caused, found), phase in zip(shipped, PHASES_MS):
        assert found is not None and found <= 0.050, phase  # the next redundant sample
        # the jump (1.5 deg in one sample) held the command until the pair saw it: nothing caused
        assert 0.0 <= caused <= 0.002, (phase, caused)
    # Without the suspicion the law answers the stuck angle at full speed until the pair sees it:
    # the worst phase waits 48 ms, and the command's yaw is over the target (docs/decisions/0004-suspicions-hold-the-law.md).
    unheld = [_caused(p, pl.PlausibilityConfig(steer_jump=1e3), pl.CUT_CHECKS)[0] for p in PHASES_MS]
    assert 0.02 < max(unheld) <= CAUSED_YAW_TARGET
    # What the shipped settings are for: three samples and the 30 deg/s fault fade miss it.
    earlier = [_caused(p, pl.PlausibilityConfig(steer_count=3, steer_jump=1e3), pl.CHECK_YAW_PAIR)[0]
               for p in PHASES_MS]
    assert max(earlier) > CAUSED_YAW_TARGET


def test_the_worst_case_the_pair_alone_left_is_held_at_every_phase() -> None:
    # 10 m/s on mu 1: the curve needs 3.1 deg of wheel, and that angle stuck at 0 and found a
    # frame late caused 0.055 rad/s without the suspicion (docs/decisions/0004-suspicions-hold-the-law.md)
    worst = {}
    for steer_jump in (0.015, 1e3):
        caused = []
        for phase_ms in range(2, 50, 6):
            start = 1.4 + phase_ms / 1000
            sc = replace(pr.steady_curve(10.0, 1.0, duration=start + 0.5),
                         sensor_faults=(SensorFault("steer", "stuck", start, 0.0),))
            run = pr.run(sc, monitor=pl.PlausibilityConfig(steer_jump=steer_jump))
            caused.append(run.caused_yaw(start, VehicleParams(v=sc.v, mu=sc.mu, mass=sc.mass)))
        worst[steer_jump] = max(caused)
    assert worst[0.015] < 0.005 and worst[1e3] > CAUSED_YAW_TARGET


def _step_monitor(rows: list[tuple[float, float]]) -> list[int]:
    """The flags per sample for (driver angle, second channel) rows on a straight road at 20 m/s."""
    c, s = pl.configure(pl.PlausibilityConfig()), pl.MonitorState()
    out = []
    for k, (d, d2) in enumerate(rows):
        lat = 0.01 * (k // 25)  # a new redundant sample every 25 periods (its a_y changes)
        pl.monitor_step(c, s, d, d2, 0.0, lat, 20.0, 0.0)
        out.append(s.flags)
    return out


def test_a_jump_no_hand_makes_holds_the_command_until_the_pair_judges_it() -> None:
    jump = pl.PlausibilityConfig().steer_jump
    # the driver's angle jumps by more than steer_jump at period 60, between the redundant
    # samples at 50 and 75: the suspicion holds from 60 to 74, the pair judges at 75
    rows = [(0.0, 0.0)] * 60 + [(1.5 * jump, 0.0)] * 60
    held = [k for k, f in enumerate(_step_monitor(rows)) if f & pl.SUSPECT_STEER_JUMP]
    assert held == list(range(60, 75))
    # the pair at 75 saw the channels apart by 1.5 steer_jump (over steer_bound): a fault
    assert _step_monitor(rows)[75] & pl.CHECK_STEER_PAIR
    # a hand's pace (just under steer_jump a sample) and a jump on a redundant sample's period
    # (the pair judges it there) hold nothing
    ramp = [(0.99 * jump * min(k, 10), 0.99 * jump * min(k, 10)) for k in range(120)]
    assert not any(f & pl.SUSPECT_STEER_JUMP for f in _step_monitor(ramp))
    on_sample = [(0.0, 0.0)] * 75 + [(2.0 * jump, 2.0 * jump)] * 45
    assert not any(f & pl.SUSPECT_STEER_JUMP for f in _step_monitor(on_sample))
    # without the second channel there is no pair to judge it, so no suspicion
    lost = [(d, math.nan) for d, _ in rows]
    assert not any(f & pl.SUSPECT_STEER_JUMP for f in _step_monitor(lost))


def test_the_steering_suspicion_ends_by_kin_gap_without_a_new_redundant_sample() -> None:
    c, s = pl.configure(pl.PlausibilityConfig()), pl.MonitorState()
    jump = pl.PlausibilityConfig().steer_jump
    flags = []
    for k in range(200):  # the redundant frame's values never change after the first sample
        pl.monitor_step(c, s, 2.0 * jump if k >= 10 else 0.0, 0.0, 0.0, 0.2, 20.0, 0.0)
        flags.append(s.flags)
    held = [k for k, f in enumerate(flags) if f & pl.SUSPECT_STEER_JUMP]
    assert held == list(range(10, 10 + c.kin_gap_steps))


@pytest.mark.parametrize("cut", [pl.CUT_CHECKS, 0])
def test_the_cut_removes_a_steering_fault_command_at_the_rate_bound(cut: int) -> None:
    start = PLAUS_START + 0.002  # a frame to wait
    sc = replace(CURVE_SCENARIO, sensor_faults=(SensorFault("steer", "stuck", start, 0.0),), duration=start + 0.6)
    # (without the jump's suspicion, which would hold the command it measures the cut on at 0)
    run = pr.run(sc, monitor=pl.PlausibilityConfig(steer_jump=1e3), cut=cut)
    k = int(round(run.fault_time / 0.002))
    at_fault = abs(float(run.aux[k]))
    periods_to_zero = next(i for i, a in enumerate(run.aux[k:]) if a == 0.0)
    # rate_max 10 rad/s moves 0.02 rad a period; the fault fade 30 deg/s 0.001 rad
    expected = at_fault / (0.02 if cut else 0.001047)
    assert at_fault > 0.01 and periods_to_zero == pytest.approx(expected, abs=2)
