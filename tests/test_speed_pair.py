"""The speed pair check (monitor check 8, docs/decisions/0006-speed-checks.md): the speed against
a second, independent speed (RedundantSensors_Speed2).  Synthetic inputs against the check's
arithmetic, then the closed loop of sim_plant.offline.plausibility_runs with the car's second
speed, on the slow speed drift in a gentle curve that no other check sees."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_py import plausibility as pl
from sim_plant.car.sensor_faults import SensorFault, parse_spec
from sim_plant.car.sensors import CHANNELS, ChannelConfig, SensorConfig, Sensors, YawRateSensorConfig
from sim_plant.judge import bounds as jb
from sim_plant.offline import plausibility_runs as pr

CFG = pl.PlausibilityConfig()
STEPS = round(CFG.speed_pair_time / CFG.ts)  # samples over the bound to trip


def _run(speeds: list[tuple[float, float]]) -> tuple[list[int], list[int]]:
    """The monitor on a straight road, every input steady but the two speeds (v, v_2) in turn;
    the flags' speed-pair bit and the returned bits per sample."""
    mon = pl.PlausibilityMonitor()
    flags, bits = [], []
    for v, v2 in speeds:
        bits.append(mon.step(0.0, 0.0, 0.0, 0.0, v, 0.0, math.nan, v2))
        flags.append(mon.state.flags & pl.CHECK_SPEED_PAIR)
    return flags, bits


@pytest.mark.parametrize("v, v2", [(20.0, 22.1), (20.0, 17.9), (10.0, 11.6), (4.0, 1.8), (30.0, 0.0)])
def test_a_difference_over_the_bound_trips_after_speed_pair_time(v: float, v2: float) -> None:
    # bound 1.0 + 0.05 min(v, v2): (20, 22.1) 2.0 against 2.1; (20, 17.9) 1.895 against 2.1;
    # (10, 11.6) 1.5 against 1.6 (the larger speed's 1.58 would not trip); 4 m/s is below
    # speed_min, where the other checks pause
    flags, bits = _run([(v, v)] * 10 + [(v, v2)] * (STEPS + 5))
    assert flags.index(pl.CHECK_SPEED_PAIR) == 10 + STEPS - 1
    assert all(flags[10 + STEPS - 1:])  # latched
    assert bits[-1] & pl.PLAUS_YAW and pl.CHECK_SPEED_PAIR & pl.CUT_CHECKS


def test_a_difference_within_the_bound_or_not_held_long_enough_never_trips() -> None:
    # over the bound for one sample less than needed, then as long within: counted down again
    brief = ([(20.0, 23.0)] * (STEPS - 1) + [(20.0, 20.0)] * (STEPS - 1)) * 5
    for speeds in ([(20.0, 21.99), (20.0, 18.1)] * 300, [(10.0, 8.6)] * 300, brief):
        flags, bits = _run(speeds)
        assert not any(flags) and not any(bits)


def test_a_second_speed_lost_after_it_was_received_is_degraded() -> None:
    flags, bits = _run([(20.0, 20.0)] * 10 + [(20.0, math.nan)] * 3 + [(20.0, 20.0)])
    assert [b & pl.PLAUS_DEGRADED for b in bits] == [0] * 10 + [pl.PLAUS_DEGRADED] * 3 + [0]
    assert not any(flags)
    # with the first speed missing too (step() faults on it) the loss is not DEGRADED
    mon = pl.PlausibilityMonitor()
    mon.step(0.0, 0.0, 0.0, 0.0, 20.0, 0.0, math.nan, 20.0)
    assert not mon.step(0.0, 0.0, 0.0, 0.0, math.nan, 0.0, math.nan, math.nan) & pl.PLAUS_DEGRADED
    # a car without the second speed (SNA from the start) is never DEGRADED for it
    assert not any(_run([(20.0, math.nan)] * 100)[1])


def test_a_second_speed_that_agrees_or_is_absent_changes_no_other_result() -> None:
    # Random inputs (speeds that jump: the jump check trips too): a monitor given no second
    # speed, one given NaN and one given an agreeing second speed report the same bits and
    # flags, and their other checks' state is the same.
    monitors = [pl.PlausibilityMonitor() for _ in range(3)]
    rng = np.random.default_rng(5)
    for _ in range(3000):
        x = (rng.normal(0, 0.02), rng.normal(0, 0.02), rng.normal(0, 0.1), rng.normal(0, 2),
             float(rng.uniform(0.0, 40.0)), 0.0, rng.normal(0, 0.1))
        bits = [monitors[0].step(*x), monitors[1].step(*x, math.nan), monitors[2].step(*x, x[4] + 0.5)]
        assert bits[0] == bits[1] == bits[2]
        assert len({m.state.flags for m in monitors}) == 1 and not monitors[2].state.flags & pl.CHECK_SPEED_PAIR
        assert len({(m.state.kin_err, m.state.model_err, m.state.turn_err) for m in monitors}) == 1
    assert monitors[2].state.speed_pair_err > 0.0 and monitors[0].state.speed_pair_err == 0.0


