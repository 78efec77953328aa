"""The yaw-rate pair check (issue 18's decision, docs/decisions/0003-a-second-yaw-rate-element-and-the-cut.md):
the monitor compares the yaw-rate sensor's two elements over a 10 ms window, and the limiter
removes the command at once on its fault.  Synthetic inputs against the window's arithmetic,
then the closed loop of sim_plant.offline.plausibility_runs with a second element."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from firmware_py import authority as au
from firmware_py import plausibility as pl
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import SensorConfig, YawRateSensorConfig
from sim_plant.offline import plausibility_runs as pr

TS = 0.002
BOUND = pl.PlausibilityConfig().yaw_pair_bound


def _flags(differences: list[float]) -> list[int]:
    """The monitor on a straight road at 20 m/s, every input steady but the second element,
    which is the first less each difference in turn (NaN: missing)."""
    mon = pl.PlausibilityMonitor()
    out = []
    for d in differences:
        mon.step(0.0, 0.0, 0.01, 0.2, 20.0, 0.0, 0.01 - d)
        out.append(mon.state.flags & pl.CHECK_YAW_PAIR)
    return out


@pytest.mark.parametrize("d", [0.031, 0.05, 0.08, 0.2, -0.04])
def test_a_step_in_the_difference_trips_when_the_window_mean_passes_the_bound(d: float) -> None:
    # After 10 agreeing samples the window holds j + 1 samples of d at the j-th after the step:
    # its mean d (j + 1) / 5 passes the bound first at j = ceil(5 bound / |d|) - 1.
    flags = _flags([0.0] * 10 + [d] * 10)
    first = flags.index(pl.CHECK_YAW_PAIR) - 10
    assert first == math.ceil(pl.YAW_PAIR_WINDOW * BOUND / abs(d)) - 1
    assert all(flags[10 + first:])  # latched


def test_a_difference_within_the_bound_never_trips() -> None:
    assert not any(_flags([0.029, -0.029] * 500 + [0.0299] * 500))


def test_a_second_element_lost_after_it_was_received_is_degraded_and_restarts_the_window() -> None:
    mon = pl.PlausibilityMonitor()
    bits = [mon.step(0.0, 0.0, 0.01, 0.2, 20.0, 0.0, x) for x in [0.01] * 10 + [math.nan] * 3 + [0.01]]
    assert [b & pl.PLAUS_DEGRADED for b in bits] == [0] * 10 + [pl.PLAUS_DEGRADED] * 3 + [0]
    assert not mon.state.flags & pl.CHECK_YAW_PAIR  # DEGRADED, no fault: the command may stay
    # with the first element invalid too (a stale frame: step() faults on it) the loss is not DEGRADED
    assert not mon.step(0.0, 0.0, math.nan, 0.2, 20.0, 0.0, math.nan) & pl.PLAUS_DEGRADED
    # a sender without the element (SNA from the start) is never DEGRADED for it, and the next
    # ignition cycle forgets that the element was there
    for m in (pl.PlausibilityMonitor(), mon):
        pl.reset_monitor(m.state)
        assert not any(m.step(0.0, 0.0, 0.01, 0.2, 20.0, 0.0, math.nan) & pl.PLAUS_DEGRADED for _ in range(50))
    # four samples far apart after the gap: the window is not full again yet
    flags = _flags([0.0] * 10 + [math.nan] + [1.0] * 5)
    assert flags[-2] == 0 and flags[-1] == pl.CHECK_YAW_PAIR


def test_without_the_second_element_every_result_is_as_before() -> None:
    a, b = pl.PlausibilityMonitor(), pl.PlausibilityMonitor()
    rng = np.random.default_rng(3)
    for k in range(3000):
        x = (rng.normal(0, 0.02), rng.normal(0, 0.02), rng.normal(0, 0.1), rng.normal(0, 2), 20.0, 0.0)
        assert a.step(*x) == b.step(*x, math.nan)
        assert a.state.flags == b.state.flags and not a.state.flags & pl.CHECK_YAW_PAIR


def test_the_pair_fault_cuts_the_command_at_the_rate_bound() -> None:
    c = au.configure_authority(au.AuthorityConfig())
    for cut, periods in ((1, math.ceil(math.radians(3.0) / (10.0 * TS))), (0, round(3.0 / 30.0 / TS))):
        s = au.AuthorityState()
        for _ in range(50):
            au.authority_step(c, s, 1.0, 0)  # at the 3 deg limit
        u = [au.authority_step(c, s, 1.0, pl.PLAUS_YAW, cut) for _ in range(60)]
        # at zero after |u| / rate periods (one more where the float steps leave a remainder)
        assert periods - 1 <= u.index(0.0) <= periods, cut
    s = au.AuthorityState()
    au.authority_step(c, s, 0.01, 0)
    # no fault, no cut: a cut alone does not remove a command
    assert au.authority_step(c, s, 0.01, 0, 1) == pytest.approx(0.01)


def test_a_sample_over_the_hold_threshold_is_a_suspicion_for_at_most_a_window() -> None:
    # 0.025 apart: over yaw_pair_hold (0.02) in every sample, under the bound in the mean
    mon = pl.PlausibilityMonitor()
    over, clear = 0.025, 0.0
    seq = [clear] * 10 + [over] * 12 + [clear] * 4 + [-over] * 2 + [clear] * 5 + [-over] * 2
    suspect = []
    for d in seq:
        mon.step(0.0, 0.0, 0.01, 0.2, 20.0, 0.0, 0.01 - d)
        suspect.append(bool(mon.state.flags & pl.SUSPECT_YAW_PAIR))
    w = pl.YAW_PAIR_WINDOW
    # the first w samples over it, then none until w samples in a row within it re-arm it (4 do
    # not), of either sign; never latched, never a fault
    expected = [False] * 10 + [True] * w + [False] * (12 - w) + [False] * 4 + [False] * 2 + [False] * 5 + [True] * 2
    assert suspect == expected
    assert not mon.state.latched and not mon.state.bits & pl.PLAUS_FAULT


def test_a_suspicion_lets_the_law_s_command_shrink_but_not_grow() -> None:
    # The law at 20 m/s with a positive command, held while the yaw-rate error first eases
    # (the law asks for less: given), then grows and reverses (it asks for more, then for the
    # other side: refused).  Each period is compared with the same state stepped without the
    # hold: where that request lies between zero and the held command the hold changes nothing.
    import copy

    from firmware_py import model_regulator as mr
    c = mr.configure(mr.ControllerConfig())
    s = mr.State()
    mr.step(c, s, 0.0, 0.0, 20.0)
    for _ in range(20):
        mr.step(c, s, 0.0, -0.02, 20.0)  # a positive command builds
    last = s.u_prev
    assert last > math.radians(0.5)
    followed = refused = 0
    for r in [-0.015, -0.01, -0.005, 0.0, -0.03, -0.05, -0.08, 0.02, 0.05, 0.1, 0.1]:
        request = mr.step(c, copy.deepcopy(s), 0.0, r, 20.0)
        u = mr.step(c, s, 0.0, r, 20.0, True)
        assert 0.0 <= u <= last  # toward zero only, never past it
        if 0.0 <= request <= last:
            assert u == request
            followed += 1
        else:
            assert u == (last if request > last else 0.0)
            refused += 1
        last = u
    assert followed and refused and last == 0.0


def _caused(v: float, fault: SensorFault | None, second: SensorConfig | None) -> tuple[float, pr.MonitorRun]:
    """The largest |r - r of the fault-free twin| after the onset (the campaigns' twin_yaw_rate)
    in a 2 m/s^2 curve on a dry road, and the faulty run."""
    sensors = SensorConfig(seed=1, yaw_rate=YawRateSensorConfig(noise_density=0.028, bias_deg_s=0.3))
    base = replace(pr.steady_curve(v, 1.0, duration=2.0), sensors=sensors)
    twin = pr.run(base, second_yaw=second)
    hit = pr.run(base.with_sensor_faults((fault,)), second_yaw=second) if fault else twin
    k = round(1.0 / TS)
    return float(np.max(np.abs(hit.r_true[k:] - twin.r_true[k:]))), hit


@pytest.mark.parametrize("v,fault", [(40.0, SensorFault("yaw_rate", "stuck", 1.0, 0.01)),
                                     (10.0, SensorFault("yaw_rate", "scale", 1.0, 0.5))], ids=("stuck", "gain"))
def test_in_closed_loop_the_pair_keeps_the_caused_yaw_under_the_target(v: float, fault: SensorFault) -> None:
    # Issue 18's target: the faulty sensor's command causes < 0.05 rad/s.  A stuck element in the
    # 40 m/s curve is the prototype's hardest case (docs/decisions/0019-sensor-frame-layouts.md), a gain of
    # 0.5 at 10 m/s today's worst gain; the elements at the top of the campaigns' noise and
    # 0.6 deg/s apart.
    second = SensorConfig(seed=99, yaw_rate=YawRateSensorConfig(noise_density=0.028, bias_deg_s=-0.3))
    caused, run = _caused(v, fault, second)
    assert caused <= 0.05 and run.fault_time is not None and run.fault_time < 1.3
    without, _ = _caused(v, fault, None)
    assert without > 0.05  # what the pair is for: today's monitor alone lets this through


def test_in_closed_loop_the_suspicion_lowers_the_yaw_a_stuck_element_causes() -> None:
    # Stuck 0.045 rad/s above the truth in a 30 m/s curve: the filtered error ramps in, the law
    # answers it at once, and the window confirms it 10 ms later.  With the threshold at the
    # bound (the highest configure allows) the suspicion starts when one sample passes 0.03,
    # later on the ramp, and the command grows meanwhile: measured 0.0105 against 0.0144 rad/s.
    second = SensorConfig(seed=99, yaw_rate=YawRateSensorConfig(noise_density=0.028, bias_deg_s=-0.3))
    sensors = SensorConfig(seed=1, yaw_rate=YawRateSensorConfig(noise_density=0.028, bias_deg_s=0.3))
    base = replace(pr.steady_curve(30.0, 1.0, duration=2.0), sensors=sensors)
    hit = base.with_sensor_faults((SensorFault("yaw_rate", "stuck", 1.0, 2.0 / 30.0 + 0.045),))
    caused = {}
    for hold in (pl.PlausibilityConfig().yaw_pair_hold, BOUND):
        mon = pl.PlausibilityConfig(yaw_pair_hold=hold)
        twin, run = pr.run(base, second_yaw=second, monitor=mon), pr.run(hit, second_yaw=second, monitor=mon)
        k = round(1.0 / TS)
        caused[hold] = float(np.max(np.abs(run.r_true[k:] - twin.r_true[k:])))
        assert run.fault_time is not None and run.fault_time < 1.02
    assert caused[pl.PlausibilityConfig().yaw_pair_hold] < 0.8 * caused[BOUND]


def test_in_closed_loop_the_pair_raises_no_alarm_without_a_fault() -> None:
    second = SensorConfig(seed=99, yaw_rate=YawRateSensorConfig(noise_density=0.028, bias_deg_s=-0.3))
    _, run = _caused(40.0, None, second)
    assert run.report_time is None and 0.3 < run.margins["yaw_pair"] < 1.0
