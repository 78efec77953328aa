"""The single-track model against the paper's eqs. (14), (15), (16) and its ZOH discretisation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from sim_plant.car.vehicle import (
    DiscretePlant,
    VehicleParams,
    disturbance_tf,
    nominal_yaw_gain,
    state_space,
    steering_tf,
    zoh_discretize,
)

POINTS = [VehicleParams(v=v, mu=mu, mass=m) for v, mu, m in
          [(5.0, 1.0, 1296.0), (13.0, 0.4, 1296.0), (27.0, 0.7, 1550.0), (50.0, 1.2, 1800.0)]]


def _paper_eq14(p: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (14) typed in from the paper, independent of sim_plant's helper."""
    cf, cr, lf, lr, m, J, v = p.mu * 84000, p.mu * 96000, 1.25, 1.32, p.mass, 1750.0, p.v
    num = [cf * lf * m * v**2, cf * cr * (lf + lr) * v]
    den = [J * m * v**2, (cf * (J + lf**2 * m) + cr * (J + lr**2 * m)) * v,
           cf * cr * (lf + lr) ** 2 + (cr * lr - cf * lf) * m * v**2]
    return np.array(num), np.array(den)


def _normalised(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    num = np.trim_zeros(np.atleast_1d(np.squeeze(num)), "f")
    return num / den[0], den / den[0]


@pytest.mark.parametrize("p", POINTS, ids=lambda p: f"v{p.v}-mu{p.mu}-m{p.mass}")
def test_state_space_steering_channel_is_eq14(p: VehicleParams) -> None:
    ss = state_space(p)
    num, den = signal.ss2tf(ss.A, ss.B, ss.C, ss.D, input=0)
    got_num, got_den = _normalised(num[0], den)
    ref_num, ref_den = _normalised(*_paper_eq14(p))
    np.testing.assert_allclose(got_den, ref_den, rtol=1e-10)
    np.testing.assert_allclose(got_num, ref_num, rtol=1e-10)


@pytest.mark.parametrize("p", POINTS, ids=lambda p: f"v{p.v}-mu{p.mu}")
def test_state_space_disturbance_channel_is_eq16(p: VehicleParams) -> None:
    ss = state_space(p)
    num, den = signal.ss2tf(ss.A, ss.B, ss.C, ss.D, input=1)
    got_num, got_den = _normalised(num[0], den)
    _, den14 = _paper_eq14(p)
    ref_num, ref_den = _normalised(np.array([p.mass * p.v**2, (p.mu * 180000.0) * p.v]), den14)
    np.testing.assert_allclose(got_den, ref_den, rtol=1e-10)
    np.testing.assert_allclose(got_num, ref_num, rtol=1e-10)


def test_helper_tfs_match_paper_formulas() -> None:
    p = VehicleParams(v=31.0, mu=0.6)
    tf = steering_tf(p)
    num, den = _paper_eq14(p)
    np.testing.assert_allclose(tf.num, num, rtol=1e-12)
    np.testing.assert_allclose(tf.den, den, rtol=1e-12)
    np.testing.assert_allclose(disturbance_tf(p).den, den, rtol=1e-12)


@pytest.mark.parametrize("v", [5.0, 10.0, 20.0, 40.0, 60.0])
def test_dc_gain_is_the_classical_steady_state_yaw_gain(v: float) -> None:
    # Steady cornering: r/delta = v / (L + EG v^2), EG = m (c_r l_r - c_f l_f) / (c_f c_r L).
    L = 2.57
    eg = 1296 * (96000 * 1.32 - 84000 * 1.25) / (84000 * 96000 * L)
    assert nominal_yaw_gain(v) == pytest.approx(v / (L + eg * v**2), rel=1e-12)
    # M_z -> r at d.c.: eq. (16) over eq. (14)'s a0.
    p = VehicleParams(v=v)
    a0 = 84000 * 96000 * L**2 + (96000 * 1.32 - 84000 * 1.25) * 1296 * v**2
    assert disturbance_tf(p).dc_gain() == pytest.approx(180000 * v / a0, rel=1e-12)
    ss = state_space(p)
    x_ss = -np.linalg.solve(ss.A, ss.B)  # steady state per unit input
    assert x_ss[1, 0] == pytest.approx(nominal_yaw_gain(v), rel=1e-10)


def test_lateral_acceleration_is_v_times_yaw_rate_in_steady_state() -> None:
    p = VehicleParams(v=25.0, mu=0.8)
    ss = state_space(p)
    u = np.array([0.02, 300.0])
    x = -np.linalg.solve(ss.A, ss.B @ u)
    r, beta, ay = ss.C @ x + ss.D @ u
    assert ay == pytest.approx(p.v * r, rel=1e-10)  # beta' = 0 in steady state


@pytest.mark.parametrize("ts", [1e-4, 1e-3, 1e-2])
def test_zoh_discretisation_agrees_with_scipy(ts: float) -> None:
    ss = state_space(VehicleParams(v=17.0, mu=0.5))
    phi, gamma = zoh_discretize(ss.A, ss.B, ts)
    ref = signal.cont2discrete((ss.A, ss.B, ss.C, ss.D), ts, method="zoh")
    np.testing.assert_allclose(phi, ref[0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(gamma, ref[1], rtol=1e-12, atol=1e-15)


def test_discrete_plant_step_matches_continuous_step_response_exactly() -> None:
    p = VehicleParams(v=22.0, mu=0.9)
    ts = 0.01
    plant = DiscretePlant(p, ts)
    ss = state_space(p)
    t = np.arange(0, 2.0 + ts / 2, ts)
    _, y, _ = signal.lsim((ss.A, ss.B, ss.C, ss.D), np.tile([0.01, 500.0], (len(t), 1)), t)
    r = []
    for _ in t:
        r.append(plant.outputs(0.01, 500.0)[0])
        plant.advance(0.01, 500.0)
    np.testing.assert_allclose(r, y[:, 0], rtol=1e-6, atol=1e-9)


def test_rediscretisation_keeps_state_and_changes_dynamics() -> None:
    plant = DiscretePlant(VehicleParams(v=20.0), 0.001)
    for _ in range(300):
        plant.advance(0.02, 0.0)
    x = plant.x.copy()
    before = plant.outputs(0.02, 0.0)
    plant.set_params(plant.params.at(mu=0.3))
    np.testing.assert_array_equal(plant.x, x)
    np.testing.assert_allclose(plant.outputs(0.02, 0.0)[0], before[0])  # r is a state: continuous
    plant.advance(0.02, 0.0)
    ref = DiscretePlant(VehicleParams(v=20.0, mu=0.3), 0.001)
    ref.x = x
    ref.advance(0.02, 0.0)
    np.testing.assert_allclose(plant.x, ref.x, rtol=1e-14)


@pytest.mark.parametrize("bad", [dict(v=0.0), dict(v=-3.0), dict(mu=0.0), dict(mu=1.6), dict(mass=-1.0),
                                 dict(v=math.nan), dict(mu=math.inf)])
def test_invalid_parameters_are_rejected(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        VehicleParams(**bad)
