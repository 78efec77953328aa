"""The firmware step(): convergence to the reference, limits, anti-windup, faults, purity."""

from __future__ import annotations

import ast
import inspect
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from firmware_py import model_regulator as mr
from sim_plant.offline import experiments
from sim_plant.offline.paper import PAPER_CONFIG
from sim_plant.offline.closed_loop import discrete_loop_matrix, discrete_loop_poles
from sim_plant.car.vehicle import VehicleParams

LIMIT = math.radians(3.0)


def _fresh(**changes: object) -> tuple[mr.Coefficients, mr.State]:
    return mr.configure(replace(mr.PREVIOUS_CONFIG, **changes)), mr.State()


# ------------------------------------------------------------------ convergence to the reference


def _relative_errors(got: dict, ref: dict) -> float:
    """Largest error of peak and final values, each relative to the reference peak of its signal
    (the final yaw rate of the standard regulator is zero, so it has no scale of its own)."""
    aux, yaw = ref["peak_aux_steer_deg"], ref["peak_yaw_rate_rad_s"]
    return max(abs(got["peak_aux_steer_deg"] - aux) / aux,
               abs(got["final_aux_steer_deg"] - ref["final_aux_steer_deg"]) / aux,
               abs(got["peak_yaw_rate_rad_s"] - yaw) / yaw,
               abs(got["final_yaw_rate_rad_s"] - ref["final_yaw_rate_rad_s"]) / yaw)


# Tustin is second-order accurate and meets 1 % at 0.1 ms; the ZOH form of the controller
# behaves like half a sample of extra delay (first order) and needs a finer step for 1 %.
@pytest.mark.parametrize("method,fine_ts", [(mr.METHOD_TUSTIN, 1e-4), (mr.METHOD_ZOH, 2e-5)])
@pytest.mark.parametrize("form", [mr.Q_LIMITED, mr.Q_STANDARD])
@pytest.mark.parametrize("v,mu", [(15.0, 1.0), (33.0, 0.65)])
def test_discrete_firmware_converges_to_continuous_reference(method: str, fine_ts: float, form: str,
                                                             v: float, mu: float) -> None:
    p = VehicleParams(v=v, mu=mu)
    exp = experiments.disturbance(p, 2500.0, form, replace(PAPER_CONFIG, method=method), 1.0)
    ref = experiments.run(exp).summary()
    coarse = _relative_errors(experiments.run(exp, ts=1e-3, delay_steps=0).summary(), ref)
    fine = _relative_errors(experiments.run(exp, ts=fine_ts, delay_steps=0).summary(), ref)
    assert fine < 0.01, (coarse, fine)
    assert fine < coarse


def test_steering_step_converges_too() -> None:
    p = VehicleParams(v=25.0, mu=0.8)
    exp = experiments.steer(p, mr.Q_LIMITED, PAPER_CONFIG, 1.0)
    ref = experiments.run(exp).summary()
    got = experiments.run(exp, ts=1e-4, delay_steps=0).summary()
    for key in ("peak_yaw_rate_rad_s", "final_yaw_rate_rad_s", "peak_aux_steer_deg"):
        assert got[key] == pytest.approx(ref[key], rel=0.01)


# ----------------------------------------------------- discrete coefficients vs scipy.signal


