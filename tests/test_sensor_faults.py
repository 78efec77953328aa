"""Sensor faults in well-formed frames: what reaches the bus for each kind, the redundant sensors'
frame, and the fault specs' errors."""

from __future__ import annotations

import math
from dataclasses import replace

import can
import numpy as np
import pytest

import mrsteer_dbc
from mrsteer_dbc import E2EStatus, names
from mrsteer_dbc.link import RxLink
from sim_plant.car import scenario as scn
from sim_plant.car.model_files import ModelFileError
from sim_plant.car.sensor_faults import SensorFault, fault_from_mapping, parse_spec
from sim_plant.car.sensors import SensorConfig, Sensors
from sim_plant.nodes.plant import PlantNode, build_parser

C = mrsteer_dbc.load()
TS = 2e-3
STEPS = 600  # 1.2 s
ONSET = 0.7
LSB = {names.SIG_YAW_RATE: 1e-4, names.SIG_STEER_ANGLE: 2.5e-5,
       names.SIG_LAT_ACCEL: C.message(names.MSG_REDUNDANT).get_signal_by_name(names.SIG_LAT_ACCEL).scale,
       names.SIG_STEER_ANGLE_2: 2.5e-5, names.SIG_SPEED: 2e-3}


def bus_run(channel: str, faults: tuple[SensorFault, ...] = (), scenario: str = "handover",
            sensors: SensorConfig | None = None) -> dict[str, list[tuple[float, dict[str, float]]]]:
    """The plant alone on a virtual bus (no controller): every sensor frame it sent, accepted
    by a receive link, as (send time, signals) per message."""
    sc = scn.load(scenario).with_sensor_faults(faults)
    if sensors is not None:
        sc = replace(sc, sensors=sensors)
    plant_bus = can.Bus(interface="virtual", channel=channel)
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        node = PlantNode(plant_bus, sc, mode="lockstep", ts=TS, expect_controller=False)
        rx = RxLink(C, names.VEHICLE_SENSORS)
        out: dict[str, list[tuple[float, dict[str, float]]]] = {n: [] for n in names.VEHICLE_SENSORS}
        for k in range(STEPS):
            node.step(k)
            while (msg := listener.recv(0.0)) is not None:
                got = rx.accept(msg)
                if msg.arbitration_id == C.frame_id(names.MSG_SYNC):
                    continue
                assert got.status in (E2EStatus.OK, E2EStatus.INITIAL), got  # well-formed, counter advancing
                out[got.name].append((k * TS, got.signals))
        return out
    finally:
        plant_bus.shutdown()
        listener.shutdown()


def series(run, signal: str) -> tuple[np.ndarray, np.ndarray]:
    message = {names.SIG_YAW_RATE: names.MSG_YAW, names.SIG_STEER_ANGLE: names.MSG_STEER,
               names.SIG_SPEED: names.MSG_SPEED, names.SIG_LAT_ACCEL: names.MSG_REDUNDANT,
               names.SIG_STEER_ANGLE_2: names.MSG_REDUNDANT, names.SIG_YAW_RATE_2: names.MSG_YAW}[signal]
    rows = run[message]
    return np.array([t for t, _ in rows]), np.array([s[signal] for _, s in rows])


@pytest.fixture
def clean(channel: str):
    return bus_run(channel + "-clean")


def test_the_redundant_frame_is_sent_at_its_dbc_cycle_with_a_y_and_the_second_angle(channel: str) -> None:
    run = bus_run(channel)
    t, ay = series(run, names.SIG_LAT_ACCEL)
    assert np.diff(t) == pytest.approx(0.05)  # GenMsgCycleTime 50 ms
    _, steer2 = series(run, names.SIG_STEER_ANGLE_2)
    t1, steer1 = series(run, names.SIG_STEER_ANGLE)
    # ideal sensors: the second channel is the first one at the same instants
    assert steer2 == pytest.approx(np.interp(t, t1, steer1), abs=LSB[names.SIG_STEER_ANGLE])
    # a_y = v (beta' + r): in the yaw-moment scenario the car turns, and a_y follows v r in steady state
    ty, r = series(run, names.SIG_YAW_RATE)
    late = t > 1.0
    assert np.abs(ay[late]).max() > 1.0
    assert ay[late] == pytest.approx(25.0 * np.interp(t[late], ty, r), rel=0.1)


