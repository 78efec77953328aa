"""Physical disturbances of the realistic car (sim_plant.car.disturbances)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_plant.car.disturbances import (KINDS, NO_LOADS, SideWindGust, SplitMuBraking, TyreBlowout, parameter_names,
                                        sum_loads)
from sim_plant.car.nonlinear import NonlinearPlant
from sim_plant.car.tyres import INTACT, WheelGrip
from sim_plant.car.vehicle import VehicleParams

M, GRAV = 1296.0, 9.81


def test_split_mu_full_braking_is_limited_by_each_side_and_decelerates():
    b = SplitMuBraking()  # 1.0 / 0.2, 10 m/s^2 demanded, 1.5 m track
    assert b.at(0.49) == NO_LOADS
    loads = b.at(2.0)
    f_l, f_r = 1.0 * M * GRAV / 2, 0.2 * M * GRAV / 2  # both sides in ABS
    assert loads.m_z == pytest.approx((f_l - f_r) * 0.75, rel=1e-12)
    assert loads.m_z == pytest.approx(3814.13, abs=0.01)
    assert loads.a_x == pytest.approx(0.6 * GRAV, rel=1e-12)
    assert loads.grip.fl.mu == 1.0 and loads.grip.rr.mu == 0.2
    # a gentle stop that neither side's road limits gives no moment
    assert SplitMuBraking(deceleration=1.5).at(2.0).m_z == pytest.approx(0.0, abs=1e-9)
    # half way up the 1 - cos pressure ramp
    assert b.brake_forces(0.5 + 0.075)[0] == pytest.approx(0.5 * M * 10.0 / 2, rel=1e-12)


def test_split_mu_braking_slips_the_wheels_by_their_stiffness_or_at_abs_slip():
    # full braking: ABS holds both sides at its slip
    assert SplitMuBraking().at(2.0).wheel_slip == pytest.approx(0.15, rel=1e-12)
    # a gentle stop (1.5 m/s^2) under both caps: 0.05 per unit of force over load, a / g
    assert SplitMuBraking(deceleration=1.5).at(2.0).wheel_slip == pytest.approx(0.05 * 1.5 / GRAV, rel=1e-12)
    # the built-in scenario's 5 m/s^2 on 1.0 / 0.2: the ice side in ABS, the dry side rolling on
    assert SplitMuBraking(deceleration=5.0).at(2.0).wheel_slip == pytest.approx(
        0.5 * (0.05 * 5.0 / GRAV + 0.15), rel=1e-12)
    assert SplitMuBraking().at(0.49).wheel_slip == 0.0  # before the stop
    both = sum_loads([SplitMuBraking(t_start=0.0), TyreBlowout(t_start=0.0, wheel="fr")], 2.0)
    assert both.wheel_slip == SplitMuBraking(t_start=0.0).wheel_slip(2.0)  # a blow-out adds none


def test_split_mu_braking_slows_the_car_and_yaws_it_left():
    plant = NonlinearPlant(VehicleParams(v=25.0), 0.002)
    b = SplitMuBraking(t_start=0.0)
    for k in range(500):
        loads = b.at(k * 0.002)
        plant.set_grip(loads.grip)
        plant.advance(0.0, loads.m_z, loads.f_y, loads.a_x)
    assert plant.v < 25.0 - 0.8 * 0.6 * GRAV * (1.0 - 0.15)  # ~5 m/s slower after 1 s
    assert plant.x[1] > 0.05  # toward the high-mu side


def test_side_wind_gust_profile_and_moment_arm():
    g = SideWindGust(t_start=1.0, peak_force=1000.0, rise_time=0.2, hold_time=0.5, fall_time=0.4, cp_ahead=0.6)
    assert g.at(0.99) == NO_LOADS
    assert g.force(1.1) == pytest.approx(500.0, rel=1e-12)  # half way up the 1 - cos ramp
    assert g.force(1.5) == pytest.approx(1000.0)
    assert g.force(1.7 + 0.2) == pytest.approx(500.0, rel=1e-12)
    assert g.force(3.0) == 0.0
    loads = g.at(1.5)
    assert (loads.f_y, loads.m_z, loads.a_x) == pytest.approx((1000.0, 600.0, 0.0))
    t = np.linspace(0, 3, 3001)
    f = np.array([g.force(x) for x in t])
    assert np.abs(np.diff(f)).max() < 1000.0 * math.pi / 2 * 0.001 / 0.2 * 1.01  # smooth, no step


def test_blowout_front_left_pulls_left_and_weakens_that_wheel():
    b = TyreBlowout(t_start=0.0, wheel="fl", stiffness_loss=0.8, peak_loss=0.5, rolling_resistance=0.15,
                    deflation_time=0.2)
    f_zf = M * GRAV * 1.32 / 2.57
    loads = b.at(1.0)
    drag = 0.15 * f_zf / 2
    assert loads.m_z == pytest.approx(drag * 0.75, rel=1e-12)
    assert loads.a_x == pytest.approx(drag / M, rel=1e-12)
    assert loads.grip.fl.stiffness == pytest.approx(0.2) and loads.grip.fl.peak == pytest.approx(0.5)
    assert loads.grip.fr == WheelGrip()
    right_rear = TyreBlowout(t_start=0.0, wheel="rr").at(1.0)
    assert right_rear.m_z < 0 and right_rear.grip.rr.stiffness < 1
    half = b.at(0.1)  # mid-deflation
    assert half.grip.fl.stiffness == pytest.approx(0.6)


def test_sum_of_disturbances_adds_loads_and_composes_grip():
    total = sum_loads([SplitMuBraking(t_start=0.0), TyreBlowout(t_start=0.0, wheel="fr")], 2.0)
    assert total.grip.fr.mu == 0.2 and total.grip.fr.stiffness == pytest.approx(0.2)
    assert total.m_z == pytest.approx(SplitMuBraking(t_start=0.0).at(2.0).m_z + TyreBlowout(t_start=0.0, wheel="fr").at(2.0).m_z)
    assert sum_loads([], 1.0).grip == INTACT


@pytest.mark.parametrize("cls, name, value", [
    (SplitMuBraking, "mu_left", 0.0), (SplitMuBraking, "deceleration", -1.0), (SplitMuBraking, "track_width", 9.0),
    (SideWindGust, "rise_time", -0.1), (SideWindGust, "peak_force", math.inf),
    (TyreBlowout, "stiffness_loss", 1.0), (TyreBlowout, "wheel", "front"), (TyreBlowout, "rolling_resistance", True),
])
def test_every_parameter_is_range_checked_with_a_one_line_message_naming_it(cls, name, value):
    with pytest.raises(ValueError) as err:
        cls(**{name: value})
    assert name in str(err.value) and "\n" not in str(err.value)


def test_kinds_name_their_parameters():
    assert set(KINDS) == {"split_mu_braking", "side_wind", "blowout"}
    assert "mu_right" in parameter_names("split_mu_braking")
