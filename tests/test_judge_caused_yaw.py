"""The yaw rate a command's excursion caused, replayed on the run's car
(``sim_plant.judge.caused_yaw``): the paper's linear car against scipy's continuous
response, the nonlinear car against the linear one where its tyres are linear and against its
grip where they are not."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from sim_plant.car.nonlinear import NonlinearPlant
from sim_plant.car.vehicle import VehicleParams, steering_tf
from sim_plant.judge.caused_yaw import STEADY_MOVE, excursion, excursion_yaw, kept, onset_step, steady

TS = 0.002
CAR = VehicleParams(v=20.0, mu=0.3)


def _peak(u: list[float], car: VehicleParams = CAR) -> float:
    """The continuous linear car's peak |r| for the input u held over each step (eqs. 14/16)."""
    tf = steering_tf(car)
    _, r, _ = signal.lsim(signal.lti(tf.num, tf.den), u, [k * TS for k in range(len(u))], interp=False)
    return float(max(abs(r)))


def _steady_curve(delta: float, car: VehicleParams = CAR) -> tuple[float, float]:
    """The nonlinear car's (beta, r) after 6 s at the driver's front-wheel angle ``delta``."""
    plant = NonlinearPlant(car, TS)
    for _ in range(3000):
        plant.advance(delta, 0.0)
    beta, r = plant.x
    return float(beta), float(r)


def test_the_excursion_is_what_lies_beyond_the_held_angle_or_beyond_zero() -> None:
    assert excursion(-0.03, -0.02) == pytest.approx(-0.01)  # further than the held angle
    assert excursion(-0.01, -0.02) == 0.0  # between it and zero: a fade, the safe state
    assert excursion(0.005, -0.02) == pytest.approx(0.005)  # past zero
    assert excursion(0.01, 0.0) == pytest.approx(0.01)


def test_on_the_linear_car_it_is_the_cars_response_to_the_excursion_alone() -> None:
    a0, step = math.radians(-1.0), math.radians(-0.5)
    applied = [a0] * 10 + [a0 + step] * 20 + [a0 * 0.5] * 970  # a pulse, then a fade halfway
    assert excursion_yaw(applied, TS, CAR) == pytest.approx(_peak([0.0] * 10 + [step] * 20 + [0.0] * 970), rel=2e-3)


def test_the_nonlinear_car_gives_the_linear_figure_where_its_tyres_are_linear() -> None:
    # From straight running, 0.2 deg: the slip angles stay small, the tyres on their slope at
    # zero slip, which is the linear car's cornering stiffness.
    applied = [0.0] + [math.radians(0.2)] * 1000
    zeros = [0.0] * len(applied)
    nonlinear = excursion_yaw(applied, TS, CAR, "nonlinear", zeros, zeros)
    assert nonlinear == pytest.approx(_peak(applied), rel=2e-3)


@pytest.mark.parametrize("driver_deg", [1.0, 2.0])
def test_near_its_grip_the_nonlinear_car_answers_less_and_fading_causes_nothing(driver_deg: float) -> None:
    # A steady curve on mu 0.3 at 20 m/s (a_y 1.5 and 2.6 m/s^2 of the road's 2.9): the tyres'
    # slope there is below the zero-slip one, so the same 0.5 deg further into the turn yaws the
    # car less than it would the linear car, and less the nearer the limit.
    delta = math.radians(driver_deg)
    beta, r = _steady_curve(delta)
    a0 = math.radians(0.2)
    further = [a0] + [a0 + math.radians(0.5)] * 1000
    driver, m_z = [delta] * len(further), [0.0] * len(further)
    nonlinear = excursion_yaw(further, TS, CAR, "nonlinear", driver, m_z, beta, r)
    linear = excursion_yaw(further, TS, CAR)
    assert 0.0 < nonlinear < (0.95 if driver_deg == 1.0 else 0.7) * linear
    # Back to zero from the held angle: the replay without the excursion is the same run.
    fade = [a0 * (1.0 - k / 50) if k < 50 else 0.0 for k in range(1000)]
    assert excursion_yaw(fade, TS, CAR, "nonlinear", driver[:1000], m_z[:1000], beta, r) == 0.0


def test_the_nonlinear_replay_needs_the_driver_angle_and_the_yaw_moment() -> None:
    with pytest.raises(ValueError, match="driver angle and the yaw moment"):
        excursion_yaw([0.0, 0.01], TS, CAR, "nonlinear")
    with pytest.raises(ValueError, match="plant must be one of"):
        excursion_yaw([0.0, 0.01], TS, CAR, "bicycle")


def _with_driver(car: VehicleParams, time_constant: float) -> tuple[list[float], list[float]]:
    """(num, den) of r - r' per rad of excursion on the continuous linear car whose driver adds
    the integral of -(r' - r) / (time_constant K_n) (``ScenarioState.driver_angle``'s correction):
    G T K s / (T K s den + num), G = num / den (eq. 14), K the dry road's K_n(v)."""
    tf = steering_tf(car)
    k_n = steering_tf(car.at(mu=1.0)).dc_gain()
    tk = time_constant * k_n
    num = [tk * c for c in tf.num] + [0.0]
    den = [tk * c for c in tf.den] + [0.0]
    for i, c in enumerate(reversed(tf.num)):
        den[-1 - i] += c
    return num, den