def test_lat_accel_sensor_model_noise_and_quantisation() -> None:
    s = Sensors(SensorConfig(seed=4), TS)
    x = np.array([s.lat_accel(0.0) for _ in range(20000)])
    # 180 ug/rtHz through the 30 Hz Butterworth: sigma^2 ~ N^2 * B_noise, B_noise = 30 pi / (2 sqrt 2)... bounded
    raw = 180e-6 * 9.80665 * math.sqrt(250.0)
    assert 0.2 * raw < x.std() < 0.6 * raw
    assert np.allclose(np.round(x / 1e-3) * 1e-3, x, atol=1e-12)
    ideal = Sensors(SensorConfig.ideal(), TS)
    assert (ideal.lat_accel(3.21), ideal.steer_redundant(-0.0123)) == (3.21, -0.0123)


ONSET_FAULTS = [
    ("bias", 0.05, lambda t, clean: clean + 0.05),
    ("scale", 1.5, lambda t, clean: clean * 1.5),
    ("drift", 0.02, lambda t, clean: clean + 0.02 * (t - ONSET)),
    ("stuck", 0.01, lambda t, clean: np.full_like(clean, 0.01)),
]


@pytest.mark.parametrize("kind, value, expected", ONSET_FAULTS, ids=[f[0] for f in ONSET_FAULTS])
def test_yaw_rate_fault_kinds_on_the_bus(channel: str, clean, kind: str, value: float, expected) -> None:
    run = bus_run(channel, (SensorFault("yaw_rate", kind, ONSET, value),))
    t, faulted = series(run, names.SIG_YAW_RATE)
    _, base = series(clean, names.SIG_YAW_RATE)
    before, after = t < ONSET - 1e-9, t >= ONSET - 1e-9
    assert np.array_equal(faulted[before], base[before])
    # The faulted and the clean value each rounded to the LSB (scale: 1.5 times the clean one's error)
    assert faulted[after] == pytest.approx(expected(t[after], base[after]), abs=1.26 * LSB[names.SIG_YAW_RATE])
    assert np.abs(faulted[after] - base[after]).max() > 1e-3  # the fault is visible


def test_the_yaw_rate_frame_carries_both_elements_and_a_fault_on_one_leaves_the_other(channel: str, clean) -> None:
    _, first = series(clean, names.SIG_YAW_RATE)
    _, second = series(clean, names.SIG_YAW_RATE_2)
    assert np.array_equal(first, second) and np.ptp(first) > 1e-2  # ideal sensors: the same car, moving
    run = bus_run(channel, (SensorFault("yaw_rate_redundant", "stuck", ONSET, 0.0),))
    t, faulted = series(run, names.SIG_YAW_RATE_2)
    _, untouched = series(run, names.SIG_YAW_RATE)
    after = t >= ONSET - 1e-9
    assert np.array_equal(untouched, first)  # no controller: the car is the clean run's
    assert np.array_equal(faulted[~after], second[~after]) and np.all(faulted[after] == 0.0)


def test_stuck_without_a_value_holds_the_value_at_onset(channel: str, clean) -> None:
    run = bus_run(channel, (SensorFault("yaw_rate", "stuck", ONSET),))
    t, faulted = series(run, names.SIG_YAW_RATE)
    _, base = series(clean, names.SIG_YAW_RATE)
    at = int(np.searchsorted(t, ONSET - 1e-9))
    assert np.all(faulted[at:] == base[at]) and np.ptp(base[at:]) > 1e-2  # the car yaws, the sensor not


def test_stuck_keeps_the_sensor_noise_and_frozen_holds_the_output_bit_for_bit(channel: str) -> None:
    noisy = SensorConfig(seed=3)
    stuck = bus_run(channel + "-s", (SensorFault("yaw_rate", "stuck", ONSET, 0.0),), sensors=noisy)
    t, y = series(stuck, names.SIG_YAW_RATE)
    after = t >= ONSET + 0.05  # past the filter's settling
    assert abs(y[after].mean()) < 1.5e-3 and y[after].std() > 1e-4  # noise around the stuck value (r ~ 0.2 rad/s)
    frozen = bus_run(channel + "-f", (SensorFault("yaw_rate", "frozen", ONSET),), sensors=noisy)
    clean = bus_run(channel + "-c", sensors=noisy)
    t, y = series(frozen, names.SIG_YAW_RATE)
    _, base = series(clean, names.SIG_YAW_RATE)
    at = int(np.searchsorted(t, ONSET - 1e-9))
    assert np.all(y[at:] == base[at - 1]) and np.array_equal(y[:at], base[:at])
    # every frozen frame was accepted with an advancing counter (bus_run asserts OK), so E2E passes


