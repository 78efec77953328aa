"""The yaw rate a HIL run's command caused (``sim_plant.harness.hil_caused_yaw``), on synthetic
runs built from the fault-free twin itself: what the run did beyond the twin is the only thing
counted, and the figure is then the linear car's response to it (scipy's, eqs. 14/16)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from scipy import signal

from firmware_py import model_regulator as mr
from sim_plant.car import scenario as scn
from sim_plant.car.scenario_play import ScenarioState
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.vehicle import VehicleParams, steering_tf
from sim_plant.harness.hil_caused_yaw import caused_yaw_figures, driver_gains
from sim_plant.harness.hil_steps import Step
from sim_plant.offline import plausibility_runs

RATE = 500.0
TS = 1.0 / RATE
CTRL = mr.ControllerConfig()
#: paper-fig9 (the linear car, ideal sensors): the 4000 Nm step at 0.5 s; the fault at 0.55 s,
#: while the healthy command is still moving (so a constant held angle would be the wrong
#: reference), with an onset where the error is plainly visible.
ONSET = 0.55
SCENARIO = scn.load("paper-fig9").with_sensor_faults((SensorFault("yaw_rate", "stuck", ONSET, 0.01),))


def _twin() -> list[float]:
    run = plausibility_runs.run(SCENARIO.without_sensor_faults(), TS, controller=CTRL,
                                second_yaw=SCENARIO.sensor_config, second_speed=True)
    return [float(a) for a in run.aux]


def _steps(applied: list[float]) -> list[Step]:
    """A run of paper-fig9 on the bus that applied ``applied`` (its other columns as the linear
    car's figure needs them: the speed, mu and the yaw moment)."""
    return [Step(k, k * TS, 0.0, 0.0, 0.0, 20.0, a, a, "ACTIVE", 0, 4000.0 if k * TS >= 0.5 else 0.0, 1.0, 0.0, 0.0,
                 1000.0 + k * TS) for k, a in enumerate(applied)]


def _peak(u: list[float]) -> float:
    tf = steering_tf(VehicleParams(v=20.0, mu=1.0))
    _, r, _ = signal.lsim(signal.lti(tf.num, tf.den), u, [k * TS for k in range(len(u))], interp=False)
    return float(max(abs(r)))


@pytest.fixture(scope="module")
def twin() -> list[float]:
    return _twin()


def test_only_what_the_run_applied_beyond_the_healthy_command_counts(twin: list[float]) -> None:
    k0 = round(ONSET / TS)
    moving = abs(twin[k0 + 50] - twin[k0])
    assert moving > math.radians(0.2)  # the healthy command moves after the onset: a held angle is no reference
    # 0.3 deg further from zero than the twin for 20 ms from 0.6 s, then the twin's again
    pulse = [0.0] * len(twin)
    for k in range(round(0.6 / TS), round(0.6 / TS) + 10):
        pulse[k] = math.copysign(math.radians(0.3), twin[k])
    fig = caused_yaw_figures(_steps([a + p for a, p in zip(twin, pulse)]), SCENARIO, CTRL, RATE)
    assert fig["caused_yaw_rad_s"] == pytest.approx(_peak(pulse[k0:]), rel=2e-3)
    assert fig["caused_yaw_twin_mismatch_deg"] == 0.0
    assert "fault-free twin" in fig["caused_yaw_note"] and "linear car" in fig["caused_yaw_note"]
    assert "unchecked" not in fig["caused_yaw_note"]  # the command moved from 0.5 s: the twin was checked
    # A fault at 0.3 s, before the yaw moment: the command was 0 until then, so the twin's
    # match there says nothing, and the note says so (the figure is still given).
    early = caused_yaw_figures(_steps(twin), scn.load("paper-fig9").with_sensor_faults(
        (SensorFault("yaw_rate", "stuck", 0.3, 0.01),)), CTRL, RATE)
    assert early["caused_yaw_rad_s"] == 0.0 and "twin unchecked" in early["caused_yaw_note"]
    # The same run following the twin: nothing caused. A fade to zero from the onset: nothing either.
    assert caused_yaw_figures(_steps(twin), SCENARIO, CTRL, RATE)["caused_yaw_rad_s"] == 0.0
    fade = twin[:k0] + [twin[k0] * max(0.0, 1.0 - (k - k0) / 100) for k in range(k0, len(twin))]
    assert caused_yaw_figures(_steps(fade), SCENARIO, CTRL, RATE)["caused_yaw_rad_s"] == 0.0


def test_a_run_its_twin_does_not_match_before_the_onset_gets_no_figure(twin: list[float]) -> None:
    off = caused_yaw_figures(_steps([a + math.radians(0.1) for a in twin]), SCENARIO, CTRL, RATE)
    assert off["caused_yaw_rad_s"] is None
    assert off["caused_yaw_note"].startswith("the fault-free twin differs from the run by 0.100 deg before the onset")


def test_runs_without_a_twin_say_why(twin: list[float]) -> None:
    steps = _steps(twin)
    cases = {"no sensor fault": caused_yaw_figures(steps, SCENARIO.without_sensor_faults(), CTRL, RATE),
             "no controller": caused_yaw_figures(steps, SCENARIO, CTRL, RATE, controller=False),
             "a realtime run": caused_yaw_figures(steps, SCENARIO, CTRL, RATE, lockstep=False),
             "one-step delay, the run 2": caused_yaw_figures(steps, SCENARIO, CTRL, RATE, delay_steps=2),
             "ends at the fault's onset": caused_yaw_figures(steps[:round(ONSET / TS)], SCENARIO, CTRL, RATE),
             "another controller program": caused_yaw_figures(steps, SCENARIO, CTRL, RATE, shipped=False)}
    for words, fig in cases.items():
        assert fig["caused_yaw_rad_s"] is None and words in fig["caused_yaw_note"], (words, fig)
    # A fault in the sensor models' own file counts as the run's fault, and the twin drops it too.
    in_file = SCENARIO.without_sensor_faults()
    in_file = replace(in_file, sensors=replace(in_file.sensors, faults=SCENARIO.sensor_faults))
    assert in_file.without_sensor_faults().sensor_config.faults == ()
    assert caused_yaw_figures(steps, in_file, CTRL, RATE)["caused_yaw_rad_s"] == 0.0


def test_the_replays_driver_corrects_as_the_scenarios_driver_model_does() -> None:
    # handover: the 4000 Nm step at 0.5 s, a panic time of 1 s, then the driver model's 0.5 s
    # correction; paper-fig9's driver holds the wheel.
    steps = _steps([0.0] * 1000)
    gains = driver_gains(ScenarioState(scn.load("handover")), steps, TS)
    k_n = steering_tf(VehicleParams(v=20.0, mu=1.0)).dc_gain()
    assert gains[100] == pytest.approx(TS / 0.5 / k_n)  # correcting before the hit
    assert gains[300] == gains[700] == 0.0  # the panic time, 0.5-1.5 s
    assert gains[800] == pytest.approx(TS / 0.5 / k_n)
    assert set(driver_gains(ScenarioState(scn.load("paper-fig9")), steps, TS)) == {0.0}


def test_the_figure_lets_the_scenarios_driver_correct_the_car_without_the_excursion() -> None:
    # handover's driver corrects from 1.5 s: an excursion of 0.3 deg held for 0.8 s from 2 s is
    # partly taken back by the driver of the car without it, so the figure is below the
    # uncorrected replay's, and equal to the replay with the scenario's gains.
    from sim_plant.judge.caused_yaw import excursion_yaw

    sc = scn.load("handover").with_sensor_faults((SensorFault("yaw_rate", "stuck", 1.8, 0.01),))
    twin = [float(a) for a in plausibility_runs.run(sc.without_sensor_faults(), TS, controller=CTRL,
                                                     second_yaw=sc.sensor_config, second_speed=True).aux]
    applied = [a + (math.copysign(math.radians(0.3), a) if 2.0 <= k * TS < 2.8 else 0.0) for k, a in enumerate(twin)]
    steps = _steps(applied)
    k0 = round(1.8 / TS)
    figure = caused_yaw_figures(steps, sc, CTRL, RATE)["caused_yaw_rad_s"]
    car = VehicleParams(v=20.0, mu=1.0, mass=sc.mass)
    gains = driver_gains(ScenarioState(sc), steps[k0:], TS)
    assert set(gains) == {TS / 0.5 / steering_tf(car).dc_gain()}
    corrected = excursion_yaw(applied[k0:], TS, car, healthy=twin[k0:], driver_gain=gains)
    assert figure == pytest.approx(corrected, rel=1e-12)
    assert figure < 0.9 * excursion_yaw(applied[k0:], TS, car, healthy=twin[k0:])