@pytest.mark.parametrize("method,scipy_method", [(mr.METHOD_TUSTIN, "bilinear"), (mr.METHOD_ZOH, "zoh")])
@pytest.mark.parametrize("form", [mr.Q_LIMITED, mr.Q_STANDARD])
def test_coefficients_are_the_discretised_filters(method: str, scipy_method: str, form: str) -> None:
    cfg = replace(mr.PREVIOUS_CONFIG, method=method, q_form=form, ts=0.0007, tau_n=0.03)
    c = mr.configure(cfg)
    q0, tau_q = mr.q_filter(cfg.q_form, cfg.k, cfg.tau)
    law = mr.law_at(c, 20.0)
    for num, b0, b1 in (([q0], law.g_w0, law.g_w1), ([q0 * cfg.tau_n, q0], law.g_r0, law.g_r1)):
        bd, ad, _ = signal.cont2discrete((num, [tau_q, 1.0]), cfg.ts, method=scipy_method)
        bd = np.squeeze(bd)
        assert ad[1] == pytest.approx(-law.a, rel=1e-12)
        np.testing.assert_allclose([b0, b1], bd[-2:], rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize("ts,delay", [(1e-3, 1), (2e-3, 1), (5e-4, 0), (1e-3, 2)])
def test_loop_poles_match_an_independent_polynomial_construction(ts: float, delay: int) -> None:
    p = VehicleParams(v=24.0, mu=0.7)
    cfg = replace(mr.PREVIOUS_CONFIG, ts=ts, method=mr.METHOD_TUSTIN, model_delay_steps=0)
    c = mr.configure(cfg)
    # Plant delta_f -> r discretised by scipy; controller r -> u from the textbook form
    # u = Q/(1-Q) (-(tau_n s + 1) r / K_n), Tustin by scipy, with z^-delay.
    from sim_plant.car.vehicle import state_space, steering_tf

    ss = state_space(p)
    pn, pd, *_ = signal.cont2discrete((ss.A, ss.B[:, :1], ss.C[:1], ss.D[:1, :1]), ts, method="zoh")
    pnum, pden = signal.ss2tf(pn, pd, ss.C[:1], ss.D[:1, :1])
    kn = steering_tf(VehicleParams(v=24.0)).dc_gain()
    # Q/(1-Q) = K/(tau s + 1) for eq. (22)
    cn, cd, _ = signal.cont2discrete(([-cfg.k * cfg.tau_n / kn, -cfg.k / kn], [cfg.tau, 1.0]), ts, method="bilinear")
    cnum = np.squeeze(cn)
    char = np.polyadd(np.polymul(np.polymul(pden, cd), np.r_[1.0, np.zeros(delay)]),
                      -np.polymul(np.squeeze(pnum), cnum))
    expected = np.sort_complex(np.roots(char))
    got = discrete_loop_poles(p, c, delay)
    got = np.sort_complex(got[np.abs(got) > 1e-9])
    expected = np.sort_complex(expected[np.abs(expected) > 1e-9])
    np.testing.assert_allclose(np.sort(np.abs(got)), np.sort(np.abs(expected)), rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("model_delay,delay", [(0, 0), (0, 1), (1, 1), (2, 1), (1, 3)])
def test_firmware_step_in_closed_loop_is_the_loop_matrix(model_delay: int, delay: int) -> None:
    # step() itself against the linear state matrix the poles and margins come from.
    p = VehicleParams(v=17.0, mu=0.8)
    cfg = replace(mr.PREVIOUS_CONFIG, k=6.0, tau=0.04, ts=0.005, model_delay_steps=model_delay)
    exp = experiments.disturbance(p, 200.0, mr.Q_LIMITED, cfg, 0.5)
    tr = experiments.run(exp, ts=cfg.ts, delay_steps=delay)
    assert not tr.saturated
    F, g = discrete_loop_matrix(p, mr.configure(cfg), delay)
    x = np.zeros(F.shape[0])
    r = []
    for _ in range(len(tr.t)):
        r.append(x[1])
        x = F @ x + g * 200.0
    np.testing.assert_allclose(tr.yaw_rate, r, rtol=0, atol=1e-9 * np.max(np.abs(r)))


def test_stability_verdict_matches_simulation() -> None:
    p = VehicleParams(v=10.0, mu=1.0)  # the low-speed corner is the first to go unstable
    exp = experiments.disturbance(p, 500.0, mr.Q_LIMITED, PAPER_CONFIG, 1.0)
    good = experiments.run(exp, ts=1e-3, delay_steps=1)
    bad = experiments.run(exp, ts=5e-3, delay_steps=1)
    assert good.stable and not good.saturated
    # An unstable linear loop shows up as a limit cycle on the actuator limit.
    assert not bad.stable and bad.saturated


# ------------------------------------------------------------- saturation and anti-windup


def test_state_stays_bounded_while_saturated() -> None:
    c, s = _fresh(q_form=mr.Q_STANDARD, ts=1e-3)
    mr.step(c, s, 0.0, 0.0, 20.0)
    # A yaw rate the standard regulator (pure integrator) would integrate without bound.
    zs = []
    for _ in range(3000):
        u = mr.step(c, s, 0.0, 0.2, 20.0)
        zs.append(s.z)
    assert u == -LIMIT and s.status == mr.STATUS_SATURATED
    assert max(abs(z) for z in zs) < 1.0  # bounded: no integrator run-away
    assert abs(zs[-1] - zs[-100]) < 1e-12  # and settled while saturated


def _pulse_run(law, ts: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Closed loop, one sample of delay: 9000 Nm of yaw moment for 1 s, then none."""
    from sim_plant.car.vehicle import DiscretePlant

    plant = DiscretePlant(VehicleParams(v=20.0, mu=1.0), ts)
    queued, cmds, yaw = 0.0, [], []
    for k in range(2500):
        m_z = 9000.0 if k < 1000 else 0.0
        r = float(plant.outputs(0.0, m_z)[0])
        u = law(r)
        plant.advance(queued, m_z)
        queued = u
        cmds.append(u)
        yaw.append(r)
    return np.array(cmds), np.array(yaw)


def _samples_at_limit_after_pulse(cmds: np.ndarray) -> int:
    return int(np.argmax(np.abs(cmds[1000:]) < LIMIT - 1e-12))


def test_output_leaves_saturation_as_soon_as_the_disturbance_goes() -> None:
    c, s = _fresh(q_form=mr.Q_STANDARD, ts=1e-3)
    mr.step(c, s, 0.0, 0.0, 20.0)
    cmds, yaw = _pulse_run(lambda r: mr.step(c, s, 0.0, r, 20.0))
    assert np.all(np.abs(cmds[500:1000]) == LIMIT)  # saturated during the pulse
    ours = _samples_at_limit_after_pulse(cmds)

    # The same law written as the Figure 3 integrator with the output clamped but not the
    # state: the textbook wind-up case.
    tau_q, ratio = 0.006 / 11.0, mr.DEFAULT_TAU_N / (0.006 / 11.0)
    inv_kn = c.wheelbase / 20.0 + c.k_us * 20.0
    integ = [0.0]

    def naive(r: float) -> float:
        rho = inv_kn * r
        integ[0] += 1e-3 / tau_q * (0.0 - rho)
        return min(LIMIT, max(-LIMIT, integ[0] - ratio * rho))

    naive_cmds, naive_yaw = _pulse_run(naive)
    wound = _samples_at_limit_after_pulse(naive_cmds)
    assert ours <= 30, ours
    assert wound > 10 * ours, (ours, wound)
    # No wind-up kick: after the pulse our yaw rate does not swing far past zero.
    assert yaw[1000:].min() > -0.05 * yaw[:1000].max()
    assert naive_yaw[1000:].min() < -0.05 * naive_yaw[:1000].max()


@pytest.mark.parametrize("method", [mr.METHOD_TUSTIN, mr.METHOD_ZOH])
def test_rate_limit_bounds_every_step(method: str) -> None:
    rate = math.radians(20.0)
    c, s = _fresh(rate_limit=rate, method=method, ts=1e-3)
    prev = 0.0
    rng = np.random.default_rng(1)
    for k in range(2000):
        r = 0.3 * math.sin(k * 0.05) + 0.01 * rng.standard_normal()
        u = mr.step(c, s, 0.01, r, 18.0)
        assert abs(u - prev) <= rate * 1e-3 + 1e-15
        assert abs(u) <= LIMIT
        prev = u


def test_reset_returns_to_power_on_behaviour() -> None:
    c, s = _fresh()
    for k in range(500):
        mr.step(c, s, 0.02, 0.1 * math.sin(k / 30), 25.0)
    mr.reset(s)
    fresh = mr.State()
    assert [getattr(s, f) for f in mr.State.__slots__] == [getattr(fresh, f) for f in mr.State.__slots__]
    seq = [(0.01, 0.05 * math.cos(k / 10), 22.0) for k in range(200)]
    a = [mr.step(c, s, *x) for x in seq]
    b = [mr.step(c, fresh, *x) for x in seq]
    assert a == b


# -------------------------------------------------------------------------------- faults


@pytest.mark.parametrize("bad_input,flag", [
    ((math.nan, 0.0, 20.0), mr.FAULT_DRIVER_ANGLE),
    ((0.0, math.inf, 20.0), mr.FAULT_YAW_RATE),
    ((0.0, 0.0, -1.0), mr.FAULT_SPEED),
    ((0.0, 0.0, 1e9), mr.FAULT_SPEED),
    ((2.0, 0.0, 20.0), mr.FAULT_DRIVER_ANGLE),
    ((0.0, -9.0, 20.0), mr.FAULT_YAW_RATE),
])
def test_invalid_input_faults_fades_and_recovers_without_jump(bad_input: tuple[float, float, float], flag: int) -> None:
    c, s = _fresh(ts=1e-3)
    mr.step(c, s, 0.0, 0.0, 20.0)  # at rest
    for _ in range(300):
        u = mr.step(c, s, 0.0, -0.25, 20.0)  # drive the command to the limit
    assert u == LIMIT
    z_before = s.z
    fade = mr.ControllerConfig().fade_rate * 1e-3
    outs = []
    for _ in range(100):
        outs.append(mr.step(c, s, *bad_input))
        assert s.status == mr.STATUS_FAULT and s.fault_flags & flag
    assert s.z == z_before  # the bad value never touched the state
    assert outs[0] == pytest.approx(LIMIT - fade)
    assert np.all(np.diff(outs) < 0) and np.allclose(np.diff(outs), -fade)
    # Valid again, with a demand for the opposite sign: no jump, the slew is bounded by the fade rate.
    prev = outs[-1]
    for _ in range(2000):
        u = mr.step(c, s, 0.0, 0.05, 20.0)
        assert abs(u - prev) <= fade + 1e-15
        prev = u
    assert s.status in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED)
    assert not s.recovering


def test_below_activation_speed_the_controller_is_inactive() -> None:
    c, s = _fresh()
    u = mr.step(c, s, 0.0, 0.3, 2.0)
    assert u == 0.0 and s.status == mr.STATUS_INACTIVE and s.fault_flags == 0


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                          st.floats(min_value=-1.0, max_value=1.0))
speeds = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(min_value=0.0, max_value=80.0))


@settings(max_examples=300, deadline=None)
@given(inputs=st.lists(st.tuples(finite_or_not, finite_or_not, speeds), min_size=1, max_size=60),
       form=st.sampled_from([mr.Q_LIMITED, mr.Q_STANDARD]),
       method=st.sampled_from([mr.METHOD_TUSTIN, mr.METHOD_ZOH]),
       rate=st.sampled_from([0.0, 0.5]))
def test_step_never_exceeds_limits_nor_returns_non_finite(inputs, form, method, rate) -> None:
    c, s = _fresh(q_form=form, method=method, rate_limit=rate)
    prev = 0.0
    for d, r, v in inputs:
        u = mr.step(c, s, d, r, v)
        assert math.isfinite(u) and abs(u) <= c.u_max
        assert math.isfinite(s.z)
        if rate:
            assert abs(u - prev) <= max(c.du_max, c.fade_step) + 1e-15
        prev = u


# ------------------------------------------------------------------ porting-reference form


def _step_units() -> dict[str, ast.FunctionDef]:
    """step() and the module's functions it calls, directly or through one another (its units)."""
    tree = ast.parse(inspect.getsource(mr))
    functions = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    units, todo = {}, ["step"]
    while todo:
        name = todo.pop()
        if name in units:
            continue
        units[name] = functions[name]
        todo += [n.func.id for n in ast.walk(functions[name])
                 if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in functions]
    return units


def test_step_is_scalar_arithmetic_only() -> None:
    units = _step_units()
    assert len(units) > 5  # the law's units: the walk follows step()'s calls
    # The only loops allowed are bounded C for-loops: the fill of the delay buffer at
    # (re)initialisation (at most MAX_MODEL_DELAY slots) and the breakpoint search (at most
    # MAX_SCHEDULE breakpoints).
    loops = [n for fn in units.values() for n in ast.walk(fn) if isinstance(n, ast.For)]
    assert loops and all(ast.unparse(n.iter) in ("range(c.model_delay)", "range(1, n - 1)") for n in loops)
    allowed = {id(n.iter) for n in loops}
    calls = [ast.unparse(n) for fn in units.values() for n in ast.walk(fn)
             if isinstance(n, ast.Call) and id(n) not in allowed
             and not (isinstance(n.func, ast.Name) and n.func.id in units)]
    assert calls == [], "step() calls only its units (no allocation, I/O, clock or library calls)"
    forbidden = (ast.List, ast.Dict, ast.Set, ast.Tuple, ast.ListComp, ast.DictComp, ast.SetComp,
                 ast.GeneratorExp, ast.Lambda, ast.JoinedStr, ast.Import, ast.ImportFrom,
                 ast.Try, ast.While)
    bad = [type(n).__name__ for fn in units.values() for stmt in fn.body for n in ast.walk(stmt)
           if isinstance(n, forbidden)]  # the bodies: an annotation's tuple[...] is no tuple
    assert bad == []


def test_firmware_imports_no_numpy_or_io() -> None:
    tree = ast.parse(inspect.getsource(mr))
    modules = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    modules |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    # the plausibility monitor's bits for reported_state(): a porting reference of the standard library too
    assert modules <= {"__future__", "math", "dataclasses", "firmware_py.calibration", "firmware_py.plausibility"}


@pytest.mark.parametrize("bad", [dict(q_form="pid"), dict(method="euler"), dict(ts=0.0), dict(k=-1.0),
                                 dict(tau=math.nan), dict(rate_limit=-1.0), dict(aux_limit=math.inf)])
def test_bad_calibration_is_rejected_at_configuration(bad: dict[str, object]) -> None:
    with pytest.raises(ValueError):
        mr.configure(replace(mr.ControllerConfig(), **bad))


def test_shipped_default_is_stable_with_one_sample_of_delay_over_the_envelope() -> None:
    c = mr.configure(mr.ControllerConfig())
    worst = max(float(np.max(np.abs(discrete_loop_poles(VehicleParams(v=v, mu=mu, mass=m), c, 1))))
                for v in (5.0, 10.0, 20.0, 35.0, 50.0) for mu in (0.1, 0.4, 1.0) for m in (1296.0, 1800.0))
    assert worst < 1.0
