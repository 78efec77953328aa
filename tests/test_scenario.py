"""Scenario files, built-ins, and the driver model."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim_plant.car import scenario as scn
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
    st = scn.ScenarioState(scn.load("paper-fig8"))
    st.advance_to(1.0)
    assert st.steer_intent == pytest.approx(1.0 / nominal_yaw_gain(20.0))


def test_driver_holds_during_panic_then_steers_back() -> None:
    sc = scn.Scenario("t", 5.0, v=20.0, events=(scn.Event(0.5, "yaw_moment", 3000.0),),
                      driver=scn.DriverModel("model", 1.0, 0.5))
    st = scn.ScenarioState(sc)
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
    hold = scn.ScenarioState(scn.load("paper-fig9"))
    hold.advance_to(2.0)
    assert hold.driver_angle(2.0, 0.1, dt) == 0.0  # "hold" never steers


def test_mu_and_speed_events_change_the_operating_point() -> None:
    sc = scn.Scenario("t", 3.0, events=(scn.Event(1.0, "mu", 0.3), scn.Event(2.0, "speed", 30.0)))
    st = scn.ScenarioState(sc)
    assert not st.advance_to(0.5)
    assert st.advance_to(1.0) and st.params() == VehicleParams(v=20.0, mu=0.3)
    assert st.advance_to(2.5) and st.params().v == 30.0
    assert st.panic_until == 1.0 + sc.driver.reaction_time  # a friction drop also startles the driver
