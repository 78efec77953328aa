"""The loop with the actuator and the yaw-rate filter in it (issue 15, item 2), against
independent constructions: today's pinned figures, scipy.signal's cascade, perturbed-loop
poles, the firmware's own step() in closed loop, a Monte-Carlo run, and the issue's figures."""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from firmware_py import model_regulator as mr
from sim_plant.car.actuator_dynamics import ActuatorModelConfig
from sim_plant.car.sensors import SensorConfig, YawRateSensorConfig
from sim_plant.car.vehicle import VehicleParams, steering_tf
from sim_plant.offline import delay_margin as DM
from sim_plant.offline import constraints as K
from sim_plant.offline import experiments
from sim_plant.offline import margins as M
from sim_plant.offline.closed_loop import Experiment, simulate_discrete
from sim_plant.offline.discrete_loop import closed_loop, discrete_loop_poles, max_pole_radius
from sim_plant.offline.loop_plant import LoopModels, sampled_plant

SHIPPED = mr.PREVIOUS_CONFIG  # the calibration issue 15 measured (shipped before it)
REF = LoopModels.reference()
ACTUATOR_ONLY = LoopModels(ActuatorModelConfig.default(), SensorConfig.ideal())
FILTER_ONLY = LoopModels(ActuatorModelConfig.ideal(), SensorConfig.default())
# A calibration that is stable on the reference loop (the shipped one is not).
GENTLE = replace(SHIPPED, k=5.0, tau=0.05)

# Today's figures (ideal loop), recorded from the code before the actuator and sensors were
# added: (config, delay, v, mu, mass) -> (pole radius, GM dB, PM deg, delay margin samples).
_CFGS = {"shipped": (SHIPPED, 1), "paper_1k": (M.paper_config(0.001), 1),
         "plain": (replace(SHIPPED, k=4.0, tau=0.1, tau_n=0.05, ts=0.005, model_delay_steps=0), 2)}
TODAY = [
    ("shipped", 5.0, 1.0, 1296.0, 0.9408559044500282, 6.039723312568654, 54.980089125811716, 0.8974990844726562),
    ("shipped", 23.0, 0.4, 1800.0, 0.9961410133183245, 25.158431802830947, 50.96346308559092, 10.670387268066406),
    ("shipped", 50.0, 0.1, 1296.0, 0.9993129682272026, 38.765618935882976, 46.81291866070325, 25.283660888671875),
    ("paper_1k", 5.0, 1.0, 1296.0, 0.9840942709479005, 0.2780824585156935, 3.7783363338645586, 0.27216339111328125),
    ("paper_1k", 23.0, 0.4, 1800.0, 0.9979563392625442, 19.365131479504136, 116.48777089086218, None),
    ("plain", 5.0, 1.0, 1296.0, 0.9108847469927988, 6.832053968432344, 68.15581201555935, 4.230316162109375),
    ("plain", 50.0, 0.1, 1296.0, 0.9960433277003505, 38.21309317625099, 86.57758610456351, None),
]


@pytest.mark.parametrize("name,v,mu,mass,radius,gm,pm,dm", TODAY)
def test_ideal_models_give_todays_figures(name: str, v: float, mu: float, mass: float, radius: float, gm: float,
                                          pm: float, dm: float | None) -> None:
    cfg, delay = _CFGS[name]
    m = M.point_margins(VehicleParams(v=v, mu=mu, mass=mass), cfg, delay, models=LoopModels.ideal())
    got = [m.max_pole_radius, m.gain_margin_db, m.phase_margin_deg]
    assert got == pytest.approx([radius, gm, pm], rel=1e-12)
    assert m.delay_margin_samples == (None if dm is None else pytest.approx(dm, rel=1e-12))


def test_ideal_models_keep_the_firmware_simulation_bit_identical() -> None:
    exp = Experiment(VehicleParams(v=10.0, mu=1.0), SHIPPED.q_form, SHIPPED, m_z=4000.0, duration=1.5)
    a = simulate_discrete(exp, SHIPPED.ts, 1)
    assert float(np.max(np.abs(a.yaw_rate))) == 0.013059262679539885  # recorded before the change
    assert np.array_equal(a.applied, np.clip(np.concatenate([[0.0], a.aux[:-1]]), -SHIPPED.aux_limit,
                                             SHIPPED.aux_limit))


def _cascade_step(p: VehicleParams, ts: float, t_act: float, lowpass_hz: float, n: int) -> np.ndarray:
    """Yaw rate measured after a unit step of the command: scipy.signal's continuous cascade
    actuator 1/(T s + 1) -> eq. (14), ZOH-discretised, then the Butterworth filter."""
    g = steering_tf(p)  # its raw coefficients are large: scipy warns, the comparison below decides
    num = np.polymul([1.0], g.num)
    den = np.polymul([t_act, 1.0], g.den)
    numd, dend, _ = signal.cont2discrete((num, den), ts, method="zoh")
    _, y = signal.dlsim((np.ravel(numd), dend, ts), np.ones(n))
    b, a = signal.butter(2, lowpass_hz, fs=1.0 / ts)
    return signal.lfilter(b, a, np.ravel(y))


