"""``mrsteer sim ... --plant nonlinear``: the firmware's ``step()`` against the bus runs' realistic
car (``plants.Car``, magic-formula tyres), with the actuator and sensor models.  At small slip it
is the paper's linear car; where the tyres saturate it is not; what it cannot run is refused."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from firmware_py import model_regulator as mr
from mrsteer_cli.cli import main
from sim_plant.car.plants import Car
from sim_plant.car.vehicle import VehicleParams
from sim_plant.offline import experiments
from sim_plant.offline.loop_plant import LoopModels

TS = 0.002
G = 9.81


def _sim(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    assert main(["sim", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("models", ["ideal", "default"])
def test_linear_and_nonlinear_agree_at_small_slip(models: str, capsys: pytest.CaptureFixture[str]) -> None:
    # 500 N m at 20 m/s on mu 1: slip angles of about 0.1 deg, where the tyres are linear.
    argv = ("disturbance", "--mz", "500", "--v", "20", "--mu", "1", "--ts", "0.002", "--actuator", models,
            "--sensors", models)
    lin, non = _sim(capsys, *argv, "--plant", "linear"), _sim(capsys, *argv, "--plant", "nonlinear")
    assert (lin["plant"], non["plant"]) == ("linear", "nonlinear")
    assert lin["peak_yaw_rate_rad_s"] > 0.004  # the disturbance moved the car
    for key in ("peak_yaw_rate_rad_s", "final_yaw_rate_rad_s"):
        assert abs(lin[key] - non[key]) < 1e-3, key
    assert non["peak_side_slip_deg"] < 0.2 and non["final_speed_m_s"] == pytest.approx(20.0)
    assert non["stable"] is None and lin["stable"] is True  # the poles are the linear loop's
    # the whole trace, not only its figures
    exp = experiments.disturbance(VehicleParams(v=20.0, mu=1.0), 500.0, mr.Q_LIMITED, mr.ControllerConfig())
    loop = LoopModels.ideal() if models == "ideal" else LoopModels.reference()
    a, b = (experiments.run(exp, TS, 1, loop, plant) for plant in ("linear", "nonlinear"))
    assert np.max(np.abs(a.yaw_rate - b.yaw_rate)) < 1e-3
    # the commands too (with noisy quantised sensors a reading now and then falls on the other side
    # of a quantisation step: 0.015 deg)
    assert np.max(np.abs(a.aux - b.aux)) < math.radians(0.01 if models == "ideal" else 0.05)


def test_they_differ_where_the_tyres_saturate(capsys: pytest.CaptureFixture[str]) -> None:
    # A driver's step sized for 1 rad/s of steady yaw rate on a dry road, on mu 0.3: the linear
    # car corners at 14 m/s^2, the tyres can give at most mu g = 2.9 m/s^2.
    exp = experiments.steer(VehicleParams(v=20.0, mu=0.3), "none", mr.ControllerConfig())
    lin, non = (experiments.run(exp, TS, 1, plant=plant) for plant in ("linear", "nonlinear"))
    assert np.max(np.abs(lin.lat_accel)) > 3.0 * 0.3 * G
    assert np.max(np.abs(non.lat_accel)) <= 0.3 * G * 1.001
    assert abs(lin.yaw_rate[-1] - non.yaw_rate[-1]) > 0.1
    argv = ("steer", "--v", "20", "--mu", "0.3", "--ts", "0.002", "--controller", "none")
    a, b = _sim(capsys, *argv), _sim(capsys, *argv, "--plant", "nonlinear")
    assert a["final_yaw_rate_norm"] == pytest.approx(lin.yaw_rate[-1])
    assert b["final_yaw_rate_norm"] == pytest.approx(non.yaw_rate[-1])


def test_the_nonlinear_loop_steps_the_plant_nodes_car() -> None:
    # No controller, ideal models: the sim's car is plants.Car stepped with the inputs held, as the
    # plant node steps it, to the last bit.
    p = VehicleParams(v=25.0, mu=0.5)
    exp = experiments.disturbance(p, 3000.0, "none", mr.ControllerConfig(), duration=0.5)
    trace = experiments.run(exp, TS, 1, plant="nonlinear")
    car = Car("nonlinear", p, TS)
    r = []
    for _ in range(len(trace.t)):
        r.append(float(car.x[1]))
        car.advance(0.0, 3000.0)
    assert np.array_equal(trace.yaw_rate, np.array(r))


@pytest.mark.parametrize("argv", [
    ["--ts", "0"],  # the continuous reference is of the linear car
    ["--k", "10", "--tau", "0.006"],  # constant gains select --ts 0
])
def test_what_the_nonlinear_car_cannot_run_is_one_line_and_exit_2(argv: list[str],
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["sim", "disturbance", "--mz", "500", "--v", "20", "--mu", "1", "--plant", "nonlinear", *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("mrsteer: sim disturbance: ") and "--ts" in err
    assert "Traceback" not in err


def test_the_text_output_names_the_plant_and_prints_no_dict(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "steer", "--v", "20", "--mu", "0.5", "--plant", "nonlinear"]) == 0
    out = capsys.readouterr().out
    assert "nonlinear" in out and "scheduled over v 5/10/20/30/40/50 m/s" in out
    assert "{" not in out and "[" not in out


def test_a_car_that_spins_ends_the_run_there_with_the_campaigns_rule(capsys: pytest.CaptureFixture[str]) -> None:
    """4000 N m on the uncontrolled nonlinear car: its side slip passes 30 deg near 2 s.  The run
    ends at that step (the tyre model is no longer the car), as a campaign's does: the figures
    are those up to it, the side slip no further than one step past the bound."""
    result = _sim(capsys, "disturbance", "--mz", "4000", "--v", "20", "--mu", "1", "--plant", "nonlinear",
                   "--controller", "none")
    assert result["spun"] is True and 1.5 < result["spin_time_s"] < 2.5
    assert 30.0 < result["peak_side_slip_deg"] < 31.0  # the spin step's |beta|, wrapped: not 185 deg
    held = _sim(capsys, "disturbance", "--mz", "4000", "--v", "20", "--mu", "1", "--plant", "nonlinear")
    assert held["spun"] is False and held["spin_time_s"] is None and held["peak_side_slip_deg"] < 2.0