def _braking(decel: float, slip: float, v0: float = 25.0, periods: int = 1000, speed_every: int = 10,
             slip_from: int = 0) -> list[tuple[float, float]]:
    """A stop from v0 at ``decel`` m/s^2 whose second speed (wheel speeds) reads (1 - slip) v
    from period ``slip_from`` on: the speed frame every ``speed_every`` periods, the second
    speed every 25 (its 50 ms frame)."""
    out = []
    for k in range(periods):
        v = v0 - decel * CFG.ts * (k - k % speed_every)
        held = k - k % 25
        s = slip if held >= slip_from else 0.0
        out.append((v, round((1.0 - s) * (v0 - decel * CFG.ts * held) / 0.3) * 0.3))
    return out


@pytest.mark.parametrize("speed_every", [1, 10])
def test_braking_allows_the_wheels_slip_below_the_speed_only(speed_every: int) -> None:
    # ABS holds a braked wheel at 10-20 % slip: at 25 m/s a second speed 15 % low is 3.75 m/s off,
    # over the plain bound (1.0 + 0.05 v_2 = 2.06) and within the braking one (+ 0.25 v_2 = 6.3)
    still = [(25.0, round(0.85 * 25.0 / 0.3) * 0.3)] * 300
    assert any(_run(still)[0])  # without braking the same difference is a fault
    assert not any(_run(_braking(4.0, 0.15, speed_every=speed_every))[0])
    assert any(_run(_braking(4.0, 0.33, speed_every=speed_every))[0])  # beyond the slip ABS allows
    assert any(_run(_braking(4.0, -0.15, speed_every=speed_every))[0])  # a second speed above: no allowance


def test_the_braking_allowance_opens_at_speed_brake_decel() -> None:
    # A first-order lag follows a falling ramp (1 - alpha) a ts / alpha above it: the allowance
    # opens where that passes the same at speed_brake_decel, here a ramp in every period (the
    # slip from 0.5 s, when the lag has settled to within 10^-4 of its final value).
    slip = 0.12  # 3 m/s at 25 m/s: over the plain bound, within the braking one
    for scale, trips in ((0.95, True), (1.05, False)):
        speeds = _braking(scale * CFG.speed_brake_decel, slip, speed_every=1, periods=1500, slip_from=250)
        assert any(_run(speeds)[0]) == trips, scale
    c = pl.configure(CFG)
    assert c.speed_brake_lag == pytest.approx(CFG.speed_brake_decel * CFG.speed_brake_tau, rel=0.03)


def test_a_speed_stuck_while_the_car_brakes_is_still_found() -> None:
    # The speed held at 25 m/s while the car (and its second speed) slows at 4 m/s^2: the stuck
    # speed does not fall, so the allowance stays shut and the pair finds it once the true
    # speed is 1.0 + 0.05 v_2 below: at about 2.2 m/s, 0.55 s in, plus speed_pair_time
    speeds = [(25.0, v2) for _, v2 in _braking(4.0, 0.0)]
    flags = _run(speeds)[0]
    assert 0.5 / CFG.ts < flags.index(pl.CHECK_SPEED_PAIR) < (0.6 + CFG.speed_pair_time) / CFG.ts + 25


@pytest.mark.parametrize("field, value", [("speed_pair_bound", 0.0), ("speed_pair_time", -1.0),
                                          ("speed_pair_rel", -0.1), ("speed_pair_bound", math.inf)])
def test_a_bad_calibration_is_refused_by_name(field: str, value: float) -> None:
    from dataclasses import replace

    with pytest.raises(ValueError, match=field):
        pl.configure(replace(CFG, **{field: value}))