@pytest.mark.parametrize("v,mu,t_act", [(7.0, 0.9, 0.02), (33.0, 0.3, 0.045)])
def test_augmented_plant_step_response_is_the_discretised_cascade(v: float, mu: float, t_act: float) -> None:
    p = VehicleParams(v=v, mu=mu)
    ts, n = 0.002, 400
    models = LoopModels(ActuatorModelConfig(time_constant_s=t_act), SensorConfig(YawRateSensorConfig(lowpass_hz=25.0)))
    plant = sampled_plant(p, ts, models)
    x = np.zeros(plant.order)
    y = np.empty(n)
    for k in range(n):
        y[k] = plant.c @ x
        x = plant.a @ x + plant.b
    ref = _cascade_step(p, ts, t_act, 25.0, n)
    np.testing.assert_allclose(y, ref, atol=1e-9 * np.max(np.abs(ref)))


NEW = mr.ControllerConfig()  # the shipped law: schedule, nominal actuator and filter


@pytest.mark.parametrize("cfg,v", [(GENTLE, 15.0), (NEW, 4.0), (NEW, 10.0), (NEW, 17.0), (NEW, 33.0), (NEW, 60.0)])
def test_firmware_step_in_closed_loop_is_the_loop_matrix_with_actuator_and_filter(cfg: mr.ControllerConfig,
                                                                                   v: float) -> None:
    """step() itself (below, at, between and above the schedule's breakpoints, with the nominal
    actuator and filter in its model) against the state matrix every figure comes from."""
    p = VehicleParams(v=v, mu=0.7)
    m_z, n = 200.0, 500  # small: no saturation
    exp = Experiment(p, cfg.q_form, cfg, m_z=m_z, duration=(n - 1) * cfg.ts)
    tr = simulate_discrete(exp, cfg.ts, 1, REF.deterministic())
    assert 0.0 < np.max(np.abs(tr.aux)) < 0.5 * cfg.aux_limit
    loop = closed_loop(p, mr.configure(cfg), 1, models=REF)
    x = np.zeros(loop.f.shape[0])
    r, u = np.empty(n), np.empty(n)
    for k in range(n):
        r[k], u[k] = x[1], loop.u_row @ x
        x = loop.f @ x + loop.g_mz * m_z
    np.testing.assert_allclose(tr.yaw_rate, r, atol=1e-9 * np.max(np.abs(r)))
    np.testing.assert_allclose(tr.aux, u, atol=1e-9 * np.max(np.abs(u)))


@pytest.mark.parametrize("cfg,p", [(GENTLE, VehicleParams(v=5.0, mu=1.0)), (GENTLE, VehicleParams(v=40.0, mu=0.5)),
                                   (replace(SHIPPED, k=3.0, tau=0.03), VehicleParams(v=20.0, mu=1.0)),
                                   (NEW, VehicleParams(v=7.0, mu=0.1)), (NEW, VehicleParams(v=45.0, mu=1.0))])
def test_reference_loop_margins_are_where_the_perturbed_loop_reaches_the_limit(cfg: mr.ControllerConfig,
                                                                                p: VehicleParams) -> None:
    m = M.point_margins(p, cfg, 1, models=REF)
    c = mr.configure(cfg)

    def radius(gain: complex = 1.0, extra: float = 0.0) -> float:
        return float(np.max(np.abs(discrete_loop_poles(p, c, 1, gain, extra, models=REF))))

    assert m.stable
    g = 10.0 ** (m.gain_margin_db / 20.0)
    assert radius(g) == pytest.approx(1.0, abs=1e-7) and radius(0.99 * g) < 1.0
    if m.phase_margin_deg is not None:
        turned = [radius(cmath.exp(s * 1j * math.radians(m.phase_margin_deg))) for s in (1, -1)]
        assert min(abs(r - 1.0) for r in turned) < 1e-7
    d = m.delay_margin_samples
    if d is None:  # beyond the searched limit: stable with that much extra delay
        assert radius(extra=DM.MAX_SAMPLES) < 1.0
    else:
        assert radius(extra=d - 1e-3) < 1.0 < radius(extra=d + 1e-3)


