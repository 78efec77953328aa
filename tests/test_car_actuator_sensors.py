"""The realistic car's actuator and sensor models and their config files
(sim_plant.car.actuator_dynamics, .sensors, .model_files)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import freqz, lfilter, welch

import mrsteer_dbc
from sim_plant.car.actuator_dynamics import ActuatorModelConfig, PositionActuator
from sim_plant.car.model_files import ModelFileError
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import SensorConfig, Sensors, YawRateSensorConfig, ChannelConfig

TS = 0.002
DEG = math.radians(1.0)


def respond(actuator: PositionActuator, commands) -> np.ndarray:
    return np.array([actuator.step(float(c)) for c in commands])


# ------------------------------------------------------------------ actuator

@pytest.mark.parametrize("tau", [0.01, 0.02, 0.04])
def test_first_order_step_is_exact_at_the_samples(tau):
    y = respond(PositionActuator(ActuatorModelConfig(time_constant_s=tau), TS), [2 * DEG] * 200)
    t = TS * np.arange(1, 201)  # step() returns the position at the end of the held step
    assert y == pytest.approx(2 * DEG * (1 - np.exp(-t / tau)), abs=1e-12 * DEG, rel=1e-12)


@pytest.mark.parametrize("tau", [0.01, 0.02])
def test_mean_over_each_step_is_the_integral_of_the_exponential(tau):
    """What the car gets over a step: (1/ts) * integral of 2 deg (1 - e^{-t/tau}) over the step,
    integrated independently here with the trapezoid rule on a fine grid."""
    act = PositionActuator(ActuatorModelConfig(time_constant_s=tau), TS)
    for k in range(60):
        act.step(2 * DEG)
        t = np.linspace(k * TS, (k + 1) * TS, 2001)
        y = 2 * DEG * (1 - np.exp(-t / tau))
        assert act.mean == pytest.approx(float(np.sum((y[1:] + y[:-1]) / 2) / 2000), rel=1e-6)


def test_mean_of_a_rate_limited_ramp_is_its_midpoint():
    act = PositionActuator(ActuatorModelConfig(rate_limit_deg_s=40.0), TS)
    start = act.position
    end = act.step(3 * DEG)
    assert end == pytest.approx(40.0 * DEG * TS) and act.mean == pytest.approx(0.5 * (start + end))


def test_second_order_step_matches_the_underdamped_response():
    f_n, zeta = 8.0, 0.3
    y = respond(PositionActuator(ActuatorModelConfig(order=2, natural_frequency_hz=f_n, damping=zeta), TS),
                [1 * DEG] * 300)
    wn = 2 * math.pi * f_n
    wd = wn * math.sqrt(1 - zeta**2)
    t = TS * np.arange(1, 301)
    exact = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))
    assert y == pytest.approx(DEG * exact, abs=1e-12)
    assert y.max() > 1.3 * DEG  # it does overshoot (37 % at zeta 0.3)


def test_second_order_overshoot_stops_at_the_end_stop():
    y = respond(PositionActuator(ActuatorModelConfig(order=2, damping=0.2), TS), [3 * DEG] * 300)
    assert y.max() == pytest.approx(3 * DEG, rel=1e-15)


def test_rate_limit_gives_a_ramp_of_that_slope():
    rate = 40.0  # deg/s, well below the 20 ms lag's 150 deg/s for a 3 deg step
    y = respond(PositionActuator(ActuatorModelConfig(rate_limit_deg_s=rate), TS), [3 * DEG] * 100)
    slope = np.diff(np.concatenate([[0.0], y]))
    ramp = slope[: int(0.05 / TS)]
    assert ramp == pytest.approx(rate * DEG * TS, rel=1e-12)
    assert y[-1] == pytest.approx(3 * DEG * (1 - 0.0), rel=1e-2)


def test_dead_time_shifts_the_response_by_whole_samples():
    commands = np.sin(np.arange(200) * 0.05) * 2 * DEG
    plain = respond(PositionActuator(ActuatorModelConfig(), TS), commands)
    late = respond(PositionActuator(ActuatorModelConfig(dead_time_samples=3), TS), commands)
    assert late[:3] == pytest.approx(0.0, abs=0)
    assert late[3:] == pytest.approx(plain[:-3], rel=1e-15, abs=1e-18)


def test_commands_are_clamped_to_three_degrees_and_ideal_is_g_sa_one():
    y = respond(PositionActuator(ActuatorModelConfig(), TS), [5 * DEG] * 500 + [-7 * DEG] * 500)
    assert np.abs(y).max() <= 3 * DEG * (1 + 1e-15)
    assert y[499] == pytest.approx(3 * DEG, rel=1e-9) and y[-1] == pytest.approx(-3 * DEG, rel=1e-9)
    ideal = PositionActuator(ActuatorModelConfig.ideal(), TS)
    assert respond(ideal, [0.01, -0.02, 0.9, -0.9]) == pytest.approx([0.01, -0.02, 3 * DEG, -3 * DEG], rel=1e-15)


# ------------------------------------------------------------------ sensors

def yaw_series(config: SensorConfig, r, n: int) -> np.ndarray:
    s = Sensors(config, TS)
    return np.array([s.yaw_rate(r) for _ in range(n)])


def test_yaw_noise_density_from_a_long_seeded_sample():
    cfg = SensorConfig(YawRateSensorConfig(lowpass_hz=0.0, quantise=False), seed=7)
    x = yaw_series(cfg, 0.0, 2**18)
    f, pxx = welch(x, fs=1 / TS, nperseg=1024)  # one-sided density, (rad/s)^2/Hz
    density = math.degrees(math.sqrt(pxx[1:-1].mean()))
    assert density == pytest.approx(0.014, rel=0.05)
    assert math.degrees(x.std()) == pytest.approx(0.014 * math.sqrt(500 / 2), rel=0.01)  # sigma^2 = N^2 fs / 2
    # through the default 30 Hz filter the density below 5 Hz is unchanged
    y = yaw_series(SensorConfig(YawRateSensorConfig(quantise=False), seed=7), 0.0, 2**18)
    f, pyy = welch(y, fs=1 / TS, nperseg=1024)
    assert math.degrees(math.sqrt(pyy[(f > 0) & (f < 5)].mean())) == pytest.approx(0.014, rel=0.05)


def test_noise_is_reproducible_by_seed_and_streams_differ_by_seed():
    a = yaw_series(SensorConfig(seed=1), 0.1, 2000)
    assert np.array_equal(a, yaw_series(SensorConfig(seed=1), 0.1, 2000))
    assert not np.array_equal(a, yaw_series(SensorConfig(seed=2), 0.1, 2000))
    s = Sensors(SensorConfig(seed=1), TS)
    first = [s.yaw_rate(0.1) for _ in range(50)]
    s.reset()
    assert first == [s.yaw_rate(0.1) for _ in range(50)]


def test_lowpass_is_butterworth_30_hz_with_unit_dc_gain():
    s = Sensors(SensorConfig(), TS)
    b, a = s.lowpass
    _, h = freqz(b, a, worN=[0.0, 30.0, 100.0], fs=1 / TS)
    assert abs(h[0]) == pytest.approx(1.0, abs=1e-12)
    assert abs(h[1]) == pytest.approx(1 / math.sqrt(2), abs=1e-9)
    assert abs(h[2]) < 0.1  # 2nd order: ~ -21 dB at 100 Hz
    # the per-sample filter is lfilter's recurrence (noise and quantisation off, started at rest on 0)
    quiet = SensorConfig(YawRateSensorConfig(noise_density=0.0, quantise=False))
    x = np.concatenate([[0.0], np.sin(np.arange(999) * 0.3)])
    s = Sensors(quiet, TS)
    assert np.array([s.yaw_rate(v) for v in x]) == pytest.approx(lfilter(b, a, x), abs=1e-14)


def test_quantisation_steps_are_the_dbc_scales():
    contract = mrsteer_dbc.load()
    scale = {q: contract.message(m).get_signal_by_name(sig).scale for q, (m, sig) in
             {"yaw": ("MRS_YawRate", "YawRate_YawRate"), "steer": ("MRS_DriverSteer", "DriverSteer_Angle"),
              "speed": ("MRS_VehicleSpeed", "VehicleSpeed_Speed")}.items()}
    cfg = SensorConfig(YawRateSensorConfig(noise_density=0.0, lowpass_hz=0.0))
    s = Sensors(cfg, TS)
    for read, q, top in ((s.yaw_rate, "yaw", 0.01), (s.steer, "steer", 0.01), (s.speed, "speed", 20.1)):
        values = np.unique([read(float(x)) for x in np.linspace(top - 50 * scale[q], top, 1001)])
        assert np.diff(values) == pytest.approx(scale[q], rel=1e-6)
        assert len(values) in (50, 51)


def test_bias_shifts_the_mean_and_ideal_sensors_are_exact():
    biased = yaw_series(SensorConfig(YawRateSensorConfig(bias_deg_s=0.5), seed=3), 0.0, 20000)
    assert math.degrees(biased.mean()) == pytest.approx(0.5, abs=0.01)
    s = Sensors(SensorConfig.ideal(), TS)
    assert (s.yaw_rate(0.123456789), s.steer(-0.0123456789), s.speed(12.3456789)) == (0.123456789, -0.0123456789,
                                                                                      12.3456789)


def test_steer_and_speed_noise_have_the_configured_rms():
    cfg = SensorConfig(steer=ChannelConfig(noise=0.1, quantise=False), speed=ChannelConfig(noise=0.05, quantise=False))
    s = Sensors(cfg, TS)
    steer = np.array([s.steer(0.0) for _ in range(20000)])
    speed = np.array([s.speed(10.0) for _ in range(20000)])
    assert math.degrees(steer.std()) == pytest.approx(0.1, rel=0.03)
    assert speed.std() == pytest.approx(0.05, rel=0.03)


# ------------------------------------------------------------------ config files

def test_specs_ideal_default_and_a_file(tmp_path):
    assert ActuatorModelConfig.load("ideal").order == 0
    assert ActuatorModelConfig.load("default") == ActuatorModelConfig(1, 3.0, math.inf, 0.02, 8.0, 0.7, 0)
    f = tmp_path / "act.toml"
    f.write_text("order = 2\nnatural_frequency_hz = 12\ndamping = 0.8\nrate_limit_deg_s = inf\ndead_time_samples = 1\n")
    cfg = ActuatorModelConfig.load(str(f))
    assert (cfg.order, cfg.natural_frequency_hz, cfg.damping, cfg.dead_time_samples) == (2, 12.0, 0.8, 1)
    assert SensorConfig.load("ideal").exact and not SensorConfig.load("default").exact
    g = tmp_path / "sens.toml"
    g.write_text("seed = 5\n[yaw_rate]\nnoise_density = 0.02\nlowpass_hz = 0\n[speed]\nnoise = 0.01\n")
    s = SensorConfig.load(str(g))
    assert (s.seed, s.yaw_rate.noise_density, s.yaw_rate.lowpass_hz, s.speed.noise) == (5, 0.02, 0.0, 0.01)


@pytest.mark.parametrize("loader, text, key", [
    (ActuatorModelConfig.load, "order = 1\ntime_constant = 0.02\n", "time_constant"),
    (ActuatorModelConfig.load, "time_constant_s = 0\n", "time_constant_s"),
    (ActuatorModelConfig.load, "limit_deg = 45\n", "limit_deg"),
    (ActuatorModelConfig.load, "order = 3\n", "order"),
    (ActuatorModelConfig.load, "dead_time_samples = 1.5\n", "dead_time_samples"),
    (ActuatorModelConfig.load, "damping = true\n", "damping"),
    (SensorConfig.load, "[yaw_rate]\nnoise = 0.1\n", "noise"),
    (SensorConfig.load, "[yaw_rate]\nnoise_density = -1\n", "noise_density"),
    (SensorConfig.load, "[gyro]\n", "gyro"),
    (SensorConfig.load, "seed = -1\n", "seed"),
    (SensorConfig.load, "yaw_rate = 3\n", "yaw_rate"),
    (SensorConfig.load, "[steer]\nquantise = 1\n", "quantise"),
])
def test_bad_files_give_one_line_naming_key_and_file(tmp_path, loader, text, key):
    f = tmp_path / "model.toml"
    f.write_text(text)
    with pytest.raises(ModelFileError) as err:
        loader(str(f))
    message = str(err.value)
    assert key in message and str(f) in message and "\n" not in message


@pytest.mark.parametrize("loader", [ActuatorModelConfig.load, SensorConfig.load])
def test_missing_file_and_not_toml(tmp_path, loader):
    with pytest.raises(ModelFileError, match="no such file"):
        loader(str(tmp_path / "absent.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text("order = = 1\n[[")
    with pytest.raises(ModelFileError, match="not valid TOML") as err:
        loader(str(bad))
    assert "\n" not in str(err.value)


def test_direct_construction_is_range_checked_too():
    with pytest.raises(ModelFileError, match="time_constant_s"):
        ActuatorModelConfig(time_constant_s=-0.1)
    with pytest.raises(ModelFileError, match="noise_density"):
        YawRateSensorConfig(noise_density=-1.0)
    with pytest.raises(ModelFileError, match="noise"):
        ChannelConfig(noise=math.nan)
    with pytest.raises(ModelFileError, match="lowpass_hz"):
        Sensors(SensorConfig(YawRateSensorConfig(lowpass_hz=300.0)), TS)


# ------------------------------------------------------------------ the yaw-rate sensor's second element

def test_the_second_yaw_rate_element_has_its_own_stream_after_the_others():
    # numpy's SeedSequence children by index: the channels' five, the faults', then the element's.
    # Without filter and quantisation a reading is r + bias + sigma * that stream's next normal.
    quiet = YawRateSensorConfig(lowpass_hz=0.0, quantise=False)
    cfg = SensorConfig(quiet, seed=11, yaw_rate_redundant=YawRateSensorConfig(0.02, 0.5, 0.0, False),
                       faults=(SensorFault("steer", "noise", 0.0, 0.01),))
    s = Sensors(cfg, TS)
    first = np.array([s.yaw_rate(0.1) for _ in range(100)])
    second = np.array([s.yaw_rate_redundant(0.1) for _ in range(100)])
    children = np.random.SeedSequence(11).spawn(7)
    sigma = math.radians(0.014) * math.sqrt(0.5 / TS)
    assert first == pytest.approx(0.1 + sigma * np.random.default_rng(children[0]).standard_normal(100), abs=1e-15)
    sigma2 = math.radians(0.02) * math.sqrt(0.5 / TS)
    expected = 0.1 + math.radians(0.5) + sigma2 * np.random.default_rng(children[6]).standard_normal(100)
    assert second == pytest.approx(expected, abs=1e-15)


def test_a_fault_on_one_yaw_rate_element_leaves_the_other_reading_the_car():
    for faulted, read_faulted, read_other in (("yaw_rate", "yaw_rate", "yaw_rate_redundant"),
                                              ("yaw_rate_redundant", "yaw_rate_redundant", "yaw_rate")):
        s = Sensors(SensorConfig(exact=True, faults=(SensorFault(faulted, "stuck", 0.0, 0.01),)), TS)
        assert [getattr(s, read_faulted)(0.2) for _ in range(3)] == [0.01] * 3
        assert [getattr(s, read_other)(0.2) for _ in range(3)] == [0.2] * 3


def test_the_second_elements_table_takes_the_first_ones_keys_it_leaves_out(tmp_path):
    f = tmp_path / "sens.toml"
    f.write_text("[yaw_rate]\nnoise_density = 0.02\nlowpass_hz = 20\n[yaw_rate_redundant]\nbias_deg_s = -0.3\n")
    s = SensorConfig.load(str(f))
    assert s.yaw_rate_redundant == YawRateSensorConfig(0.02, -0.3, 20.0, True)
    assert s.yaw_rate == YawRateSensorConfig(0.02, 0.0, 20.0, True)
    f.write_text("[yaw_rate]\nbias_deg_s = 0.4\n[yaw_rate_redundant]\nlowpass_hz = 0\n")
    s = SensorConfig.load(str(f))  # an offset is the element's own: not taken from the first
    assert s.yaw_rate_redundant == YawRateSensorConfig(0.014, 0.0, 0.0, True) and s.yaw_rate_redundant_present
    f.write_text("[yaw_rate_redundant]\npresent = false\n")
    s = SensorConfig.load(str(f))
    assert not s.yaw_rate_redundant_present and math.isnan(Sensors(s, TS).yaw_rate_redundant(0.1))
    f.write_text("[yaw_rate_redundant]\nbias_deg_s = 99\n")
    with pytest.raises(ModelFileError, match="bias_deg_s"):
        SensorConfig.load(str(f))


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig.ideal()], ids=["default", "ideal"])
def test_every_reading_saturates_at_its_signals_range_as_the_bus_carries_it(config: SensorConfig) -> None:
    # The DBC's ranges: yaw rate (both elements) +-3 rad/s, a_y +-65 m/s^2, the steering angles
    # +-0.7 rad, the speed 0-70 and the second speed 0-75 m/s.  A spinning car reads 3 rad/s
    # offline as the plant node sends it, not 4.5.
    s = Sensors(config, 0.002)
    assert (s.yaw_rate(4.5), s.yaw_rate_redundant(-4.5)) == (3.0, -3.0)
    assert (s.lat_accel(80.0), s.steer(1.0), s.steer_redundant(-1.0)) == (65.0, 0.7, -0.7)
    assert (s.speed(-1.0), s.speed_redundant(80.0)) == (0.0, 75.0)
    # within range a reading is left as it was (a fresh sensor: the filter holds the 4.5 above)
    fresh = Sensors(config, 0.002)
    assert abs(fresh.yaw_rate(0.5) - 0.5) < 0.01 and abs(fresh.speed(20.0) - 20.0) < 0.2
    # a fault's value past the range saturates too: a yaw rate stuck at 50 rad/s reads 3
    stuck = Sensors(SensorConfig(faults=(SensorFault("yaw_rate", "stuck", 0.0, 50.0),)), 0.002)
    assert stuck.yaw_rate(0.0) == 3.0