def test_the_second_speed_sensor_reads_the_bus_resolution_and_nan_without_one() -> None:
    s = Sensors(SensorConfig(speed_redundant=ChannelConfig(noise=0.0)), CFG.ts)
    assert s.speed_redundant(10.0) == pytest.approx(9.9)  # 0.3 m/s per LSB: 33 x 0.3
    assert math.isnan(Sensors(SensorConfig(speed_redundant_present=False), CFG.ts).speed_redundant(10.0))
    cfg = SensorConfig.from_mapping({"speed_redundant": {"noise": 0.1, "present": False}}, "test")
    assert cfg.speed_redundant == ChannelConfig(noise=0.1) and not cfg.speed_redundant_present
    # its own faults, from the command line's spec as from a scenario's table (0.3 m/s per LSB)
    stuck = SensorConfig(speed_redundant=ChannelConfig(noise=0.0), faults=(parse_spec("speed_redundant:stuck:5@0"),))
    assert Sensors(stuck, CFG.ts).speed_redundant(10.0) == pytest.approx(5.1)
    # its noise stream comes after every other: the yaw rate's second element keeps the seed's
    # child it had before (the one after the channels' and the faults'), the second speed the next
    raw = ChannelConfig(noise=1.0, quantise=False)
    bare = SensorConfig(seed=4, yaw_rate=YawRateSensorConfig(lowpass_hz=0.0, quantise=False),
                        yaw_rate_redundant=YawRateSensorConfig(lowpass_hz=0.0, quantise=False, noise_density=1.0),
                        speed_redundant=raw)
    s = Sensors(bare, CFG.ts)
    children = np.random.SeedSequence(4).spawn(len(CHANNELS) + 2)
    sigma = math.radians(1.0) * math.sqrt(0.5 / CFG.ts)
    assert s.yaw_rate_redundant(0.0) == pytest.approx(sigma * np.random.default_rng(children[-2]).standard_normal())
    assert s.speed_redundant(30.0) == pytest.approx(30.0 + np.random.default_rng(children[-1]).standard_normal())


# The case the other speed checks leave open: a falling speed reading in a curve gentler than the
# steady-turn check's turn_yaw_min (r 0.088 rad/s at 10 m/s on mu 0.3), long enough that without
# the pair the law's caused yaw passes the 0.05 rad/s target (docs/decisions/0006-speed-checks.md).
_ONSET, _RATE = 1.4, -1.0


def _drift(second_speed: bool) -> tuple[pr.MonitorRun, pr.MonitorRun]:
    clean = pr.steady_curve(10.0, 0.3, a_y=0.88, duration=9.0)
    faulty = clean.with_sensor_faults((SensorFault("speed", "drift", _ONSET, _RATE),))
    second = SensorConfig(seed=101)
    return (pr.run(clean, second_yaw=second, second_speed=second_speed),
            pr.run(faulty, second_yaw=second, second_speed=second_speed))


def test_in_closed_loop_the_pair_finds_a_slow_speed_drift_in_a_gentle_curve() -> None:
    twin, run = _drift(True)
    assert not np.any(twin.bits & (pl.PLAUS_FAULT | pl.PLAUS_DEGRADED))
    assert twin.margins["speed_pair"] < 0.5
    over = run.exceeded_time(jb.speed_pair_bound(CFG, 10.0))
    assert over is not None and run.fault_time is not None
    assert run.fault_time - over <= 0.3
    # The second speed reads 9.9 (10 m/s at 0.3 m/s per LSB), so the pair trips once
    # 9.9 - v > 1.0 + 0.05 v, at v = 8.9 / 1.05, and speed_pair_time later (+ a 20 ms speed frame)
    v_trip = (9.9 - CFG.speed_pair_bound) / (1.0 + CFG.speed_pair_rel)
    expected = _ONSET + (10.0 - v_trip) / -_RATE + CFG.speed_pair_time
    assert expected <= run.fault_time <= expected + 0.03
    caused = np.abs(run.r_true - twin.r_true)
    assert caused.max() < 0.05
    assert abs(run.aux[-1]) < 1e-9 and run.bits[-1] & pl.PLAUS_YAW  # faded (the actuator at rest) and latched


def test_without_the_pair_the_same_drift_passes_the_caused_yaw_target() -> None:
    # the reason for the pair (docs/decisions/0006-speed-checks.md): no other check sees this drift
    twin, run = _drift(False)
    assert run.report_time is None
    assert np.abs(run.r_true - twin.r_true).max() > 0.05


def _split_mu_stop(v: float, mu_right: float):
    from dataclasses import replace

    sc = pr.scn.load("split-mu").with_overrides(v=v)  # 5 m/s^2 asked: the icy side in ABS
    return replace(sc, events=tuple(replace(e, load=replace(e.load, mu_right=mu_right)) if e.load is not None
                                    else e for e in sc.events))


