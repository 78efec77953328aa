"""Scenario files, built-ins, and the driver model."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim_plant.car import scenario as scn
from sim_plant.car.scenario_play import ScenarioState
from sim_plant.car.vehicle import VehicleParams, nominal_yaw_gain


def _write(tmp_path: Path, text: str) -> str:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return str(p)


def test_builtins_exist() -> None:
    for name in ("paper-fig8", "paper-fig9", "handover"):
        sc = scn.load(name)
        assert sc.name == name and sc.duration > 0
    assert scn.load("paper-fig9").events[0] == scn.Event(0.5, "yaw_moment", 4000.0)


def test_file_round_trip(tmp_path: Path) -> None:
    sc = scn.load(_write(tmp_path, """
name = "mine"
duration = 4.0
v = 25.0
mu = 0.8
[driver]
mode = "model"
reaction_time = 1.5
[[events]]
t = 2.0
mu = 0.4
[[events]]
t = 0.5
yaw_moment = -3000
"""))
    assert sc.name == "mine" and sc.v == 25.0 and sc.mu == 0.8
    assert [e.kind for e in sc.events] == ["yaw_moment", "mu"]  # sorted by time
    assert sc.driver == scn.DriverModel("model", 1.5, 0.5)


@pytest.mark.parametrize("text,needle", [
    ("duration = 2\nspeed = 3", "unknown key 'speed'"),
    ("v = 20", "'duration' is required"),
    ("duration = -1", "duration"),
    ("duration = 2\nmu = 0", "mu"),
    ("duration = 2\nv = 200", "v must be"),
    ("duration = 2\n[driver]\nreaction_time = 3", "reaction_time"),
    ("duration = 2\n[driver]\nmode = 'sleepy'", "driver mode"),
    ("duration = 2\n[[events]]\nt = 1\n", "exactly one of"),
    ("duration = 2\n[[events]]\nt = 5\nyaw_moment = 1", "outside"),
    ("duration = 2\n[[events]]\nt = 1\nyaw_moment = 'big'", "finite number"),
    ("duration = 2\n[[events]]\nt = 1\nyaw_moment = nan", "finite number"),
    ("duration = [", "not valid TOML"),
])
def test_bad_files_name_the_problem(tmp_path: Path, text: str, needle: str) -> None:
    with pytest.raises(scn.ScenarioError, match=needle) as info:
        scn.load(_write(tmp_path, text))
    assert "s.toml" in str(info.value)


def test_unknown_name_lists_the_builtins() -> None:
    with pytest.raises(scn.ScenarioError, match="paper-fig9"):
        scn.load("no-such-scenario")


def test_overrides_replace_operating_point_and_yaw_moments() -> None:
    sc = scn.load("paper-fig9").with_overrides(v=31.0, mu=0.7, mz=1234.0)
    assert (sc.v, sc.mu) == (31.0, 0.7) and sc.events[0].value == 1234.0
    with pytest.raises(scn.ScenarioError):
        scn.load("paper-fig9").with_overrides(v=-1.0)


def test_steer_norm_is_the_figure8_normalisation() -> None:
    st = ScenarioState(scn.load("paper-fig8"))
    st.advance_to(1.0)
    assert st.steer_intent == pytest.approx(1.0 / nominal_yaw_gain(20.0))


def test_driver_holds_during_panic_then_steers_back() -> None:
    sc = scn.Scenario("t", 5.0, v=20.0, events=(scn.Event(0.5, "yaw_moment", 3000.0),),
                      driver=scn.DriverModel("model", 1.0, 0.5))
    st = ScenarioState(sc)
    dt = 0.01
    angles = []
    for k in range(400):
        t = k * dt
        st.advance_to(t)
        angles.append(st.driver_angle(t, 0.1 if t >= 0.5 else 0.0, dt))  # the car yaws after the hit
    a = dict(zip([round(k * dt, 2) for k in range(400)], angles))
    assert a[0.4] == 0.0 and a[1.4] == 0.0  # panic reaction time: the wheel is held
    assert a[1.6] < 0.0  # then the driver counter-steers
    assert a[3.9] < a[1.6]  # and keeps integrating while the error persists
    hold = ScenarioState(scn.load("paper-fig9"))
    hold.advance_to(2.0)
    assert hold.driver_angle(2.0, 0.1, dt) == 0.0  # "hold" never steers


def test_the_correction_gain_is_how_far_the_drivers_angle_moves_per_yaw_rate_error() -> None:
    # Two drivers in the same state see yaw rates 0.01 rad/s apart: their angles differ by the
    # gain times that, in the panic window by nothing; the "hold" driver never corrects.
    dt = 0.002
    for t in (0.2, 0.7, 1.6):  # before the yaw moment, in the panic time, correcting
        st, other = (ScenarioState(scn.load("handover")) for _ in range(2))
        for s in (st, other):
            s.advance_to(t)
        gain = st.correction_gain(t, dt)
        difference = st.driver_angle(t, 0.1, dt) - other.driver_angle(t, 0.11, dt)
        assert difference == pytest.approx(0.01 * gain, rel=1e-9, abs=1e-15)
        assert (gain == 0.0) == (t == 0.7)
    assert st.correction_gain(1.6, dt) == pytest.approx(dt / 0.5 / nominal_yaw_gain(st.v))
    hold = ScenarioState(scn.load("paper-fig9"))
    hold.advance_to(2.0)
    assert hold.correction_gain(2.0, dt) == 0.0


def test_mu_and_speed_events_change_the_operating_point() -> None:
    sc = scn.Scenario("t", 3.0, events=(scn.Event(1.0, "mu", 0.3), scn.Event(2.0, "speed", 30.0)))
    st = ScenarioState(sc)
    assert not st.advance_to(0.5)
    assert st.advance_to(1.0) and st.params() == VehicleParams(v=20.0, mu=0.3)
    assert st.advance_to(2.5) and st.params().v == 30.0
    assert st.panic_until == 1.0 + sc.driver.reaction_time  # a friction drop also startles the driver


# ---------------------------------------------------------------- the realistic car's keys

from sim_plant.car import disturbances as dist  # noqa: E402
from sim_plant.car.actuator_dynamics import ActuatorModelConfig  # noqa: E402
from sim_plant.car.sensors import SensorConfig  # noqa: E402


def test_a_file_without_the_new_keys_is_the_papers_ideal_car(tmp_path: Path) -> None:
    sc = scn.load(_write(tmp_path, "duration = 1\n[[events]]\nt = 0.5\nyaw_moment = 100"))
    assert sc.plant == "linear" and sc.actuator == ActuatorModelConfig.ideal() and sc.sensors == SensorConfig.ideal()
    assert sc.ideal_car and sc.disturbances == ()
    for name in ("paper-fig8", "paper-fig9", "handover"):
        assert scn.load(name).ideal_car


def test_plant_actuator_sensors_and_disturbances_are_read_from_the_file(tmp_path: Path) -> None:
    sc = scn.load(_write(tmp_path, """
