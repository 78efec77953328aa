"""The plausibility monitor and the authority limiter (firmware_py.plausibility): each check on
synthetic inputs, then offline in closed loop on the realistic car (sim_plant.offline
.plausibility_runs): faults found within 300 ms of their error staying over the bound, no alarm
in the fault-free scenarios."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from firmware_py import model_regulator as mr
from firmware_py import authority as au
from firmware_py import plausibility as pl
from mrsteer_dbc import names
from sim_plant.campaign import params
from sim_plant.car import scenario as scn
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import SensorConfig, YawRateSensorConfig
from sim_plant.judge import bounds as jb
from sim_plant.offline import plausibility_runs as pr

TS = 0.002
D = math.radians
#: The law in the loop: the shipped (issue 15's scheduled) calibration.
LAW = mr.ControllerConfig()


def test_bits_are_the_dbc_names() -> None:
    assert (pl.PLAUS_YAW, pl.PLAUS_STEER, pl.PLAUS_DEGRADED) == (names.PLAUS_YAW, names.PLAUS_STEER,
                                                                  names.PLAUS_DEGRADED)
    assert pl.YAW_CHECKS & pl.STEER_CHECKS == 0 and (pl.YAW_CHECKS | pl.STEER_CHECKS | pl.MISSING) == 0x17FF
    assert (pl.NOMINAL_L_F, pl.NOMINAL_L_R, pl.NOMINAL_MASS, pl.NOMINAL_C_F, pl.NOMINAL_C_R) == (
        mr.NOMINAL_L_F, mr.NOMINAL_L_R, mr.NOMINAL_MASS, mr.NOMINAL_C_F, mr.NOMINAL_C_R)


def _straight(mon: pl.PlausibilityMonitor, n: int, k0: int = 0, *, yaw=lambda k: 0.0, lat=lambda k: 0.0,
              steer=lambda k: 0.0, steer2=None, v: float = 20.0) -> list[int]:
    """n periods; the redundant frame (a_y, second angle) new every 25th period with a little
    noise on it, as a real sensor's LSB toggles."""
    out, held = [], (0.0, 0.0)
    steer2 = steer2 or steer
    for k in range(k0, k0 + n):
        if k % 25 == 0:
            held = (lat(k) + 1e-3 * ((k // 25) % 3 - 1), steer2(k) + 2.5e-5 * ((k // 25) % 2))
        out.append(mon.step(steer(k), held[1], yaw(k), held[0], v, 0.0))
    return out


def test_fault_free_straight_driving_is_quiet_and_a_yaw_bias_trips_the_kinematic_check() -> None:
    mon = pl.PlausibilityMonitor()
    assert set(_straight(mon, 1000)) == {0}
    bits = _straight(mon, 500, 1000, yaw=lambda k: 0.05)  # 2.9 deg/s while a_y says 0
    first = bits.index(pl.PLAUS_YAW)
    assert first * TS <= 0.3 and mon.state.flags & pl.CHECK_KINEMATIC
    assert set(bits[first:]) == {pl.PLAUS_YAW}  # latched
    pl.reset_monitor(mon.state)
    assert set(_straight(mon, 300, yaw=lambda k: 0.0)) == {0}


def _first_fault_with_a_gap(gap: range) -> int:
    """Periods from a 2.9 deg/s yaw-rate bias's onset (after 1000 clean ones) to PLAUS_YAW, with
    the redundant pair missing (NaN: withheld or lost) over ``gap`` (periods from the onset)."""
    mon = pl.PlausibilityMonitor()
    _straight(mon, 1000)
    held = (0.0, 0.0)
    for k in range(1000, 1600):
        if k % 25 == 0:
            held = (1e-3 * ((k // 25) % 3 - 1), 2.5e-5 * ((k // 25) % 2))
        lat, d2 = (math.nan, math.nan) if k - 1000 in gap else held
        if mon.step(0.0, d2, 0.05, lat, 20.0, 0.0) & pl.PLAUS_YAW:
            return k - 1000
    raise AssertionError("no fault")


def test_one_missing_redundant_sample_keeps_the_kinematic_window_and_a_long_gap_restarts_it() -> None:
    # The node withholds a sample that came off time (a stalled plant): that must cost the
    # detection that one sample (the next one's interval spans the gap, as for a lost frame),
    # not the 200 ms of a window refilled from nothing.
    clean = _first_fault_with_a_gap(range(0))
    one = _first_fault_with_a_gap(range(25, 50))  # the second sample after the onset
    assert clean < one <= clean + 25
    gap = round(pl.PlausibilityConfig().kin_gap / TS)
    long = _first_fault_with_a_gap(range(25, 25 + gap + 25))
    assert long >= 25 + gap + 25 + pl.KIN_WINDOW * 25  # restarted: a full window after the gap


def test_the_two_steering_channels_disagreeing_trips_the_pair_check() -> None:
    mon = pl.PlausibilityMonitor()
    bits = _straight(mon, 400, steer=lambda k: 0.01, steer2=lambda k: 0.01 - 0.006 * (k >= 110),
                     yaw=lambda k: 0.06, lat=lambda k: 1.2)
    # one redundant sample over the bound trips (steer_count 1): the first after the onset
    assert bits.index(pl.PLAUS_STEER) == 125 and mon.state.flags & pl.CHECK_STEER_PAIR
    assert mon.state.flags & pl.YAW_CHECKS == 0
    assert mon.state.flags & pl.CUT_CHECKS == pl.CHECK_STEER_PAIR  # the node cuts the command on it
    within = pl.PlausibilityMonitor()  # 0.0035 rad apart, under the 0.004 bound: never the pair
    _straight(within, 400, steer=lambda k: 0.01, steer2=lambda k: 0.01 - 0.0035 * (k >= 110),
              yaw=lambda k: 0.06, lat=lambda k: 1.2)
    assert within.state.pair_count == 0 and not within.state.flags & pl.CHECK_STEER_PAIR


def test_a_frozen_value_trips_once_its_partner_moves() -> None:
    mon = pl.PlausibilityMonitor()
    # the yaw rate stops changing at 0.1 s; a_y / v moves from 0 to 0.1 rad/s from 0.3 s
    yaw = lambda k: 1e-4 * (k % 7) if k < 50 else 6e-4  # noqa: E731
    lat = lambda k: 0.0 if k < 150 else min(2.0, (k - 150) * 0.02)  # noqa: E731
    bits = _straight(mon, 600, yaw=yaw, lat=lat)
    assert mon.state.flags & pl.FROZEN_YAW
    assert bits.index(pl.PLAUS_YAW) * TS > 0.3  # not before the partner moved
    # a held wheel (exactly constant, ideal sensor) while the car yaws is not frozen: the partner is steady
    quiet = pl.PlausibilityMonitor()
    assert set(_straight(quiet, 1000, steer=lambda k: 0.02, yaw=lambda k: 0.12, lat=lambda k: 2.4)) == {0}


def test_missing_redundancy_is_degraded_and_slow_or_invalid_inputs_pause_the_checks() -> None:
    mon = pl.PlausibilityMonitor()
    assert mon.step(0.0, math.nan, 0.0, math.nan, 20.0, 0.0) == pl.PLAUS_DEGRADED
    assert mon.step(0.0, 0.0, 0.0, 0.0, 20.0, 0.0) == 0  # not latched
    for v in (2.0, math.nan):
        mon = pl.PlausibilityMonitor()
        # a huge yaw-rate error, but below speed_min (or no speed): nothing is judged
        assert set(_straight(mon, 500, yaw=lambda k: 0.5, v=v)) == {0}
    mon = pl.PlausibilityMonitor()
    assert mon.step(math.inf, 0.0, 0.0, 0.0, 20.0, 0.0) == 0


def test_the_model_check_is_wide_and_one_sided_enough_for_low_mu() -> None:
    mon = pl.PlausibilityMonitor()
    # the steering asks for 0.2 rad/s (nominal car); a low-mu car yaws only 0.05: fine
    kn = 20.0 / (pl.configure(pl.PlausibilityConfig()).wheelbase + pl.configure(pl.PlausibilityConfig()).k_us * 400.0)
    delta = 0.2 / kn
    for k in range(1000):
        assert mon.step(delta, delta, 0.05, 1.0, 20.0, 0.0) & pl.PLAUS_FAULT == 0 or k < 0
    assert mon.state.flags & pl.CHECK_MODEL == 0
    # yawing 0.6 rad/s on a straight wheel, a_y missing (degraded): the model check alone trips
    mon = pl.PlausibilityMonitor()
    bits = [mon.step(0.0, math.nan, 0.6, math.nan, 20.0, 0.0) for _ in range(200)]
    assert bits[-1] == pl.PLAUS_YAW | pl.PLAUS_DEGRADED and mon.state.flags & pl.CHECK_MODEL


def _speeds(mon: pl.PlausibilityMonitor, speeds: list[float]) -> list[int]:
    """Straight driving at each speed in turn, one value per period (the node holds a 20 ms
    frame's value ten periods)."""
    return [mon.step(0.0, 0.0, 0.0, 0.0, v, 0.0) for v in speeds]


def test_a_speed_that_jumps_is_a_fault_but_hard_braking_and_a_missing_speed_are_not() -> None:
    step = pl.PlausibilityConfig().speed_step
    braking = [30.0 - 10.0 * 0.02 * (k // 10) for k in range(1000)]  # 10 m/s^2 in 20 ms frames
    mon = pl.PlausibilityMonitor()
    assert set(_speeds(mon, braking)) == {0} and not mon.state.flags & pl.CHECK_SPEED
    # a sensor stuck at another value: the jump, however few periods it lasts
    mon = pl.PlausibilityMonitor()
    bits = _speeds(mon, [20.0] * 50 + [20.0 + 1.01 * step] + [20.0] * 50)
    assert bits[49] == 0 and set(bits[50:]) == {pl.PLAUS_YAW} and mon.state.flags & pl.CHECK_SPEED
    assert mon.state.flags & pl.CUT_CHECKS  # the limiter removes the command, not fades it
    mon = pl.PlausibilityMonitor()
    assert set(_speeds(mon, [20.0] * 50 + [20.0 + 0.99 * step] * 50)) == {0}
    # a jump below speed_min, where the other checks pause, is found too
    mon = pl.PlausibilityMonitor()
    assert _speeds(mon, [20.0] * 50 + [3.0])[-1] == pl.PLAUS_YAW
    # a speed missing for a while (NaN: the node's freshness) comes back wherever the car is
    mon = pl.PlausibilityMonitor()
    assert set(_speeds(mon, [20.0] * 50 + [math.nan] * 50 + [16.0] * 50)) == {0}


def test_bad_calibrations_are_refused() -> None:
    for bad in ({"yaw_bound": 0.0}, {"yaw_count": 0}, {"yaw_count": 2.5}, {"model_rel": -1.0}, {"ts": math.nan},
                {"mu_min": 0.0}, {"mu_min": 1.5}, {"actuator_tau": 0.0}, {"sensor_tau": -0.001},
                {"speed_step": 0.0}, {"side_accel": -0.1}, {"side_accel": math.inf}, {"turn_yaw_min": 0.0},
                {"turn_lat_rel": -0.1}, {"turn_lat_bias": math.nan}, {"turn_speed_rel": 0.0},
                {"turn_yaw_tol": 0.2}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            pl.configure(replace(pl.PlausibilityConfig(), **bad))
    with pytest.raises(ValueError, match="rate_max"):
        au.configure_authority(replace(au.AuthorityConfig(), rate_max=-1.0))


# ------------------------------------------------------------------ authority limiter

def test_authority_bounds_magnitude_and_rate_and_fades_on_a_fault() -> None:
    c, s = au.configure_authority(au.AuthorityConfig()), au.AuthorityState()
    u = [au.authority_step(c, s, 0.1, 0) for _ in range(30)]
    assert u[0] == pytest.approx(10.0 * TS) and s.flags == au.AUTH_MAGNITUDE  # rate, then the range
    assert max(u) == pytest.approx(D(3.0))
    u = [au.authority_step(c, s, 0.04, pl.PLAUS_YAW) for _ in range(20)]
    # a fault's command is wrong: it fades at 30 deg/s (3 deg in 0.1 s), five times the hand-back's 6
    assert u[0] == pytest.approx(D(3.0) - D(30.0) * TS) and s.flags == au.AUTH_FAULT
    assert u[-1] == pytest.approx(D(3.0) - 20 * D(30.0) * TS)
    assert au.authority_step(c, s, math.nan, 0) == pytest.approx(u[-1] - D(30.0) * TS)  # a non-finite request too
    assert [au.authority_step(c, s, 0.04, pl.PLAUS_STEER) for _ in range(31)][-1] == 0.0


def test_authority_ends_an_intervention_at_the_panic_window_only_when_degraded() -> None:
    c, s = au.configure_authority(au.AuthorityConfig()), au.AuthorityState()
    window = round(2.0 / TS)
    u = [au.authority_step(c, s, 0.02, 0) for _ in range(window + 500)]
    assert u[-1] == pytest.approx(0.02)  # consistent inputs: no time limit
    u = [au.authority_step(c, s, 0.02, pl.PLAUS_DEGRADED) for _ in range(500)]
    assert s.flags == au.AUTH_TIME and u[-1] == 0.0 and u[0] == pytest.approx(0.02 - D(6.0) * TS)
    s2 = au.AuthorityState()
    u = [au.authority_step(c, s2, 0.02, pl.PLAUS_DEGRADED) for _ in range(window + 200)]
    assert u[window - 1] == pytest.approx(0.02) and u[-1] < 0.02  # the window, then the fade
    rest = [au.authority_step(c, s2, 0.0, pl.PLAUS_DEGRADED) for _ in range(round(1.0 / TS) + 1000)]
    assert rest[-1] == 0.0 and s2.engaged == 0  # re-armed after 1 s at rest
    assert au.authority_step(c, s2, 0.01, pl.PLAUS_DEGRADED) > 0.0


def test_a_request_the_time_rule_faded_does_not_re_arm_the_window() -> None:
    # The faded command rests, but the law still asks: no fresh window until it lets go.
    c, s = au.configure_authority(au.AuthorityConfig()), au.AuthorityState()
    window, rearm = round(2.0 / TS), round(1.0 / TS)
    u = [au.authority_step(c, s, 0.02, pl.PLAUS_DEGRADED) for _ in range(window + 10 * rearm)]
    faded = u.index(0.0)
    assert window < faded < window + rearm and set(u[faded:]) == {0.0} and s.flags == au.AUTH_TIME
    rest = [au.authority_step(c, s, 0.0, pl.PLAUS_DEGRADED) for _ in range(rearm)]
    assert s.engaged == 0 and rest[-1] == 0.0  # the law at rest for rearm_time: the window starts afresh
    assert au.authority_step(c, s, 0.02, pl.PLAUS_DEGRADED) > 0.0


# ------------------------------------------------------------------ offline, closed loop

FAULT_FREE = [("split-mu", 0), ("split-mu", 1), ("side-wind", 0), ("side-wind", 2), ("blow-out", 1),
              ("paper-fig8", 0), ("paper-fig9", 0), ("handover", 0)]


@pytest.mark.parametrize("name, seed", FAULT_FREE, ids=[f"{n}-{s}" for n, s in FAULT_FREE])
def test_no_false_alarm_in_the_fault_free_scenarios(name: str, seed: int) -> None:
    sc = scn.load(name)
    if not sc.sensors.exact:
        sc = replace(sc, sensors=replace(sc.sensors, seed=seed))
    r = pr.run(sc, controller=LAW)
    assert r.fault_time is None and r.bits.max() == 0
    assert max(r.margins.values()) < 0.9  # every residual stayed below 90 % of its bound


@pytest.mark.parametrize("name, v, mu", [("paper-fig8", 15.0, 0.5), ("paper-fig9", 20.0, 0.3)])
def test_a_realistic_car_past_its_grip_is_degraded_not_a_sensor_fault(name: str, v: float, mu: float) -> None:
    """The paper's Figure 8 (the wheel turned for a dry-road yaw rate of 1 rad/s: 15 m/s^2 of
    a_y at 15 m/s, three times what mu 0.5 gives) and Figure 9 (4000 Nm on mu 0.3) on the
    realistic car, fault-free: it slides past its grip (side slip beyond 20 deg), where a_y / v
    and the nominal car part from the yaw rate.  With the yaw rate's second element confirming
    the yaw rate that is DEGRADED (OUTSIDE_MODEL), never a sensor's fault bit, and the command
    fades; without the element the same run is the yaw rate's fault, as before (the monitor
    cannot tell the car from the sensor)."""
    sc = scn.load(name).with_overrides(v=v, mu=mu).with_models(plant="nonlinear", actuator="default",
                                                                sensors="default")
    r = pr.run(sc, controller=LAW, second_yaw=sc.sensor_config, second_speed=True)
    assert np.degrees(np.abs(r.beta).max()) > 20.0
    assert r.fault_time is None and r.report_time is not None
    k = int(round(r.report_time / TS))
    assert set(np.unique(r.bits[k:])) == {pl.PLAUS_DEGRADED}
    assert np.abs(r.aux[k + 200:]).max() < 1e-5  # faded (3 deg at 30 deg/s is 100 ms) and held at zero
    alone = pr.run(sc, controller=LAW, second_speed=True)
    assert alone.fault_time is not None and alone.bits.max() & pl.PLAUS_YAW


@pytest.mark.parametrize("v, mu", [(10.0, 0.3), (20.0, 0.6), (40.0, 1.0)])
def test_no_false_alarm_steering_into_a_curve(v: float, mu: float) -> None:
    r = pr.run(pr.steady_curve(v, mu, duration=2.0), controller=LAW)
    assert r.report_time is None


@pytest.mark.parametrize("v, mu, a_y", [(10.0, 1.0, 3.4), (10.0, 0.7, 2.4), (25.0, 1.0, 4.9)])
def test_a_steering_step_is_no_yaw_rate_error_whatever_the_sensors_lag(v: float, mu: float, a_y: float) -> None:
    """The wheel turned in one period into a curve (the scenario files' ``steer`` event). The
    filtered a_y shows the step a few ms after the nominal car's beta does; without the family
    of sensor lags (``sensor_tau``) the kinematic check took that for a yaw-rate error here
    (1.2-2.4 times its bound); with it the residual stays under 90 % of the bound."""
    sc = pr.steady_curve(v, mu, a_y=a_y, ramp=0.0, duration=2.0, seed=3)
    r = pr.run(sc, controller=LAW)
    assert r.report_time is None and r.margins["kinematic"] < 0.9
    no_lag = pr.run(sc, monitor=pl.PlausibilityConfig(sensor_tau=1e-9), controller=LAW)
    assert no_lag.fault_time is not None and no_lag.margins["kinematic"] > 1.0


def test_the_family_of_sensor_lags_keeps_unfiltered_sensors_as_quiet() -> None:
    """The paper's step (Figure 8) on exact sensors, at 10-40 m/s: the lagged end of the family
    is the wrong one there, and the residual is no larger than without the family."""
    for v in (10.0, 20.0, 30.0, 40.0):
        sc = replace(scn.load("paper-fig8"), v=v)
        with_family = pr.run(sc, controller=LAW).margins["kinematic"]
        without = pr.run(sc, monitor=pl.PlausibilityConfig(sensor_tau=1e-9), controller=LAW).margins["kinematic"]
        assert with_family <= without + 1e-12 and with_family < 0.5


#: The yaw-rate sensor's second element, as the plant sends it (its own noise stream).
SECOND = replace(scn.load("side-wind").sensors, seed=101)


@pytest.mark.parametrize("v, mu", [(10.0, 0.3), (10.0, 0.7), (12.5, 0.5), (15.0, 0.3)])
def test_a_side_wind_gust_at_low_speed_is_no_sensor_fault_while_the_yaw_pair_runs(v: float, mu: float) -> None:
    """The built-in 1500 N gust at 10-15 m/s: its side force is an a_y no nominal car has, and
    without the second yaw-rate element (the kinematic check alone watching the yaw rate) it
    trips the check; with it the bound allows ``side_accel`` / v and the residual stays under
    90 % of the bound."""
    sc = replace(scn.load("side-wind"), v=v, mu=mu)
    alone = pr.run(sc, controller=LAW)
    assert alone.fault_time is not None and alone.margins["kinematic"] > 1.0
    paired = pr.run(sc, controller=LAW, second_yaw=SECOND)
    assert paired.fault_time is None and paired.bits.max() == 0 and paired.margins["kinematic"] < 0.9


@pytest.mark.parametrize("v, mu, kind, value, a_y", [(10.0, 1.0, "bias", 1.5, 2.0), (40.0, 0.3, "bias", -2.5, 0.0),
                                                     (20.0, 1.0, "scale", 0.5, 4.0), (10.0, 0.3, "stuck", 3.0, 0.0)])
def test_an_a_y_fault_over_the_widened_bound_is_still_reported_within_300_ms(v: float, mu: float, kind: str,
                                                                            value: float, a_y: float) -> None:
    """With the yaw-rate pair running the kinematic check is the lateral acceleration's, and its
    bound ``error_bound`` states (``side_accel`` more than without the pair): a fault whose
    error passes it is reported within 300 ms of that, as DEGRADED (the yaw rate its second
    element confirms is not what is wrong: OUTSIDE_MODEL), and the command fades as on a fault."""
    sc = pr.steady_curve(v, mu, a_y=a_y, duration=3.0).with_sensor_faults((SensorFault("lat_accel", kind, 1.4, value),))
    cfg = pl.PlausibilityConfig()
    r = pr.run(sc, controller=LAW, second_yaw=SECOND)
    bound = pr.error_bound("lat_accel", cfg, r)
    assert bound[-1] == pytest.approx((cfg.yaw_bound + cfg.yaw_rel * abs(r.r_true[-1])) * v + cfg.side_accel)
    exceeded = r.exceeded_time(bound)
    assert exceeded is not None and r.report_time is not None and 0.0 <= r.report_time - exceeded <= 0.3
    k = int(round(r.report_time / TS))
    assert r.bits[k] == pl.PLAUS_DEGRADED  # not the yaw rate's fault bit
    fade = int(abs(r.aux[k]) / (math.radians(30.0) * TS)) + 2  # the fault fade rate's periods
    assert np.abs(r.aux[k + fade + 100:]).max() < 1e-5  # the applied angle, the actuator's lag after the command


@pytest.mark.parametrize("v, mu, value, a_y, duration", [(20.0, 0.6, -0.4, 0.0, 4.7), (15.0, 1.0, 0.3, 1.5, 5.7)])
def test_an_a_y_drift_is_reported_within_300_ms_of_passing_the_bound_of_the_true_turn(
        v: float, mu: float, value: float, a_y: float, duration: float) -> None:
    """The kinematic bound's relative part is taken on the smaller of |a_y / v| and |r|: a drift
    of a_y (m/s^2 per s, about the issue's 1 deg/s per s of yaw rate at these speeds) whose own
    reading widened its bound was reported 0.49 and 0.60 s after its error passed the bound of
    the true turn (``error_bound``), which the verdicts judge it by."""
    sc = pr.steady_curve(v, mu, a_y=a_y, duration=duration).with_sensor_faults(
        (SensorFault("lat_accel", "drift", 1.0, value),))
    r = pr.run(sc, controller=LAW, second_yaw=SECOND, second_speed=True)
    exceeded = r.exceeded_time(pr.error_bound("lat_accel", pl.PlausibilityConfig(), r))
    assert exceeded is not None and exceeded > 3.0  # a slow drift: its error passes the bound seconds after onset
    assert r.report_time is not None and r.report_time - exceeded <= 0.3


def test_an_a_y_drift_against_a_yaw_rate_bias_is_judged_by_the_residual_its_check_sees() -> None:
    """A yaw-rate bias of +0.3 deg/s (a healthy sensor's, as the campaigns sample it) hides
    b_r v = 0.079 m/s^2 of a +0.25 m/s^2-per-s a_y drift from the kinematic check at 15 m/s, so
    the check's residual passes its bound 0.31 s after the fault's own error does.  The judges
    count from the residual (``check_offset``): the report is within 300 ms of that, and was
    0.36 s after the fault's own error passed the bound."""
    bias, drift, onset, v = 0.3, 0.25, 1.0, 15.0
    sc = pr.steady_curve(v, 0.75, a_y=0.0, duration=6.5)
    sc = replace(sc, sensors=replace(sc.sensors, yaw_rate=replace(sc.sensors.yaw_rate, bias_deg_s=bias)))
    r = pr.run(sc.with_sensor_faults((SensorFault("lat_accel", "drift", onset, drift),)), controller=LAW,
               second_yaw=SECOND, second_speed=True)
    bound = pr.error_bound("lat_accel", pl.PlausibilityConfig(), r)
    exceeded = r.exceeded_time(bound)
    # the drift's own error d (t - onset) less b_r v passes the bound (the car nearly straight)
    hidden = math.radians(bias) * v
    assert exceeded == pytest.approx(onset + (bound[-1] + hidden) / drift, abs=0.06)
    assert r.report_time is not None and 0.0 <= r.report_time - exceeded <= 0.3
    assert r.report_time - (onset + bound[-1] / drift) > 0.3  # late, counted from the fault's own error


def test_the_healthy_offsets_a_check_sees_with_a_fault() -> None:
    """``check_offset``: the kinematic residual a_y - v r and the pair's r_2 - r, in the faulted
    sensor's units; per row with arrays; nothing for the channels without a modelled offset."""
    import numpy as np

    bias = {"yaw_rate": 0.004, "lat_accel": 0.1, "yaw_rate_redundant": -0.001}
    assert jb.check_offset("lat_accel", bias, 20.0, True) == pytest.approx(0.1 - 0.004 * 20.0)
    assert jb.check_offset("yaw_rate", bias, 20.0, True) == pytest.approx(0.004 - 0.1 / 20.0)
    assert jb.check_offset("yaw_rate", bias, 20.0, True, by_pair=True) == pytest.approx(0.004 + 0.001)
    assert jb.check_offset("yaw_rate_redundant", bias, 20.0, True) == pytest.approx(-0.001 - 0.004)
    for sensor in ("steer", "steer_redundant", "speed", "speed_redundant"):
        assert jb.check_offset(sensor, bias, 20.0, True) == 0.0
    rows = {"yaw_rate": np.array([0.004, -0.002]), "lat_accel": 0.0}
    assert jb.check_offset("lat_accel", rows, np.array([10.0, 30.0]), True) == pytest.approx([-0.04, 0.06])
    assert jb.check_offset("lat_accel", {}, 30.0, True) == 0.0  # no offsets given: none
    # none before the fault's onset, a bool or one per row
    assert jb.check_offset("lat_accel", bias, 20.0, False) == 0.0
    assert jb.check_offset("lat_accel", rows, np.array([10.0, 30.0]), np.array([False, True])) == pytest.approx(
        [0.0, 0.06])
    # the sensors' own: SI, and none on exact sensors, which add no bias
    cfg = SensorConfig(yaw_rate=YawRateSensorConfig(bias_deg_s=0.3))
    assert cfg.biases() == {"yaw_rate": pytest.approx(math.radians(0.3)), "lat_accel": 0.0, "yaw_rate_redundant": 0.0}
    assert set(replace(cfg, exact=True).biases().values()) == {0.0}


def test_the_error_bound_every_verdict_uses_is_one_formula_on_floats_and_arrays() -> None:
    """``sensor_bound`` is the bound the offline runs, the fault matrix, the HIL summary and the
    campaign judge a sensor's error against: the kinematic residual (yaw rate; a_y the same in
    m/s^2, plus the side force's allowance only while the pair runs), the steering channels' and
    the second element's fixed bounds, the speed pair's for either speed on a car with the second
    speed and none without it; an array per row gives each row's float."""
    import numpy as np

    cfg = pl.PlausibilityConfig()
    assert jb.sensor_bound("yaw_rate", cfg, -0.2, 20.0, True) == pytest.approx(0.035 + 0.1 * 0.2)
    assert jb.sensor_bound("lat_accel", cfg, 0.2, 20.0, False) == pytest.approx((0.035 + 0.1 * 0.2) * 20.0)
    assert jb.sensor_bound("lat_accel", cfg, 0.2, 20.0, True) == pytest.approx((0.035 + 0.02) * 20.0 + 0.6)
    assert jb.sensor_bound("steer_redundant", cfg, 0.2, 20.0, True) == cfg.steer_bound == jb.sensor_bound(
        "steer", cfg, 0.0, 5.0, False)
    assert jb.sensor_bound("yaw_rate_redundant", cfg, 0.5, 40.0, False) == cfg.yaw_pair_bound
    with pytest.raises(ValueError, match="without the second speed"):
        jb.sensor_bound("speed", cfg, 0.0, 20.0, True)
    # with the second speed either speed's is the pair's at the true speed, plus half the
    # second speed's 0.3 m/s LSB with its share of the relative term
    for sensor in ("speed", "speed_redundant"):
        assert jb.sensor_bound(sensor, cfg, 0.4, 20.0, False, speed_pair=True) == pytest.approx(
            1.0 + 0.05 * 20.0 + 0.15 * 1.05)
    r, v, pair = np.array([-0.3, 0.0, 0.1, 0.1]), np.array([10.0, 25.0, 40.0, 4.9]), np.array([True, False, True, True])
    for sensor in ("yaw_rate", "lat_accel", "speed", "steer", "yaw_rate_redundant"):
        rows = jb.sensor_bound(sensor, cfg, r, v, pair, speed_pair=True)
        assert rows.tolist() == [jb.sensor_bound(sensor, cfg, float(a), float(b), bool(c), True)
                                 for a, b, c in zip(r, v, pair)]
        # below speed_min (5 m/s) the checks pause and the law is off: no bound to pass
        assert rows[-1] == math.inf and np.isfinite(rows[:-1]).all()
        assert jb.sensor_bound(sensor, cfg, 0.0, cfg.speed_min, True, True) < math.inf


@pytest.mark.parametrize("kind, value", [("scale", 0.5), ("stuck", 5.5), ("bias", 3.0), ("stuck", 33.0)])
def test_a_speed_fault_in_a_curve_is_found_before_its_command_turns_the_car(kind: str, value: float) -> None:
    """The speed schedules the yaw rate the law asks for (K_n(v)): in a curve at 10 m/s on a dry
    road at 45 % of the grip, a speed sensor that jumps makes the command turn the car by up to
    0.18 rad/s against the same run without the fault (measured without the check, asserted
    over 0.05 here); with it, the fault is found within a speed frame (20 ms) and the car's yaw
    rate stays within 0.05 rad/s of the twin's."""
    import numpy as np

    clean = pr.steady_curve(10.0, 1.0, a_y=0.45 * 9.81, duration=3.0)
    sc = clean.with_sensor_faults((SensorFault("speed", kind, 1.4, value),))
    twin = pr.run(clean, controller=LAW, second_yaw=SECOND).r_true
    after = slice(int(round(1.4 / TS)), None)
    r = pr.run(sc, controller=LAW, second_yaw=SECOND)
    assert r.fault_time is not None and 1.4 <= r.fault_time <= 1.4 + 0.022
    assert np.abs(r.r_true - twin)[after].max() < 0.05
    unchecked = pr.run(sc, controller=LAW, second_yaw=SECOND, monitor=pl.PlausibilityConfig(speed_step=1e3))
    assert np.abs(unchecked.r_true - twin)[after].max() > 0.05


def _turn(mon: pl.PlausibilityMonitor, samples: int, *, r: float = 0.3, v: float = 10.0, measured: float = 10.0,
          lat_step: tuple[int, float] = (-1, 0.0), missing: int = -1, paused: int = -1, bias: float = 0.0) -> list[int]:
    """A steady turn at yaw rate r and true speed v, the speed read as ``measured``: a_y = r v
    (plus ``lat_step``'s (sample, size) from that redundant sample on), the driver's angle the
    nominal car's for r, both yaw-rate elements agreeing, their LSB toggling; the redundant frame
    new every 25th period with its LSB toggling; the frame of sample ``missing`` lost (NaN), the
    yaw rate missing during sample ``paused`` (every check pauses); both yaw-rate elements offset
    by ``bias``.  The bits at the last period of each redundant
    sample (the first is no new sample: the monitor starts on it)."""
    c = mon.coefficients
    d = r * (c.wheelbase + c.k_us * measured * measured) / measured
    out = []
    for j in range(samples):
        lat = r * v + (lat_step[1] if 0 <= lat_step[0] <= j else 0.0) + (1e-3 if j % 2 else 0.0)
        for k in range(25):
            yaw = math.nan if j == paused else r + bias + (1e-4 if k % 2 else 0.0)
            bits = mon.step(d, d, yaw, math.nan if j == missing else lat, measured, 0.0, yaw)
        out.append(bits)
    return out


def test_the_steady_turn_check_compares_the_speed_with_a_y_over_r_in_settled_blocks() -> None:
    """Check 7: blocks of TURN_BLOCK redundant samples (500 ms) in which r and a_y stay put; the
    first block of a turn only settles it, each later one compares the speed with a_y / r
    against turn_speed_rel v + (turn_yaw_bias v + turn_lat_bias) / |r| (1.03 m/s at 11.5 m/s and
    0.3 rad/s here).  A speed 15 % high is found at the end of the second block, not before; 3 %
    is not; nor is any speed error where |r| < turn_yaw_min; an a_y step restarts the blocks."""
    n = pl.TURN_BLOCK
    mon = pl.PlausibilityMonitor()
    bits = _turn(mon, 3 * n, measured=11.5)
    assert set(bits[:2 * n]) == {0} and bits[2 * n] == pl.PLAUS_YAW
    assert mon.state.flags & pl.YAW_CHECKS == pl.CHECK_TURN and not mon.state.flags & pl.CUT_CHECKS  # faded
    assert mon.state.turn_err == pytest.approx(1.5 / (0.02 * 11.5 + (0.011 * 11.5 + 0.1) / 0.3), rel=0.02)
    mon = pl.PlausibilityMonitor()
    assert set(_turn(mon, 4 * n, measured=10.3)) == {0} and 0.3 < mon.state.turn_err < 0.8
    mon = pl.PlausibilityMonitor()
    assert set(_turn(mon, 4 * n, r=0.09, measured=13.0)) == {0} and mon.state.turn_err == 0.0
    # the yaw-rate sensor's offset the issue calls normal (0.6 deg/s, both elements) in a wide
    # turn at speed, where it moves a_y / r most (3.2 m/s): inside turn_yaw_bias v / |r|
    mon = pl.PlausibilityMonitor()
    assert set(_turn(mon, 4 * n, r=0.1, v=30.0, measured=30.0, bias=math.radians(0.6))) == {0}
    assert 0.5 < mon.state.turn_err < 1.0
    # an a_y step (beta still settling) in the second block: that block and the next only settle
    mon = pl.PlausibilityMonitor()
    bits = _turn(mon, 4 * n, measured=11.5, lat_step=(n + 3, -0.4))
    assert set(bits[:n + 3 + 2 * n - 1]) == {0} and bits[n + 3 + 2 * n - 1] == pl.PLAUS_YAW
    assert mon.state.flags & pl.YAW_CHECKS == pl.CHECK_TURN
    # a lost frame or a pause (the yaw rate missing) after the turn settled: it settles afresh,
    # so the trip comes two whole blocks after the gap, never sooner (the frame after the gap
    # repeats the value before it, toggled LSB and all, so the block starts one frame later)
    for gap in ({"missing": n + 4}, {"paused": n + 4}):
        mon = pl.PlausibilityMonitor()
        bits = _turn(mon, 5 * n, measured=11.5, **gap)
        first = bits.index(pl.PLAUS_YAW)
        assert first == (n + 4) + 1 + 2 * n, (gap, first)
        assert mon.state.flags & pl.YAW_CHECKS == pl.CHECK_TURN


@pytest.mark.parametrize("rate", [1.0, -1.0])
def test_a_speed_drift_in_a_hard_curve_is_found_before_its_command_turns_the_car(rate: float) -> None:
    """A drift never jumps: at 10 m/s on a dry road at 45 % of the grip, 1 m/s per s made the
    command turn the car by 0.10-0.16 rad/s against the same run without the fault before the
    kinematic check found it (asserted over 0.05 here); the steady-turn check finds it within
    about 1.3 s, with the car within 0.05 rad/s of its twin."""
    import numpy as np

    clean = pr.steady_curve(10.0, 1.0, a_y=0.45 * 9.81, duration=5.0, seed=3)
    sc = clean.with_sensor_faults((SensorFault("speed", "drift", 1.4, rate),))
    twin = pr.run(clean, controller=LAW, second_yaw=SECOND).r_true
    r = pr.run(sc, controller=LAW, second_yaw=SECOND)
    assert r.fault_time is not None and 1.9 < r.fault_time < 2.9 and r.margins["turn"] > 1.0
    assert np.abs(r.r_true - twin).max() < 0.05
    unchecked = pr.run(sc, controller=LAW, second_yaw=SECOND, monitor=pl.PlausibilityConfig(turn_yaw_min=1e3))
    assert np.abs(unchecked.r_true - twin).max() > 0.05


@pytest.mark.parametrize("v, mu, ramp", [(40.0, 1.0, 0.4), (10.0, 0.3, 0.4), (10.0, 0.3, 0.0), (20.0, 0.5, 0.4)])
def test_a_fault_free_turn_whose_side_slip_settles_slowly_is_no_speed_fault(v: float, mu: float, ramp: float) -> None:
    """The turns where the side slip angle keeps settling after the yaw rate is steady (a_y
    still rising: a_y / r 2-8 m/s off the speed for up to 1.5 s), which a one-block check
    without the a_y gate took for a speed error (up to 3.5 times its bound): the blocks restart
    while a_y moves, and the first steady one only settles the turn."""
    sc = pr.steady_curve(v, mu, a_y=0.5 * 9.81 * mu, ramp=ramp, duration=5.0, seed=3)
    r = pr.run(sc, controller=LAW, second_yaw=SECOND)
    assert r.report_time is None and 0.0 < r.margins["turn"] < 0.5


def _campaign_sample(duration: float = 3.0, **values: float) -> scn.Scenario:
    """The campaign's scenario of one sample: its parameters' defaults but ``values``."""
    row = {name: p.default for name, p in params.PARAMETERS.items()} | {params.INDEX: 0, params.NOISE_SEED: 1}
    return params.scenario_for(row | values, duration)


#: Strong disturbances the controller holds (side slip below 2 deg) that the first monitor took
#: for a yaw-rate fault 0.1-0.2 s after their onset: the command faded and each car spun (side
#: slip 100-380 deg).  The causes: the nominal car's beta' taken from the command rather than
#: the lagging actuator, and the low-mu car's beta' (docs/decisions/0002-kinematic-check-against-a-family-of-cars.md).
HELD = [dict(disturbance=0, v=20.0, mu=0.5, yaw_moment=3000.0), dict(disturbance=0, v=18.8, mu=0.52, yaw_moment=-3113.0),
        dict(disturbance=1, v=30.0, mu=0.6, mu_split=0.2, deceleration=7.0),
        dict(disturbance=1, v=20.0, mu=0.8, mu_split=0.2, deceleration=8.0)]


@pytest.mark.parametrize("values", HELD, ids=["yaw-moment-3000Nm-mu0.5", "yaw-moment-3113Nm-mu0.52",
                                              "split-mu-0.6-0.2-7ms2", "split-mu-0.8-0.2-8ms2"])
def test_a_strong_disturbance_the_controller_holds_is_no_sensor_fault(values: dict[str, float]) -> None:
    r = pr.run(_campaign_sample(**values), controller=LAW)
    assert r.report_time is None and r.margins["kinematic"] < 0.8
    assert abs(r.beta).max() < D(2.5)  # the command was not faded: the car was held


#: (v, mu, sensor, kind, value, onset, a_y of the curve): each one's error does exceed its bound
#: (checked); the stuck-at-last and frozen faults begin during the steering ramp, so that the
#: truth moves away from them.
DETECT = [
    (20.0, 1.0, "yaw_rate", "stuck", 0.01, 1.4, 2.0), (40.0, 1.0, "yaw_rate", "stuck", None, 0.3, 2.0),
    (20.0, 1.0, "yaw_rate", "bias", D(3.0), 1.4, 2.0), (10.0, 0.3, "yaw_rate", "bias", -D(3.0), 1.4, 2.0),
    (20.0, 1.0, "yaw_rate", "scale", 1.5, 1.4, 4.0), (20.0, 0.6, "yaw_rate", "scale", 0.5, 1.4, 2.0),
    (20.0, 1.0, "yaw_rate", "drift", D(1.0), 0.6, 2.0), (30.0, 1.0, "yaw_rate", "frozen", None, 0.3, 2.0),
    (20.0, 0.3, "steer", "stuck", 0.0, 1.4, 2.0), (40.0, 1.0, "steer", "bias", D(0.5), 1.4, 2.0),
    (10.0, 1.0, "steer_redundant", "drift", D(0.5), 1.4, 2.0), (20.0, 1.0, "lat_accel", "bias", 1.0, 1.4, 2.0),
    # low mu and high speed, where the family of low-mu cars could absorb part of a yaw-rate error
    (40.0, 0.6, "yaw_rate", "bias", D(3.0), 1.4, 2.0), (40.0, 0.5, "yaw_rate", "bias", -D(3.0), 1.4, 0.0),
    (20.0, 0.3, "yaw_rate", "bias", -D(3.0), 1.4, 0.0),
]


@pytest.mark.parametrize("v, mu, sensor, kind, value, onset, a_y", DETECT,
                         ids=[f"{s}-{k}-{v:g}ms-mu{mu:g}" for v, mu, s, k, *_ in DETECT])
def test_a_sensor_fault_is_reported_within_300_ms(v: float, mu: float, sensor: str, kind: str,
                                                  value: float | None, onset: float, a_y: float) -> None:
    sc = pr.steady_curve(v, mu, a_y=a_y, duration=3.4).with_sensor_faults((SensorFault(sensor, kind, onset, value),))
    r = pr.run(sc, controller=LAW)
    exceeded = r.exceeded_time(pr.error_bound(sensor, pl.PlausibilityConfig(), r))
    reported = r.fault_time
    assert reported is not None and reported >= onset  # found, and not before it happened
    assert exceeded is None or reported - exceeded <= 0.3
    assert exceeded is not None or reported <= onset + 0.3  # (a frozen value is found before its error grows)
    # the command fades once it is reported (at 30 deg/s; the 20 ms actuator follows)
    after = r.t >= reported + abs(r.aux[r.t >= reported][0]) / D(30.0) + 0.15
    assert abs(r.aux[after]).max() < D(0.01)
