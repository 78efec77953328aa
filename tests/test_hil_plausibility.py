"""The plausibility figures of a HIL run's summary, from synthetic traffic: when the first
plausibility fault was reported (from the command frames leading up to the status that says so),
in scenario time counted in yaw-rate frames, and how long after the sensor fault."""

from __future__ import annotations

import pytest

from firmware_py import model_regulator as mr
from mrsteer_dbc import names
from sim_plant.car import scenario as scn
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import SensorConfig, YawRateSensorConfig
from sim_plant.harness.hil_plausibility import plausibility_figures

RATE = 500.0


def _traffic(fault_from: int | None, status_every: int = 50, steps: int = 400, plaus: int = names.PLAUS_YAW,
             wall_scale: float = 0.1) -> list[dict]:
    """One yaw frame and one command per step (a lockstep run whose wall clock runs at
    ``wall_scale`` of simulated time), a status every ``status_every`` steps; from step
    ``fault_from`` on the statuses carry ``plaus`` and the commands are FAULT if it has a fault bit,
    else DEGRADED, as the node reports them."""
    rows = []
    for k in range(steps):
        t = 1000.0 + k * wall_scale / RATE
        faulted = fault_from is not None and k >= fault_from
        rows.append({"t_s": t, "message": names.MSG_YAW, names.SIG_YAW_RATE: 0.0})
        fault_state = faulted and plaus & (names.PLAUS_YAW | names.PLAUS_STEER)
        state = mr.STATUS_FAULT if fault_state else mr.STATUS_DEGRADED if faulted and plaus else mr.STATUS_ACTIVE
        rows.append({"t_s": t, "message": names.MSG_CMD, names.SIG_CMD_STATE: state})
        if k % status_every == status_every - 1:
            rows.append({"t_s": t, "message": names.MSG_STATUS, names.SIG_STATUS_PLAUS: plaus if faulted else 0})
    return rows


def _scenario(start: float) -> scn.Scenario:
    return scn.load("side-wind").with_sensor_faults((SensorFault("yaw_rate", "stuck", start, 0.01),))


def test_detection_is_the_first_fault_command_before_the_status_in_scenario_time() -> None:
    fig = plausibility_figures(_traffic(fault_from=123), _scenario(0.1), RATE)
    assert fig["fault_detected_s"] == pytest.approx(123 / RATE)  # not the status frame's 149, nor wall time
    assert fig["detection_latency_s"] == pytest.approx(123 / RATE - 0.1)
    assert fig["bits_seen"] == names.PLAUS_YAW and fig["sensor_faults"] == ["yaw_rate:stuck:0.01@0.1"]


def test_fault_commands_for_another_reason_earlier_do_not_count() -> None:
    rows = _traffic(fault_from=200)
    for r in rows[:30]:  # FAULT at start-up (no inputs yet), then healthy
        if r["message"] == names.MSG_CMD:
            r[names.SIG_CMD_STATE] = mr.STATUS_FAULT
    fig = plausibility_figures(rows, _scenario(0.2), RATE)
    assert fig["fault_detected_s"] == pytest.approx(200 / RATE)


def test_a_clean_run_reports_nothing_and_degraded_is_its_own_figure() -> None:
    clean = plausibility_figures(_traffic(fault_from=None), scn.load("side-wind"), RATE)
    assert clean["fault_detected_s"] is None and clean["bits_seen"] == 0 and clean["detection_latency_s"] is None
    degraded = plausibility_figures(_traffic(fault_from=100, plaus=names.PLAUS_DEGRADED), scn.load("side-wind"), RATE)
    assert degraded["fault_detected_s"] is None  # DEGRADED is no fault
    # from the first DEGRADED command, not the status frame's 149
    assert degraded["first_degraded_s"] == pytest.approx(100 / RATE)
    assert clean["reported_s"] is None and clean["reported_as"] is None