def test_noise_fault_adds_its_rms_after_onset_only(channel: str, clean) -> None:
    run = bus_run(channel, (SensorFault("lat_accel", "noise", 0.2, 0.5),))
    t, faulted = series(run, names.SIG_LAT_ACCEL)
    _, base = series(clean, names.SIG_LAT_ACCEL)
    before = t < 0.2 - 1e-9
    assert np.array_equal(faulted[before], base[before])
    assert np.std(faulted[~before] - base[~before]) == pytest.approx(0.5, rel=0.35)  # 20 samples


def test_redundant_steering_bias_and_a_fault_window(channel: str, clean) -> None:
    run = bus_run(channel, (SensorFault("steer_redundant", "bias", 0.5, 0.01, stop=0.9),))
    t, faulted = series(run, names.SIG_STEER_ANGLE_2)
    _, base = series(clean, names.SIG_STEER_ANGLE_2)
    window = (t >= 0.5 - 1e-9) & (t < 0.9 - 1e-9)
    assert faulted[window] - base[window] == pytest.approx(0.01, abs=3e-5)
    assert np.array_equal(faulted[~window], base[~window])


def test_scenario_table_and_command_line_spec(tmp_path) -> None:
    f = tmp_path / "s.toml"
    f.write_text('duration = 1.0\n[[sensor_fault]]\nsensor = "yaw_rate"\nkind = "drift"\nvalue = 0.0175\n'
                 'start = 0.5\n')
    sc = scn.load(str(f))
    assert sc.sensor_faults == (SensorFault("yaw_rate", "drift", 0.5, 0.0175),)
    assert sc.sensor_config.faults == sc.sensor_faults
    assert parse_spec("steer:frozen@2") == SensorFault("steer", "frozen", 2.0)
    assert parse_spec("yaw_rate:bias:-0.05@1.5") == SensorFault("yaw_rate", "bias", 1.5, -0.05)
    args = build_parser().parse_args(["--sensor-fault", "speed:scale:1.1@0", "--sensor-fault", "steer:stuck@1"])
    assert args.sensor_fault == ["speed:scale:1.1@0", "steer:stuck@1"]


@pytest.mark.parametrize("spec, words", [
    ("gyro:bias:1@0", "sensor must be one of"), ("yaw_rate:wobble:1@0", "kind must be one of"),
    ("yaw_rate:bias@0", "needs a value"), ("yaw_rate:frozen:1@0", "takes no value"),
    ("yaw_rate:bias:1", "expected SENSOR:KIND"), ("yaw_rate:bias:x@0", "must be numbers"),
    ("yaw_rate:noise:-1@0", "RMS must be >= 0"), ("yaw_rate:bias:nan@0", "finite"),
    ("yaw_rate:bias:1@-1", "start must be"),
])
def test_bad_fault_specs_are_one_line_errors(spec: str, words: str) -> None:
    with pytest.raises(ModelFileError, match=words) as err:
        parse_spec(spec)
    assert "\n" not in str(err.value)


def test_a_fault_that_starts_at_or_after_the_run_s_end_is_refused_by_both_commands() -> None:
    sc = scn.load("side-wind").with_overrides(duration=1.0)
    assert sc.with_sensor_faults((parse_spec("yaw_rate:bias:0.01@0.99"),)).sensor_faults[-1].start == 0.99
    for start in ("1", "9"):
        with pytest.raises(scn.ScenarioError, match=r"starts at or after the run's end \(1 s\)"):
            sc.with_sensor_faults((parse_spec(f"yaw_rate:bias:0.01@{start}"),))
    # the plant's command line (hil run's: tests/test_hil_realistic.py)
    with pytest.raises(SystemExit) as exit_:
        from sim_plant.nodes.plant import main as plant_main
        plant_main(["--scenario", "side-wind", "--duration", "1.0", "--sensor-fault", "yaw_rate:stuck:0.01@2"])
    assert exit_.value.code == 2