def test_a_correcting_driver_takes_the_difference_back_on_the_linear_car() -> None:
    # Half a degree held for 6 s at 20 m/s on mu 0.3, the driver model's 0.5 s correction: the
    # figure is scipy's continuous closed loop's peak; the driver's integral action ends the
    # difference, where the car without a correcting driver keeps its steady gain.
    step, time_constant = math.radians(0.5), 0.5
    applied = [0.0] + [step] * 3000
    gain = TS / time_constant / steering_tf(CAR.at(mu=1.0)).dc_gain()
    num, den = _with_driver(CAR, time_constant)
    t = [k * TS for k in range(len(applied))]
    _, r, _ = signal.lsim(signal.lti(num, den), [0.0] + [step] * 3000, t, interp=False)
    closed = excursion_yaw(applied, TS, CAR, driver_gain=[gain] * len(applied))
    assert closed == pytest.approx(float(max(abs(r))), rel=1e-2)
    assert abs(r[-1]) < 0.05 * closed  # (the continuous loop's difference gone by the end)
    assert closed < 0.9 * excursion_yaw(applied, TS, CAR)
    assert excursion_yaw(applied, TS, CAR, driver_gain=[0.0] * len(applied)) == excursion_yaw(applied, TS, CAR)


def test_the_nonlinear_replay_lets_the_driver_correct_as_the_linear_car_does_where_its_tyres_are_linear() -> None:
    applied = [0.0] + [math.radians(0.2)] * 2000
    zeros = [0.0] * len(applied)
    gains = [TS / 0.5 / steering_tf(CAR.at(mu=1.0)).dc_gain()] * len(applied)
    nonlinear = excursion_yaw(applied, TS, CAR, "nonlinear", zeros, zeros, driver_gain=gains)
    assert nonlinear == pytest.approx(excursion_yaw(applied, TS, CAR, driver_gain=gains), rel=5e-3)
    assert nonlinear < 0.9 * excursion_yaw(applied, TS, CAR, "nonlinear", zeros, zeros)


def test_the_replayed_drivers_correction_stops_at_the_drivers_clamp() -> None:
    # The recorded driver at his 0.6 rad clamp (at 3 m/s, a_y 2 m/s^2: the tyres on their slope)
    # and an excursion further the same way: the correction would steer the car without it
    # further still, past the clamp, so it adds nothing and the figure is the uncorrected one;
    # off the clamp it does add.
    from sim_plant.car.scenario_play import DRIVER_LIMIT

    car = VehicleParams(v=3.0, mu=1.0)
    applied = [0.0] + [math.radians(0.5)] * 1500
    gains = [TS / 0.5 / steering_tf(car.at(mu=1.0)).dc_gain()] * len(applied)
    zeros = [0.0] * len(applied)
    for driver, clamped in ((DRIVER_LIMIT, True), (0.1, False)):
        angles = [driver] * len(applied)
        plant = NonlinearPlant(car, TS)
        for _ in range(2500):  # the steady turn at the driver's angle
            plant.advance(driver, 0.0)
        beta, r = (float(x) for x in plant.x[:2])
        corrected = excursion_yaw(applied, TS, car, "nonlinear", angles, zeros, beta, r, driver_gain=gains)
        uncorrected = excursion_yaw(applied, TS, car, "nonlinear", angles, zeros, beta, r)
        assert (corrected == uncorrected) == clamped


def test_kept_and_the_excursion_over_arrays_are_the_scalars_by_hand() -> None:
    a = np.array([-0.03, -0.01, 0.005, 0.01, 0.03, 0.01, -0.01])
    h = np.array([-0.02, -0.02, -0.02, 0.0, 0.02, 0.02, 0.02])
    assert kept(a, h).tolist() == [-0.02, -0.01, 0.0, 0.0, 0.02, 0.01, 0.0]
    assert excursion(a, h) == pytest.approx([-0.01, 0.0, 0.005, 0.01, 0.01, 0.0, -0.01])
    assert kept(0.03, 0.02) == 0.02 and kept(-0.01, 0.02) == 0.0


def test_the_held_angle_stands_for_the_healthy_one_only_when_steady() -> None:
    assert steady([0.0, 0.5 * STEADY_MOVE, STEADY_MOVE])
    assert not steady([0.0, 1.01 * STEADY_MOVE])
    assert not steady([])


def test_the_onset_step_is_the_first_at_or_after_the_onset() -> None:
    t = [0.0, 0.002, 0.004]
    assert onset_step(t, 0.002) == 1
    assert onset_step(t, 0.002 + 1e-10) == 1  # (k ts may fall short of an onset on the grid)
    assert onset_step(t, 0.003) == 2
    assert onset_step(np.array(t), 0.0) == 0
    assert onset_step(t, 0.01) is None