def test_the_report_is_the_fault_or_the_degraded_state_whichever_came_first() -> None:
    """Issue 18 counts the degraded state as the report: an a_y fault on a car with the yaw
    rate's second element is DEGRADED only (OUTSIDE_MODEL), and its latencies count from it."""
    from mrsteer_cli.hil_cli import plausibility_line

    degraded = plausibility_figures(_traffic(fault_from=100, plaus=names.PLAUS_DEGRADED), _scenario(0.1), RATE)
    assert degraded["reported_s"] == pytest.approx(100 / RATE) and degraded["reported_as"] == "degraded"
    assert degraded["detection_latency_s"] == pytest.approx(100 / RATE - 0.1)
    assert "DEGRADED (no sensor fault bit) reported at 0.200 s, 100 ms after the sensor fault" in plausibility_line(
        degraded)
    fault = plausibility_figures(_traffic(fault_from=123), _scenario(0.1), RATE)
    assert fault["reported_s"] == fault["fault_detected_s"] and fault["reported_as"] == "fault"
    # a missing input's DEGRADED comes and goes: no report, though first_degraded_s shows it
    transient = _traffic(fault_from=100, plaus=names.PLAUS_DEGRADED)
    for r in transient[-120:]:
        if r["message"] == names.MSG_STATUS:
            r[names.SIG_STATUS_PLAUS] = 0
        elif r["message"] == names.MSG_CMD:
            r[names.SIG_CMD_STATE] = mr.STATUS_ACTIVE
    fig = plausibility_figures(transient, _scenario(0.1), RATE)
    assert fig["first_degraded_s"] == pytest.approx(100 / RATE) and fig["reported_s"] is None
    # nor does a DEGRADED before the sensor fault's onset that lasts: the report is from the onset
    late = plausibility_figures(_traffic(fault_from=100, plaus=names.PLAUS_DEGRADED), _scenario(0.5), RATE)
    assert late["reported_s"] == pytest.approx(299 / RATE) and late["latched_degraded_s"] == late["reported_s"]


def _steps(n: int, **measured) -> list:
    """n plant steps at 20 m/s, r 0.02 rad/s, a_y 0.4 m/s^2, the wheel at 0.01 rad; each
    ``measured`` column a function of t (the truth where not given)."""
    import math

    from sim_plant.harness.hil_steps import Step

    out = []
    for k in range(n):
        t = k / RATE
        truth = dict(steer_measured_rad=0.01, lat_accel_measured_m_s2=0.4, steer_redundant_measured_rad=0.01,
                     yaw_rate_redundant_measured_rad_s=0.02, yaw_rate_measured_rad_s=0.02)
        cols = {name: f(t) for name, f in measured.items()}
        out.append(Step(step=k, t_s=t, driver_angle_rad=0.01, yaw_rate_rad_s=0.02, v_m_s=20.0, aux_cmd_rad=0.0,
                        aux_applied_rad=0.0, ctrl_state="", ctrl_cause=None, m_z_nm=0.0, mu=1.0, beta_rad=0.0,
                        lat_accel_m_s2=0.4, wall_s=1000.0 + t, **(truth | cols)))
    assert not math.isnan(out[0].lat_accel_measured_m_s2)
    return out