def test_noise_h2_agrees_with_the_firmware_driven_by_seeded_sensor_noise() -> None:
    p = VehicleParams(v=12.0, mu=0.8)
    quiet = SensorConfig(YawRateSensorConfig(quantise=False), seed=11)  # noise and filter, no quantisation
    models = LoopModels(ActuatorModelConfig.default(), quiet)
    h2 = K.noise_rms_deg(p, mr.configure(GENTLE), 1, models)
    tr = simulate_discrete(Experiment(p, GENTLE.q_form, GENTLE, duration=40.0), GENTLE.ts, 1, models)
    mc = math.degrees(float(np.sqrt(np.mean(tr.aux[500:] ** 2))))
    assert mc == pytest.approx(h2, rel=0.04)
    sigma = math.radians(0.014) * math.sqrt(0.5 / GENTLE.ts)  # one-sided density, per-sample sigma
    assert K.noise_sigma(models, GENTLE.ts) == pytest.approx(sigma)


def test_applied_threshold_is_where_the_applied_angle_reaches_99_percent() -> None:
    p = VehicleParams(v=20.0, mu=1.0)
    thr = K.applied_threshold(p, GENTLE, 1, ACTUATOR_ONLY)
    goal = 0.99 * math.radians(3.0)

    def peak(m_z: float) -> float:
        exp = Experiment(p, GENTLE.q_form, GENTLE, m_z=m_z, duration=K.STEP_DURATION)
        return float(np.max(np.abs(simulate_discrete(exp, GENTLE.ts, 1, ACTUATOR_ONLY).applied)))

    assert peak(thr * 0.999) < goal <= peak(thr * 1.001)
    # Ideal actuator: applied = command, so 99 % of the command's linear threshold.
    lin = experiments.saturation_threshold(p, SHIPPED.q_form, SHIPPED, SHIPPED.ts, 1, K.STEP_DURATION)
    assert K.applied_threshold(p, SHIPPED, 1) == pytest.approx(0.99 * lin, rel=1e-9)


def test_actuator_time_constant_range_scans_half_to_twice() -> None:
    # The shipped calibration with the 20 ms actuator: 30 ms is unstable at 50 m/s (below).
    pc = K.point_constraints(VehicleParams(v=50.0, mu=1.0), SHIPPED, 1, ACTUATOR_ONLY)
    assert pc.tau_range_pole_radius > 1.0 and pc.tau_range_worst_factor == 2.0
    twice = max_pole_radius(VehicleParams(v=50.0, mu=1.0), mr.configure(SHIPPED), 1,
                            LoopModels(ActuatorModelConfig(time_constant_s=0.040), SensorConfig.ideal()))
    assert pc.tau_range_pole_radius == pytest.approx(twice, rel=1e-12)
    assert K.point_constraints(VehicleParams(v=50.0, mu=1.0), SHIPPED, 1).tau_range_pole_radius is None


# The issue's figures for the shipped calibration (K 43, tau 21.2 ms, tau_n 20 ms, M 1, 500 Hz, one sample).
def test_issue_figure_30hz_filter_makes_the_shipped_loop_unstable() -> None:
    assert max_pole_radius(VehicleParams(v=5.0, mu=1.0), mr.configure(SHIPPED), 1, FILTER_ONLY) == \
        pytest.approx(1.04, abs=0.005)


def test_issue_figures_20ms_actuator_margins_and_peak() -> None:
    gm = M.point_margins(VehicleParams(v=5.0, mu=1.0), SHIPPED, 1, False, ACTUATOR_ONLY).gain_margin_db
    pm = M.point_margins(VehicleParams(v=50.0, mu=1.0), SHIPPED, 1, False, ACTUATOR_ONLY).phase_margin_deg
    assert gm == pytest.approx(3.6, abs=0.05) and pm == pytest.approx(6.7, abs=0.1)
    # The issue has 0.0279; the exact cascade (the car sees the position move within a sample)
    # gives 0.0294, the end-of-sample position held over the sample 0.0280 (docs/design.md).
    peak = K.peak_yaw_rate(VehicleParams(v=10.0, mu=1.0), SHIPPED, 1, ACTUATOR_ONLY)
    assert peak == pytest.approx(0.0294, abs=3e-4)
    assert K.peak_yaw_rate(VehicleParams(v=10.0, mu=1.0), SHIPPED, 1) == pytest.approx(0.0131, abs=1e-4)


def test_issue_figure_30ms_actuator_unstable_at_35_and_50_on_dry_road() -> None:
    slow = LoopModels(ActuatorModelConfig(time_constant_s=0.030), SensorConfig.ideal())
    c = mr.configure(SHIPPED)
    assert all(max_pole_radius(VehicleParams(v=v, mu=1.0), c, 1, slow) > 1.0 for v in (35.0, 50.0))
    assert max_pole_radius(VehicleParams(v=20.0, mu=1.0), c, 1, slow) < 1.0


@pytest.mark.parametrize("v,expected", [(5.0, 0.9), (50.0, 0.2)])
def test_issue_figure_white_noise_of_01_deg_s(v: float, expected: float) -> None:
    rms = K.noise_rms_deg(VehicleParams(v=v, mu=1.0), mr.configure(SHIPPED), 1, sigma=math.radians(0.1))
    assert rms == pytest.approx(expected, rel=0.03)