duration = 3
v = 25
mass = 1500
plant = "nonlinear"
[actuator]
time_constant_s = 0.03
[sensors]
seed = 7
[sensors.yaw_rate]
lowpass_hz = 20.0
[[events]]
t = 0.5
split_mu_braking = { mu_left = 0.9, mu_right = 0.3, deceleration = 4.0 }
[[events]]
t = 1.0
side_wind = {}
[[events]]
t = 2.0
blowout = { wheel = "rr" }
"""))
    assert sc.plant == "nonlinear" and sc.actuator.time_constant_s == 0.03 and sc.actuator.order == 1
    assert sc.sensors.seed == 7 and sc.sensors.yaw_rate.lowpass_hz == 20.0 and not sc.sensors.exact
    assert sc.disturbances == (dist.SplitMuBraking(t_start=0.5, mu_left=0.9, mu_right=0.3, deceleration=4.0,
                                                   mass=1500.0),
                               dist.SideWindGust(t_start=1.0), dist.TyreBlowout(t_start=2.0, wheel="rr", mass=1500.0))
    assert sc.first_disturbance_time == 0.5
    # The loads at t are those of the disturbances themselves, added.
    state = ScenarioState(sc)
    assert state.loads(0.4) == dist.NO_LOADS
    assert state.loads(1.2) == sc.disturbances[0].at(1.2) + sc.disturbances[1].at(1.2)
    # A disturbance shocks the driver like a mu change: the panic reaction time starts.
    state.advance_to(0.5)
    assert state.panic_until == 0.5 + sc.driver.reaction_time


@pytest.mark.parametrize("text,needle", [
    ("duration = 2\nplant = 'bicycle'", "plant must be one of linear, nonlinear"),
    ("duration = 2\n[[events]]\nt = 1\nside_wind = {}", "linear plant takes only yaw-moment loads; side_wind"),
    ("duration = 2\nplant = 'nonlinear'\n[[events]]\nt = 1\nside_wind = { gust = 1 }", "unknown key 'gust'"),
    ("duration = 2\nplant = 'nonlinear'\n[[events]]\nt = 1\nside_wind = { t_start = 1 }", "unknown key 't_start'"),
    ("duration = 2\nplant = 'nonlinear'\n[[events]]\nt = 1\nblowout = { mass = 900 }", "unknown key 'mass'"),
    ("duration = 2\nplant = 'nonlinear'\n[[events]]\nt = 1\nblowout = { wheel = 'spare' }", "wheel must be one of"),
    ("duration = 2\nplant = 'nonlinear'\n[[events]]\nt = 1\nsplit_mu_braking = { mu_right = 0 }", "mu_right must be"),
    ("duration = 2\nplant = 'nonlinear'\n[[events]]\nt = 1\nside_wind = { peak_force = 'x' }", "must be a number"),
    ("duration = 2\nplant = 'nonlinear'\n[[events]]\nt = 1\nside_wind = 3", "must be a table"),
    ("duration = 2\n[actuator]\ntime_constant_s = 0", "'time_constant_s' must be a number in (0, 1]"),
    ("duration = 2\n[actuator]\nlag = 1", "unknown key 'lag'"),
    ("duration = 2\nactuator = 3", "must be a table"),
    ("duration = 2\n[sensors.yaw_rate]\nnoise_density = -1", "'noise_density' must be a number in [0, 10]"),
    ("duration = 2\n[sensors]\nseed = -1", "'seed' must be an integer"),
])
def test_bad_car_keys_name_the_problem_in_one_line(tmp_path: Path, text: str, needle: str) -> None:
    with pytest.raises(scn.ScenarioError) as info:
        scn.load(_write(tmp_path, text))
    assert needle in str(info.value) and "s.toml" in str(info.value) and "\n" not in str(info.value)


def test_the_command_line_choices_override_the_files(tmp_path: Path) -> None:
    sc = scn.load("split-mu")
    assert (sc.plant, sc.actuator, sc.sensors) == ("nonlinear", ActuatorModelConfig.default(), SensorConfig.default())
    ideal = sc.with_models(actuator="ideal", sensors="ideal", seed=None)
    assert ideal.actuator == ActuatorModelConfig.ideal() and ideal.sensors.exact and ideal.plant == "nonlinear"
    assert sc.with_models(seed=5).sensors == SensorConfig(seed=5)
    assert sc.with_models() == sc
    f = tmp_path / "act.toml"
    f.write_text("order = 2\nnatural_frequency_hz = 10.0\n")
    assert scn.load("paper-fig9").with_models("nonlinear", str(f)).actuator == ActuatorModelConfig(
        order=2, natural_frequency_hz=10.0)
    with pytest.raises(scn.ScenarioError, match="linear plant takes only yaw-moment loads"):
        sc.with_models(plant="linear")
    with pytest.raises(scn.ScenarioError, match="no such file"):
        sc.with_models(sensors=str(tmp_path / "none.toml"))
    with pytest.raises(scn.ScenarioError, match="seed must be"):
        sc.with_models(seed=-1)
    # The car's mass reaches the disturbances that depend on it.
    assert sc.with_overrides(mass=1600.0).disturbances[0].mass == 1600.0


def test_the_realistic_builtins_are_the_named_events_on_the_realistic_car() -> None:
    split, wind, blow = (scn.load(n) for n in ("split-mu", "side-wind", "blow-out"))
    for sc in (split, wind, blow):
        assert not sc.ideal_car and sc.driver == scn.DriverModel("model", 1.0, 0.5)
        assert sc.plant == "nonlinear" and sc.actuator == ActuatorModelConfig.default() and not sc.sensors.exact
    (b,), (w,), (o,) = split.disturbances, wind.disturbances, blow.disturbances
    assert (split.v, b.mu_left, b.mu_right) == (25.0, 1.0, 0.2) and isinstance(b, dist.SplitMuBraking)
    assert wind.v == 30.0 and isinstance(w, dist.SideWindGust) and blow.v == 30.0 and isinstance(o, dist.TyreBlowout)
