"""The plant node on the realistic car, in process on a virtual bus: the physical disturbances'
loads reach the car, braking lowers the speed the frames carry, the sensors' noise is seeded,
and the linear plant refuses the loads it cannot take."""

from __future__ import annotations

import math

import can
import numpy as np
import pytest

import mrsteer_dbc
from mrsteer_dbc import names
from sim_plant.car import disturbances as dist
from sim_plant.car import scenario as scn
from sim_plant.car.plants import Car
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.vehicle import VehicleParams
from sim_plant.nodes.plant import PlantNode

C = mrsteer_dbc.load()
TS = 0.002


def _play(channel: str, sc: scn.Scenario) -> tuple[PlantNode, list[can.Message]]:
    """The scenario in lockstep without a controller; every frame the plant sent."""
    bus, tap = can.Bus(interface="virtual", channel=channel), can.Bus(interface="virtual", channel=channel)
    try:
        node = PlantNode(bus, sc, mode="lockstep", ts=TS, expect_controller=False)
        node.record_trace = True
        node.run()
        frames = []
        while (m := tap.recv(0.0)) is not None:
            frames.append(m)
        return node, frames
    finally:
        bus.shutdown()
        tap.shutdown()


def _signal(frames: list[can.Message], message: str, signal: str) -> list[float]:
    fid = C.frame_id(message)
    return [C.decode(f.arbitration_id, f.data).signals[signal] for f in frames if f.arbitration_id == fid]


def test_split_mu_braking_slows_the_car_and_the_speed_frames_carry_it(channel: str) -> None:
    sc = scn.load("split-mu").with_overrides(duration=1.5).with_models(actuator="ideal", sensors="ideal")
    node, frames = _play(channel, sc)
    speeds = _signal(frames, names.MSG_SPEED, names.SIG_SPEED)
    trace = np.array(node.stats.trace)
    v = trace[:, PlantNode.TRACE_COLUMNS.index("v_m_s")]
    (brake,) = sc.disturbances
    # After the pressure build-up the car decelerates at (F_l + F_r) / m, the loads' a_x.
    a_x = brake.at(1.0).a_x
    i, j = int(round(0.8 / TS)), int(round(1.4 / TS))
    assert (v[i] - v[j]) / (j - i) / TS == pytest.approx(a_x, rel=1e-3)
    assert v[0] == 25.0 and v[-1] < 25.0 - 0.7 * a_x
    # Every speed frame is the integrated speed of its step, to the DBC's resolution.
    every = node.every[names.MSG_SPEED]
    assert speeds == pytest.approx(list(v[::every]), abs=C.message(names.MSG_SPEED).get_signal_by_name(
        names.SIG_SPEED).scale)
    # The split-mu moment yaws the car left (M_z > 0), the driver holding the wheel.
    r = trace[:, PlantNode.TRACE_COLUMNS.index("yaw_rate_rad_s")]
    assert r[-1] > 0.01 and brake.at(1.0).m_z > 0


def test_noisy_sensors_are_seeded_and_the_true_state_is_traced(channel: str) -> None:
    base = scn.load("paper-fig9").with_overrides(duration=0.5).with_models(sensors="default")
    runs = [_play(f"{channel}-{k}", base.with_models(seed=seed)) for k, seed in enumerate((1, 1, 2))]
    payloads = [[bytes(f.data) for f in frames] for _, frames in runs]
    assert payloads[0] == payloads[1] and payloads[0] != payloads[2]
    node, frames = runs[0]
    measured = np.array(_signal(frames, names.MSG_YAW, names.SIG_YAW_RATE))
    trace = np.array(node.stats.trace)
    true = trace[:, PlantNode.TRACE_COLUMNS.index("yaw_rate_rad_s")]
    traced = trace[:, PlantNode.TRACE_COLUMNS.index("yaw_rate_measured_rad_s")]
    assert measured == pytest.approx(traced, abs=1e-6)  # the frames carry the sensor's value
    # The speed as measured is traced beside the true one (a fault's error is their difference).
    halved = base.with_sensor_faults((SensorFault("speed", "scale", 0.2, 0.5),))
    faulty, faulty_frames = _play(f"{channel}-speed", halved)
    steps, every = np.array(faulty.stats.trace), faulty.every[names.MSG_SPEED]
    speeds = np.array(_signal(faulty_frames, names.MSG_SPEED, names.SIG_SPEED))
    v_measured = steps[::every, PlantNode.TRACE_COLUMNS.index("speed_measured_m_s")]
    v_true = steps[::every, PlantNode.TRACE_COLUMNS.index("v_m_s")]
    assert speeds == pytest.approx(v_measured, abs=0.002)
    assert v_measured[-1] == pytest.approx(0.5 * v_true[-1], abs=0.01)
    # Before the 0.5 s moment the car is still (r = 0): the sensor shows noise through its filter.
    assert np.all(true == 0.0) and 0.0 < np.std(measured) < math.radians(0.22)


def test_the_linear_car_takes_yaw_moments_only() -> None:
    car = Car("linear", VehicleParams(v=30.0), TS)
    car.set_loads(dist.Loads(m_z=100.0))
    with pytest.raises(ValueError, match="only yaw-moment loads"):
        car.set_loads(dist.SideWindGust(t_start=0.0).at(0.5))
    with pytest.raises(ValueError, match="plant must be one of"):
        Car("rigid", VehicleParams(), TS)


@pytest.mark.parametrize("argv", [
    ["plant", "--seed", "-1"], ["plant", "--plant", "bicycle"], ["hil", "run", "--seed", "x"],
    ["faults", "run", "--plant", "bicycle"],
])
def test_the_car_options_are_checked_alike_by_every_command(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    from mrsteer_cli.cli import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mrsteer: ") and ("--seed" in err[0] or "--plant" in err[0])