def test_a_split_mu_stop_s_wheel_slip_is_no_fault_with_the_braking_allowance_and_one_without() -> None:
    # The realistic car's split-mu stop at 35 m/s on 1.0 / 0.2 (3.5 m/s^2): the icy side's wheels
    # at ABS's 15 % slip, the dry side's at 2.5 %, the second speed 8.8 % (3.1 m/s) under the
    # speed, over the plain bound (1.0 + 0.05 v_2 = 2.6 m/s)
    sc = _split_mu_stop(35.0, 0.2)
    run = pr.run(sc, second_speed=True)
    assert run.report_time is None and not np.any(run.bits)
    assert 0.3 < run.margins["speed_pair"] < 1.5  # the slip seen, within the braking bound
    without = pr.run(sc, monitor=pl.PlausibilityConfig(speed_slip_rel=0.0), second_speed=True)
    assert without.report_time is not None and np.any(without.flags & pl.CHECK_SPEED_PAIR)


def braking_turn_with_a_speed_drift(second_speed: bool = True,
                                    monitor: pl.PlausibilityConfig | None = None) -> pr.MonitorRun:
    """A steady 4 m/s^2 curve at 30 m/s, the car braking at 3 m/s^2 (both sides dry) from 1.2 s
    and its speed reading drifting up at 2 m/s per s from 1.6 s: the speed pair's allowance
    holds the difference, so only the steady-turn check (7) finds the drift."""
    from dataclasses import replace

    from sim_plant.car.disturbances import SplitMuBraking

    base = pr.steady_curve(30.0, 1.0, a_y=4.0, duration=4.5)
    brake = pr.scn.Event(1.2, "split_mu_braking", 0.0, load=SplitMuBraking(t_start=1.2, mu_left=1.0, mu_right=1.0,
                                                                           deceleration=3.0, mass=base.mass))
    sc = replace(base, events=base.events + (brake,)).with_sensor_faults((SensorFault("speed", "drift", 1.6, 2.0),))
    return pr.run(sc, monitor=monitor, second_speed=second_speed)


def test_a_second_speed_within_only_the_braking_allowance_does_not_out_vote_the_turn_check() -> None:
    # An agreeing second speed out-votes check 7 (a side slip still settling); one that agrees
    # only through the slip it is allowed while braking must not, or a speed reading high by up
    # to that slip would be found by neither check.
    run = braking_turn_with_a_speed_drift()
    alone = braking_turn_with_a_speed_drift(second_speed=False)
    assert run.flags[-1] & pl.CHECK_TURN and alone.flags[-1] & pl.CHECK_TURN
    assert np.flatnonzero(run.flags & pl.CHECK_TURN)[0] == np.flatnonzero(alone.flags & pl.CHECK_TURN)[0]
    assert not run.flags[-1] & pl.CHECK_SPEED_PAIR and run.margins["speed_pair"] < 1.0  # within the allowance


def test_the_judges_braking_periods_and_their_widened_bound() -> None:
    # braking_of: the true speed falling at BRAKING_SHARE of speed_brake_decel or more in a period
    # (the monitor's 20 ms sawtooth opens the allowance in part from about 0.85 of it)
    ts, share = CFG.ts, jb.BRAKING_SHARE
    v = np.array([20.0, 20.0, 20.0 - 0.99 * share * CFG.speed_brake_decel * ts,
                  20.0 - 2.0 * share * CFG.speed_brake_decel * ts, 21.0])
    assert braking_of_list(v) == [False, False, False, True, False]
    assert jb.braking_of(np.stack([v, v], axis=1), ts, CFG)[:, 1].tolist() == braking_of_list(v)
    plain = jb.speed_pair_bound(CFG, 20.0)
    assert plain == pytest.approx(1.0 + 0.05 * 20.0 + 0.15 * 1.05)
    assert jb.speed_pair_bound(CFG, 20.0, True) == pytest.approx(plain + CFG.speed_slip_rel * 20.0)
    both = jb.speed_pair_bound(CFG, np.array([20.0, 20.0]), np.array([False, True]))
    assert both.tolist() == pytest.approx([plain, plain + CFG.speed_slip_rel * 20.0])
    assert jb.sensor_bound("speed_redundant", CFG, 0.0, 20.0, True, True, True) == pytest.approx(both[1])
    assert jb.sensor_bound("yaw_rate", CFG, 0.0, 20.0, True, True, True) == CFG.yaw_bound  # only the speeds widen


def braking_of_list(v: np.ndarray) -> list[bool]:
    return jb.braking_of(v, CFG.ts, CFG).tolist()