def test_every_sensors_error_is_timed_from_when_it_passed_the_monitors_bound() -> None:
    from dataclasses import replace

    from firmware_py.plausibility import PlausibilityConfig

    cfg = PlausibilityConfig()
    drift = 0.5 * 3.141592653589793 / 180.0  # rad/s: the steering channel drifts 0.5 deg/s from 0.2 s
    sc = scn.load("side-wind").with_sensor_faults((SensorFault("steer", "drift", 0.2, drift),))
    steps = _steps(800, steer_measured_rad=lambda t: 0.01 + max(0.0, t - 0.2) * drift)
    fig = plausibility_figures(_traffic(fault_from=None, steps=800), sc, RATE, steps)
    assert fig["error_over_bound_s"] == pytest.approx(0.2 + cfg.steer_bound / drift, abs=2.5 / RATE)
    assert fig["yaw_error_over_bound_s"] is None  # not a yaw-rate fault
    # a_y: the kinematic bound times v, plus side_accel while the car has the second yaw element
    for offset, present, over in ((1.0, True, False), (1.0, False, True), (2.0, True, True)):
        sensors = replace(scn.load("side-wind").sensors, yaw_rate_redundant_present=present)
        sc = replace(scn.load("side-wind"), sensors=sensors).with_sensor_faults(
            (SensorFault("lat_accel", "bias", 0.5, offset),))
        steps = _steps(400, lat_accel_measured_m_s2=lambda t, o=offset: 0.4 + (o if t >= 0.5 else 0.0))
        fig = plausibility_figures(_traffic(fault_from=None), sc, RATE, steps)
        assert (fig["error_over_bound_s"] == pytest.approx(0.5)) if over else fig["error_over_bound_s"] is None
    # the second yaw-rate element: the pair's 0.03 rad/s, on the residual r_2 - r the pair sees,
    # so a first element's healthy bias of 1 deg/s (0.0175 rad/s) hides an offset of 0.031 of
    # the same sign and adds to one of the other
    biased = replace(scn.load("side-wind").sensors, yaw_rate=YawRateSensorConfig(bias_deg_s=1.0))
    for offset, over in ((0.031, False), (-0.031, True)):
        sc = replace(scn.load("side-wind"), sensors=biased).with_sensor_faults(
            (SensorFault("yaw_rate_redundant", "bias", 0.5, offset),))
        steps = _steps(400, yaw_rate_redundant_measured_rad_s=lambda t, o=offset: 0.02 + (o if t >= 0.5 else 0.0))
        fig = plausibility_figures(_traffic(fault_from=None), sc, RATE, steps)
        assert (fig["error_over_bound_s"] == pytest.approx(0.5)) if over else fig["error_over_bound_s"] is None
    # either speed: the speed pair's 1.0 m/s + 5 % of 20 m/s, and half the second speed's
    # 0.3 m/s LSB with its 5 %, on a car with the second speed; without it no check bounds the
    # speed's error (ideal sensors: the readings as the synthetic columns give them, unquantised)
    ideal = replace(scn.load("side-wind"), sensors=SensorConfig.ideal())
    for sensor, column in (("speed", "speed_measured_m_s"), ("speed_redundant", "speed_redundant_measured_m_s")):
        fault = SensorFault(sensor, "drift", 0.2, -2.0)
        steps = _steps(800, **{column: lambda t: 20.0 - 2.0 * max(0.0, t - 0.2)})
        fig = plausibility_figures(_traffic(fault_from=None, steps=800), ideal.with_sensor_faults((fault,)), RATE, steps)
        bound = cfg.speed_pair_bound + cfg.speed_pair_rel * 20.0 + 0.15 * (1.0 + cfg.speed_pair_rel)
        assert fig["error_over_bound_s"] == pytest.approx(0.2 + bound / 2.0, abs=2.5 / RATE)
        without = replace(ideal, sensors=replace(ideal.sensors, speed_redundant_present=False))
        fig = plausibility_figures(_traffic(fault_from=None, steps=800), without.with_sensor_faults((fault,)), RATE,
                                   steps)
        assert fig["error_over_bound_s"] is None