def test_bad_fault_tables_name_the_file(tmp_path) -> None:
    with pytest.raises(ModelFileError, match="unknown"):
        fault_from_mapping({"sensor": "steer", "kind": "bias", "value": 1, "when": 2}, "f.toml sensor_fault 1")
    f = tmp_path / "s.toml"
    f.write_text('duration = 1.0\n[[sensor_fault]]\nsensor = "steer"\nkind = "scale"\n')
    with pytest.raises(scn.ScenarioError, match=f"{f}.*needs a value"):
        scn.load(str(f))
    with pytest.raises(SystemExit):
        from sim_plant.nodes import plant
        plant.main(["--sensor-fault", "steer:bias@1", "--interface", "virtual"])


# ------------------------------------------------------------------ the fault bridge

from sim_plant.nodes.fault_bridge import Bridge, Fault  # noqa: E402

YAW_ID = C.frame_id(names.MSG_YAW)


def _yaw_frame(counter: int, value: float) -> can.Message:
    return can.Message(arbitration_id=YAW_ID, is_extended_id=False,
                       data=C.encode(names.MSG_YAW, {names.SIG_YAW_RATE: value}, counter))


@pytest.fixture
def bridge_of(channel: str):
    buses = [can.Bus(interface="virtual", channel=f"{channel}-{side}") for side in ("a", "b")]

    def make(kind: str, param: float = 1.0, target: str = names.MSG_YAW, signal: str | None = None) -> Bridge:
        b = Bridge(*buses, Fault(kind, target, 1.0, 2.0, param, signal))
        b.stats.t0 = 100.0
        return b

    yield make
    for b in buses:
        b.shutdown()


@pytest.mark.parametrize("kind, param, expected", [
    ("sensor_stuck", 0.01, lambda k, x: 0.01), ("sensor_bias", 0.05, lambda k, x: x + 0.05),
    ("sensor_scale", 1.5, lambda k, x: 1.5 * x), ("sensor_drift", 0.02, lambda k, x: x + 0.02 * (0.002 * k)),
    ("sensor_frozen", 0.0, lambda k, x: 0.1 + 0.001 * 9),
])
def test_the_bridge_falsifies_the_value_in_well_formed_frames(bridge_of, kind: str, param: float, expected) -> None:
    b = bridge_of(kind, param)
    rx = RxLink(C, (names.MSG_YAW,))
    for k in range(10):  # before the window
        (_, out), = b.transform(_yaw_frame(k, 0.1 + 0.001 * k), 100.9 + 0.002 * k)
        assert rx.accept(out).signals[names.SIG_YAW_RATE] == pytest.approx(0.1 + 0.001 * k)
    for k in range(20):
        value = 0.2 + 0.003 * k
        (_, out), = b.transform(_yaw_frame((10 + k) % 15, value), 101.0 + 0.002 * k)
        got = rx.accept(out)
        assert got.status in (E2EStatus.OK,)  # CRC valid, the counter advancing
        assert got.signals[names.SIG_YAW_RATE] == pytest.approx(expected(k, value), abs=0.51 * LSB[names.SIG_YAW_RATE])


def test_the_bridge_noise_and_the_redundant_frames_second_signal(bridge_of) -> None:
    b = bridge_of("sensor_noise", 0.05, target="redundant", signal=names.SIG_STEER_ANGLE_2)
    rid = C.frame_id(names.MSG_REDUNDANT)
    diffs = []
    for k in range(200):
        data = C.encode(names.MSG_REDUNDANT, {names.SIG_LAT_ACCEL: 1.0, names.SIG_STEER_ANGLE_2: 0.01}, k % 15)
        (_, out), = b.transform(can.Message(arbitration_id=rid, data=data, is_extended_id=False), 101.0 + 0.004 * k)
        got = C.decode(rid, bytes(out.data))
        assert got.status is E2EStatus.OK and got.signals[names.SIG_LAT_ACCEL] == pytest.approx(1.0)
        diffs.append(got.signals[names.SIG_STEER_ANGLE_2] - 0.01)
    assert np.std(diffs) == pytest.approx(0.05, rel=0.25)
    with pytest.raises(ValueError, match="sensor_"):
        Fault("drop", names.MSG_YAW, signal=names.SIG_YAW_RATE)
    with pytest.raises(KeyError):
        bridge_of("sensor_bias", 1.0, signal="NoSuchSignal")
