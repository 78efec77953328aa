"""The continuous reference against eqs. (8), (17)-(22) solved independently with scipy.signal."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from conftest import polyadd, polymul
from firmware_py import model_regulator as mr
from sim_plant.offline import experiments
from sim_plant.offline.paper import PAPER_CONFIG
from sim_plant.offline.closed_loop import Experiment, simulate_continuous
from sim_plant.car.vehicle import VehicleParams, disturbance_tf, steering_tf


def _q(form: str, k: float = 10.0, tau: float = 0.006) -> tuple[np.ndarray, np.ndarray]:
    """Q(s): eq. (22) for limited, eq. (17) with tau_Q = tau/(1+K) for standard."""
    if form == "limited":
        return np.array([k]), np.array([tau, 1.0 + k])
    return np.array([1.0]), np.array([tau / (1.0 + k), 1.0])


@pytest.mark.parametrize("k,tau", [(10.0, 0.006), (3.0, 0.05), (40.0, 0.002)])
def test_limited_q_gives_the_limited_integrator_eq20_22(k: float, tau: float) -> None:
    qn, qd = _q("limited", k, tau)
    # Q / (1 - Q) = qn / (qd - qn) must equal K / (tau s + 1) at every frequency.
    s = 1j * np.logspace(-2, 5, 200)
    lhs = np.polyval(qn, s) / (np.polyval(qd, s) - np.polyval(qn, s))
    np.testing.assert_allclose(lhs, k / (tau * s + 1.0), rtol=1e-12)


def test_standard_q_gives_a_pure_integrator_eq19() -> None:
    qn, qd = _q("standard")
    s = 1j * np.logspace(-2, 5, 200)
    lhs = np.polyval(qn, s) / (np.polyval(qd, s) - np.polyval(qn, s))
    np.testing.assert_allclose(lhs, 1.0 / ((0.006 / 11.0) * s), rtol=1e-12)


def _closed_loop_tfs(p: VehicleParams, form: str, tau_n: float):
    """Eq. (8) with G = G_r,delta_f (eq. 14), G_n = K_n/(tau_n s+1) (eq. 18), d = G_r,Mz M_z.

    Returns TFs (num, den) for r/delta_d, r/M_z, delta_mr/delta_d, delta_mr/M_z.
    """
    g, gm = steering_tf(p), disturbance_tf(p)
    kn = steering_tf(VehicleParams(v=p.v)).dc_gain()  # eq. (15): mu = 1, nominal mass
    qn, qd = _q(form)
    gn_n, gn_d = np.array([kn]), np.array([tau_n, 1.0])
    # Denominator of eq. (8): G_n (1 - Q) + G Q over the common denominator gn_d * qd * g.den.
    den = polyadd(polymul(gn_n, polyadd(qd, -qn), g.den), polymul(g.num, qn, gn_d))
    r_dd = (polymul(gn_n, g.num, qd), den)  # y/u_n = G_n G / (...)
    # y/d = G_n (1-Q) / (...), with d = G_rM M_z
    r_mz = (polymul(gn_n, polyadd(qd, -qn), g.den, gm.num), polymul(den, gm.den))
    # u = (G_n u_n - Q d)/(G_n(1-Q) + G Q); delta_mr = u - u_n
    u_un = (polymul(gn_n, qd, g.den), den)
    dmr_dd = (polyadd(u_un[0], -u_un[1]), den)
    dmr_mz = (-polymul(qn, gn_d, g.den, gm.num), polymul(den, gm.den))
    return r_dd, r_mz, dmr_dd, dmr_mz


def _step(tf, t: np.ndarray, amplitude: float) -> np.ndarray:
    num, den = tf
    scale = den[0]  # normalise here: scipy warns on the huge raw coefficients
    num = np.asarray(num, float)
    num = num[np.argmax(np.abs(num) > 1e-12 * np.max(np.abs(num))):]  # drop cancelled leading terms
    _, y = signal.step(signal.lti(np.asarray(num) / scale, np.asarray(den) / scale), T=t)
    return amplitude * y


# Operating points not used anywhere else in the project.
CASES = [(13.0, 0.85, 1296.0), (27.0, 0.6, 1500.0), (45.0, 1.0, 1750.0), (8.0, 0.45, 1296.0)]


@pytest.mark.parametrize("form", ["limited", "standard"])
@pytest.mark.parametrize("v,mu,mass", CASES)
def test_yaw_moment_step_matches_eq8(form: str, v: float, mu: float, mass: float) -> None:
    p = VehicleParams(v=v, mu=mu, mass=mass)
    m_z = 300.0  # small enough to stay linear everywhere
    tr = simulate_continuous(Experiment(p, form, replace(PAPER_CONFIG, q_form=form), m_z=m_z, duration=1.5))
    assert not tr.saturated
    _, r_mz, _, dmr_mz = _closed_loop_tfs(p, form, mr.DEFAULT_TAU_N)
    t = tr.t[::10]
    r_ref = _step(r_mz, t, m_z)
    a_ref = _step(dmr_mz, t, m_z)
    np.testing.assert_allclose(tr.yaw_rate[::10], r_ref, atol=1e-6 * np.max(np.abs(r_ref)) + 1e-12)
    np.testing.assert_allclose(tr.aux[::10], a_ref, atol=1e-6 * np.max(np.abs(a_ref)))


@pytest.mark.parametrize("form", ["limited", "standard"])
@pytest.mark.parametrize("v,mu,mass", CASES[:2])
def test_driver_step_matches_eq8(form: str, v: float, mu: float, mass: float) -> None:
    p = VehicleParams(v=v, mu=mu, mass=mass)
    exp = Experiment(p, form, replace(PAPER_CONFIG, q_form=form), delta_driver=0.004, duration=1.0)
    tr = simulate_continuous(exp)
    r_dd, _, dmr_dd, _ = _closed_loop_tfs(p, form, mr.DEFAULT_TAU_N)
    t = tr.t[::10]
    np.testing.assert_allclose(tr.yaw_rate[::10], _step(r_dd, t, 0.004), atol=1e-6 * 0.004 * 10)
    np.testing.assert_allclose(tr.aux[::10], _step(dmr_dd, t, 0.004), atol=1e-6)


def test_model_following_on_dry_road_is_the_desired_first_order_model() -> None:
    # Standard Q: y/u_n -> G_n at low frequency; the steering step response follows eq. (18).
    p = VehicleParams(v=20.0)
    tr = simulate_continuous(experiments.steer(p, "standard", PAPER_CONFIG, 1.0, saturate=False))
    desired = 1.0 - np.exp(-tr.t / mr.DEFAULT_TAU_N)
    # Within Q's bandwidth the loop follows G_n; in the first milliseconds the plant's own
    # high-frequency gain (b1/a2 of eq. 14) still shows, as eq. (8) predicts when Q -> 0.
    late = tr.t > 0.02
    assert np.max(np.abs(tr.yaw_rate[late] - desired[late])) < 0.025
    assert tr.yaw_rate[-1] == pytest.approx(1.0, abs=1e-3)


def test_limited_integrator_leaves_a_steady_error_the_standard_one_does_not() -> None:
    # Paper, section 4.1: with (22) a steady-state error remains; with (17) it is zero.
    p = VehicleParams(v=20.0)
    cfg = PAPER_CONFIG
    lim = simulate_continuous(experiments.disturbance(p, 2000.0, "limited", cfg, 3.0))
    std = simulate_continuous(experiments.disturbance(p, 2000.0, "standard", cfg, 3.0))
    none = simulate_continuous(experiments.disturbance(p, 2000.0, "none", cfg, 3.0))
    # Limited integrator: loop gain K at d.c. on dry road, so r_ss = r_ss(open) / (1 + K).
    assert lim.yaw_rate[-1] == pytest.approx(none.yaw_rate[-1] / 11.0, rel=1e-3)
    assert abs(std.yaw_rate[-1]) < 1e-4 * abs(none.yaw_rate[-1])


def test_saturation_events_are_located_exactly() -> None:
    # Above the threshold the reference must clamp at exactly 3 deg and agree with the firmware
    # at a tiny step, which saturates the same way.
    p = VehicleParams(v=20.0, mu=1.0)
    exp = experiments.disturbance(p, 9000.0, "limited", PAPER_CONFIG, 1.0)
    ref = simulate_continuous(exp)
    assert ref.saturated
    assert np.max(np.abs(ref.aux)) == pytest.approx(np.radians(3.0), rel=1e-12)
    fine = experiments.run(exp, ts=2e-5, delay_steps=0)
    assert fine.saturated
    np.testing.assert_allclose(fine.yaw_rate[::5][: len(ref.t) // 2], ref.yaw_rate[::2][: len(ref.t) // 2],
                               atol=5e-3 * np.max(np.abs(ref.yaw_rate)))