def test_the_yaw_rate_is_judged_on_the_residual_of_the_pair_and_never_before_its_onset_or_below_speed_min() -> None:
    from dataclasses import replace

    from firmware_py import plausibility as pl

    base = scn.load("side-wind")
    # The first element against the second, whose healthy bias of 1 deg/s (0.0175 rad/s) the pair
    # sees with it: an offset of +0.034 shows as 0.0166 (within the pair's 0.03), -0.034 as 0.051.
    second = replace(base.sensors, yaw_rate_redundant=YawRateSensorConfig(bias_deg_s=1.0))
    for offset, over in ((0.034, False), (-0.034, True)):
        sc = replace(base, sensors=second).with_sensor_faults((SensorFault("yaw_rate", "bias", 0.5, offset),))
        steps = _steps(400, yaw_rate_measured_rad_s=lambda t, o=offset: 0.02 + (o if t >= 0.5 else 0.0))
        fig = plausibility_figures(_traffic(fault_from=None), sc, RATE, steps)
        assert (fig["error_over_bound_s"] == pytest.approx(0.5)) if over else fig["error_over_bound_s"] is None
    # A first element's bias of 2 deg/s (0.035 rad/s, over the pair's bound by itself) is no fault
    # of the second element before that fault's onset: a +0.04 offset then shows as 0.005.
    first = replace(base.sensors, yaw_rate=YawRateSensorConfig(bias_deg_s=2.0))
    sc = replace(base, sensors=first).with_sensor_faults((SensorFault("yaw_rate_redundant", "bias", 0.5, 0.04),))
    steps = _steps(400, yaw_rate_redundant_measured_rad_s=lambda t: 0.02 + (0.04 if t >= 0.5 else 0.0))
    assert plausibility_figures(_traffic(fault_from=None), sc, RATE, steps)["error_over_bound_s"] is None
    # Below the monitor's speed_min its checks pause: a yaw-rate offset of 0.1 rad/s at 3 m/s is
    # over no bound (at 20 m/s it is at its onset).
    sc = base.with_sensor_faults((SensorFault("yaw_rate", "bias", 0.5, 0.1),))
    steps = _steps(400, yaw_rate_measured_rad_s=lambda t: 0.02 + (0.1 if t >= 0.5 else 0.0))
    assert plausibility_figures(_traffic(fault_from=None), sc, RATE, steps)["error_over_bound_s"] == pytest.approx(0.5)
    slow = [replace(s, v_m_s=3.0) for s in steps]
    assert 3.0 < pl.PlausibilityConfig().speed_min
    assert plausibility_figures(_traffic(fault_from=None), sc, RATE, slow)["error_over_bound_s"] is None


def test_the_error_is_the_faults_own_not_the_sensors_lag_in_a_transient() -> None:
    # The realistic a_y sensor (30 Hz low-pass, noise) through a 5 m/s^2 step of the true a_y at
    # 0.3 s: for a few ms its reading lags the truth by more than the bound (0.035 * 20 + 0.6).
    # The readings are the plant's own sensor model with the fault, as the plant sends them.
    from dataclasses import replace

    from sim_plant.car.sensors import Sensors

    base = scn.load("side-wind")
    truth = [0.4 if k / RATE < 0.3 else 5.4 for k in range(400)]
    for offset, over in ((0.1, None), (2.0, 0.2)):
        fault = SensorFault("lat_accel", "bias", 0.2, offset)
        sensor = Sensors(replace(base.sensor_config, faults=(fault,)), 1.0 / RATE)
        readings = []
        for k, a_y in enumerate(truth):
            sensor.at(k / RATE)
            readings.append(sensor.lat_accel(a_y))
        assert max(abs(r - a) for r, a in zip(readings, truth)) > 1.3  # the lag: over the bound
        steps = [replace(s, lat_accel_m_s2=a, lat_accel_measured_m_s2=r)
                 for s, a, r in zip(_steps(400), truth, readings)]
        fig = plausibility_figures(_traffic(fault_from=None), base.with_sensor_faults((fault,)), RATE, steps)
        # (the 2 m/s^2 offset acts before the sensor's filter: over the bound 10 ms after its onset)
        assert fig["error_over_bound_s"] == (None if over is None else pytest.approx(over, abs=0.015))


def test_the_command_line_says_early_or_late_against_the_bound() -> None:
    from mrsteer_cli.hil_cli import plausibility_line

    base = {"bits_seen": 2, "fault_detected_s": 1.95, "detection_latency_s": 0.45}
    assert plausibility_line(base | {"latency_from_bound_s": 0.12}).endswith(
        "at 1.950 s, 450 ms after the sensor fault, 120 ms after its error passed the bound")
    assert "10 ms before its error passed the bound" in plausibility_line(base | {"latency_from_bound_s": -0.01})
    quiet = {"bits_seen": 0, "fault_detected_s": None, "detection_latency_s": None, "latency_from_bound_s": None}
    assert plausibility_line(quiet) == "bits seen 0, fault reported none"
    missed = quiet | {"error_over_bound_s": 3.9}
    assert plausibility_line(missed, 4.0).endswith(
        "none; its error passed the bound at 3.900 s, 100 ms before the run's end: too soon to judge, run longer")
    assert plausibility_line(missed, 5.0).endswith("1.10 s before the run's end: not found in time")
    assert plausibility_line(missed).endswith("none; its error passed the bound at 3.900 s")
    # With a sensor fault the line ends with the yaw rate its command caused, against the target.
    faulted = base | {"latency_from_bound_s": 0.12, "sensor_faults": ["yaw_rate:stuck:0.01@1.5"]}
    assert plausibility_line(faulted | {"caused_yaw_rad_s": 0.0123}).endswith(
        "after its error passed the bound; the command caused at most 0.0123 rad/s of yaw (target 0.05: met)")
    assert plausibility_line(faulted | {"caused_yaw_rad_s": 0.07}).endswith("0.0700 rad/s of yaw (target 0.05: NOT met)")
    assert plausibility_line(faulted | {"caused_yaw_rad_s": None, "caused_yaw_note": "a realtime run"}).endswith(
        "; caused yaw not estimated: a realtime run")


def test_a_second_speed_fault_while_the_car_brakes_is_judged_on_the_braked_wheels() -> None:
    # The built-in split-mu stop (5 m/s^2 asked on 1.0 / 0.2 from 0.5 s, settled by 0.65 s: the car
    # slows at 3.48 m/s^2, its rear wheels 8.8 % slow) with ideal sensors and a second speed 2.5 m/s
    # low from 1.0 s: the error is the fault's 2.5 m/s, not the slip's, and while the car brakes
    # it is judged against the bound widened by speed_slip_rel v, so it never passes it; the same
    # 2.5 m/s on a car that does not brake passes the plain bound (2.16 m/s at 20 m/s) at its onset.
    from dataclasses import replace

    from firmware_py import plausibility as pl
    from sim_plant.car.disturbances import sum_loads

    base = replace(scn.load("split-mu"), sensors=SensorConfig.ideal())
    cfg, fault = pl.PlausibilityConfig(), SensorFault("speed_redundant", "bias", 1.0, -2.5)
    slip = [sum_loads(base.disturbances, k / RATE).wheel_slip for k in range(800)]
    assert slip[0] == 0.0 and slip[-1] == pytest.approx(0.5 * (0.05 * 5.0 / 9.81 + 0.15))

    def v(t: float) -> float:
        return 25.0 - 3.48 * max(0.0, t - 0.5)

    def wheels(t: float, bias: float = 2.5) -> float:
        return v(t) * (1.0 - slip[round(t * RATE)]) - (bias if t >= 1.0 else 0.0)

    braking = [replace(s, v_m_s=v(s.t_s)) for s in _steps(800, speed_redundant_measured_m_s=wheels)]
    fig = plausibility_figures(_traffic(fault_from=None, steps=800), base.with_sensor_faults((fault,)), RATE, braking)
    assert fig["error_over_bound_s"] is None
    # 6 m/s low: under the widened bound (7.5 m/s at 21 m/s) as the fault's own error; with the
    # wheels' 8.8 % slip counted as error too it would pass it by 1.4 s
    large = SensorFault("speed_redundant", "bias", 1.0, -6.0)
    braking = [replace(s, v_m_s=v(s.t_s)) for s in _steps(800, speed_redundant_measured_m_s=lambda t: wheels(t, 6.0))]
    fig = plausibility_figures(_traffic(fault_from=None, steps=800), base.with_sensor_faults((large,)), RATE, braking)
    assert fig["error_over_bound_s"] is None
    assert 2.5 < cfg.speed_pair_bound + (cfg.speed_pair_rel + cfg.speed_slip_rel) * v(1.0)
    rolling = replace(scn.load("side-wind"), sensors=SensorConfig.ideal())  # no stop: the wheels roll
    still = _steps(800, speed_redundant_measured_m_s=lambda t: 20.0 - (2.5 if t >= 1.0 else 0.0))
    fig = plausibility_figures(_traffic(fault_from=None, steps=800), rolling.with_sensor_faults((fault,)), RATE,
                               still)
    assert fig["error_over_bound_s"] == pytest.approx(1.0)
