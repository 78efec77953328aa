"""The realistic car's tyres and nonlinear single-track model (sim_plant.car.tyres, .nonlinear)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

from sim_plant.car.nonlinear import STOP_SPEED, NonlinearPlant
from sim_plant.car.tyres import G, Grip, WheelGrip, axle_tyres, static_axle_loads
from sim_plant.car.vehicle import DiscretePlant, VehicleParams, steering_tf

TS = 0.002


def run(plant, delta: float, m_z: float, n: int) -> np.ndarray:
    out = []
    for _ in range(n):
        out.append(plant.outputs(delta, m_z))
        plant.advance(delta, m_z)
    return np.array(out)


# ------------------------------------------------------------------ tyres

def test_static_loads_follow_the_lever_rule():
    f_zf, f_zr = static_axle_loads(1296.0, 1.25, 1.32)
    assert f_zf + f_zr == pytest.approx(1296.0 * 9.81, rel=1e-12)
    assert f_zf * 1.25 == pytest.approx(f_zr * 1.32, rel=1e-12)  # moments about the CG balance


@pytest.mark.parametrize("mu", [0.1, 0.5, 1.0])
def test_slope_at_zero_slip_is_mu_c0(mu):
    p = VehicleParams(mu=mu)
    h = 1e-7
    for tyre, c0 in zip(axle_tyres(p), (p.c_f0, p.c_r0)):
        slope = (tyre.force(h, mu) - tyre.force(-h, mu)) / (2 * h)
        assert slope == pytest.approx(mu * c0, rel=1e-9)


@pytest.mark.parametrize("mu", [0.1, 0.5, 1.0])
def test_lateral_force_saturates_at_mu_fz(mu):
    alpha = np.linspace(-1.2, 1.2, 240001)
    for tyre in axle_tyres(VehicleParams(mu=mu)):
        force = tyre.force(alpha, mu)
        assert np.abs(force).max() == pytest.approx(mu * tyre.f_z, rel=1e-9)
        assert np.abs(force).max() <= mu * tyre.f_z * (1 + 1e-12)
        # past the peak the force falls (shape C > 1) but keeps its sign
        assert 0.85 * mu * tyre.f_z < tyre.force(1.2, mu) < 0.95 * mu * tyre.f_z


def test_force_is_vectorised_and_odd():
    front, _ = axle_tyres(VehicleParams())
    alpha = np.array([-0.3, -0.01, 0.0, 0.02, 0.2])
    arr = front.force(alpha, 0.7)
    assert arr.shape == alpha.shape
    assert arr == pytest.approx([front.force(float(a), 0.7) for a in alpha], rel=1e-14)
    assert front.force(-alpha, 0.7) == pytest.approx(-arr, rel=1e-14)


def test_split_mu_axle_equals_the_mean_mu_and_a_blown_wheel_scales_slope_and_peak():
    front, _ = axle_tyres(VehicleParams())
    alpha = np.linspace(-0.5, 0.5, 101)
    split = front.axle_force(alpha, 1.0, WheelGrip(mu=1.0), WheelGrip(mu=0.2))
    assert split == pytest.approx(front.force(alpha, 0.6), rel=1e-12, abs=1e-9)
    blown = WheelGrip(stiffness=0.2, peak=0.5)
    h = 1e-7
    slope = (front.axle_force(h, 1.0, WheelGrip(), blown) - front.axle_force(-h, 1.0, WheelGrip(), blown)) / (2 * h)
    assert slope == pytest.approx(front.c0 * (1 + 0.2) / 2, rel=1e-9)
    wheel = front.wheel_force(np.linspace(0, 1.2, 120001), 1.0, blown)
    assert wheel.max() == pytest.approx(0.5 * 0.5 * front.f_z, rel=1e-9)


def test_grip_fractions_are_range_checked():
    with pytest.raises(ValueError, match="stiffness"):
        WheelGrip(stiffness=0.0)
    with pytest.raises(ValueError, match="mu"):
        WheelGrip(mu=2.0)


# ------------------------------------------------------------------ small signals: the paper's linear model

def _small_step(p: VehicleParams, steer: bool) -> tuple[float, float]:
    """An input scaled so that the larger slip angle of the linear response peaks at 0.05 deg."""
    d, m = (1.0, 0.0) if steer else (0.0, 1.0)
    y = run(DiscretePlant(p, TS), d, m, 750)
    r, beta = y[:, 0], y[:, 1]
    slip = max(np.abs(d - beta - p.l_f * r / p.v).max(), np.abs(-beta + p.l_r * r / p.v).max())
    k = math.radians(0.05) / slip
    return d * k, m * k


@pytest.mark.parametrize("v", [5.0, 20.0, 50.0])
@pytest.mark.parametrize("mu", [1.0, 0.5, 0.1])
@pytest.mark.parametrize("steer", [True, False], ids=["steer", "yaw_moment"])
def test_nonlinear_equals_linear_at_small_slip(v, mu, steer):
    p = VehicleParams(v=v, mu=mu)
    delta, m_z = _small_step(p, steer)
    errors = []
    for scale in (1.0, 0.5):
        lin = run(DiscretePlant(p, TS), delta * scale, m_z * scale, 750)
        nl = run(NonlinearPlant(p, TS), delta * scale, m_z * scale, 750)
        errors.append((np.abs(nl - lin).max(axis=0) / np.abs(lin).max(axis=0)).max())
    assert errors[0] < 1e-3
    # the difference is the tyres' cubic term (~0.63 (B alpha)^2), not integration error:
    # halving the input quarters it
    assert errors[1] / errors[0] == pytest.approx(0.25, abs=0.01)


# ------------------------------------------------------------------ large signals: the friction limit

def _steady_state(p: VehicleParams, delta: float) -> tuple[float, float, float]:
    """(delta_max, r, beta): the steady turn solved independently of the plant's integration.

    In a steady turn l_f F_yf = l_r F_yr, so both axles carry the same fraction phi of mu F_z
    and a_y = phi mu g, r = a_y / v; the kinematics give delta = L a_y / v^2 + alpha_f - alpha_r."""
    front, rear = axle_tyres(p)

    def peak_slip(t):
        return minimize_scalar(lambda a: -t.force(a, p.mu), bounds=(0, 0.6), method="bounded",
                               options={"xatol": 1e-13}).x

    pf, pr = peak_slip(front), peak_slip(rear)

    def slip(t, top, phi):
        return brentq(lambda a: t.force(a, p.mu) / (p.mu * t.f_z) - phi, 0.0, top, xtol=1e-15)

    L = p.wheelbase
    delta_max = L * p.mu * G / p.v**2 + pf - pr
    phi = brentq(lambda f: L * f * p.mu * G / p.v**2 + slip(front, pf, f) - slip(rear, pr, f) - delta,
                 1e-9, 1 - 1e-12, xtol=1e-15)
    r = phi * p.mu * G / p.v
    return delta_max, r, p.l_r * r / p.v - slip(rear, pr, phi)


@pytest.mark.parametrize("v, frac", [(10.0, 0.5), (10.0, 0.9), (20.0, 0.5)])
def test_steady_turn_matches_the_independent_solution_and_stays_below_mu_g_over_v(v, frac):
    p = VehicleParams(v=v, mu=1.0)
    delta_max, _, _ = _steady_state(p, 0.001)
    delta = frac * delta_max
    _, r_ss, beta_ss = _steady_state(p, delta)
    plant = NonlinearPlant(p, TS)
    run(plant, delta, 0.0, 3000)
    r, beta, a_y = plant.outputs(delta, 0.0)
    assert r == pytest.approx(r_ss, rel=1e-6)
    assert beta == pytest.approx(beta_ss, rel=1e-3)  # its slowest mode near the limit is slow
    assert r < p.mu * G / v
    # near the limit the saturating tyres give clearly less yaw than the linear model would
    if frac > 0.6:
        assert steering_tf(p).dc_gain() * delta > 1.04 * r


@pytest.mark.parametrize("v, mu, delta", [(10.0, 1.0, 0.3), (20.0, 1.0, 0.1), (20.0, 0.3, 0.2), (40.0, 0.5, 0.05)])
def test_lateral_acceleration_never_exceeds_mu_g(v, mu, delta):
    """Steered past the limit the car may spin (it is limit-oversteer, see docs/realistic-car.md),
    but the tyres never give more than mu m g."""
    y = run(NonlinearPlant(VehicleParams(v=v, mu=mu), TS), delta, 0.0, 1500)
    assert np.abs(y[:, 2]).max() <= mu * G * (1 + 1e-12)
    assert np.abs(y[:, 2]).max() > 0.98 * mu * G  # it did reach the limit


# ------------------------------------------------------------------ speed, relaxation, the interface

def test_braking_decelerates_and_stops_at_the_stop_speed():
    plant = NonlinearPlant(VehicleParams(v=25.0), TS)
    for _ in range(500):  # 1 s at 5 m/s^2
        plant.advance(0.0, 0.0, a_x=5.0)
    assert plant.v == pytest.approx(20.0, rel=1e-9)
    for _ in range(5000):
        plant.advance(0.0, 0.0, a_x=5.0)
    assert plant.v == pytest.approx(STOP_SPEED, rel=1e-12)
    plant.set_params(VehicleParams(v=25.0, mu=0.5), keep_speed=True)
    assert plant.v == pytest.approx(STOP_SPEED)
    plant.set_params(VehicleParams(v=25.0, mu=0.5))
    assert plant.v == 25.0


def test_relaxation_length_delays_the_response_but_not_its_steady_state():
    p = VehicleParams(v=20.0)
    d = math.radians(0.1)
    plain = run(NonlinearPlant(p, TS), d, 0.0, 1500)
    def lag_error(sigma: float) -> float:
        lagged = run(NonlinearPlant(p, TS, relaxation_length=sigma), d, 0.0, 1500)
        return (np.abs(lagged[5:] - plain[5:]).max(axis=0) / np.abs(plain).max(axis=0)).max()

    relaxed = run(NonlinearPlant(p, TS, relaxation_length=0.5), d, 0.0, 1500)
    # as sigma -> 0 the lagged model tends to the kinematic one, the difference first order in sigma
    small, larger = lag_error(0.01), lag_error(0.04)
    assert small < 5e-3 and small / larger == pytest.approx(0.25, abs=0.05)
    k = int(0.05 / TS)  # 50 ms in: sigma / v = 25 ms of lag is visible
    assert relaxed[k, 0] < 0.8 * plain[k, 0]
    assert relaxed[-1] == pytest.approx(plain[-1], rel=1e-4)


def test_external_lateral_force_and_grip_enter_the_force_balance():
    p = VehicleParams(v=20.0)
    pushed = NonlinearPlant(p, TS)
    assert pushed.outputs(0.0, 0.0, f_y=1000.0)[2] == pytest.approx(1000.0 / p.mass, rel=1e-12)
    pushed.advance(0.0, 0.0, f_y=1000.0)
    # one step from rest: beta' = F / (m v) to first order
    assert pushed.x[0] == pytest.approx(1000.0 / (p.mass * p.v) * TS, rel=1e-2)
    icy = NonlinearPlant(p, TS)
    icy.set_grip(Grip(WheelGrip(mu=0.1), WheelGrip(mu=0.1), WheelGrip(mu=0.1), WheelGrip(mu=0.1)))
    assert np.abs(run(icy, 0.2, 0.0, 500)[:, 2]).max() <= 0.1 * G * (1 + 1e-12)


def test_bad_construction_is_refused():
    with pytest.raises(ValueError, match="relaxation_length"):
        NonlinearPlant(VehicleParams(), TS, relaxation_length=-1.0)
    with pytest.raises(ValueError, match="ts"):
        NonlinearPlant(VehicleParams(), 0.0)


def test_side_slip_is_reported_wrapped_and_a_spin_is_beyond_thirty_degrees():
    """``outputs`` gives beta in (-180, 180] deg (a car spinning past it reads as one turning the
    other way), unchanged bit for bit inside it; ``spun`` is |beta| beyond 30 deg, either sign."""
    from sim_plant.car.nonlinear import SPIN_SIDE_SLIP, spun, wrap_angle

    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi  # (-pi, pi]
    for x in (0.1, -3.0, 3.5, -3.5, math.radians(1612.0), 40.0 * math.pi + 0.3):
        w = wrap_angle(x)
        assert -math.pi < w <= math.pi and math.isclose(math.cos(w), math.cos(x), abs_tol=1e-12)
        assert math.isclose(math.sin(w), math.sin(x), abs_tol=1e-12)
    assert wrap_angle(0.1) == 0.1 and wrap_angle(math.radians(1612.0)) == pytest.approx(math.radians(172.0))
    xs = np.array([math.pi, -math.pi, 0.1, 3.5, math.radians(1612.0)])
    assert wrap_angle(xs).tolist() == [wrap_angle(float(x)) for x in xs]
    plant = NonlinearPlant(VehicleParams(v=20.0, mu=0.5), TS)
    plant.set_state(math.radians(1612.0), 2.0)
    assert plant.outputs(0.0, 0.0)[1] == pytest.approx(math.radians(172.0))
    assert plant.x[0] == math.radians(1612.0)  # the state itself integrates on unwrapped
    assert SPIN_SIDE_SLIP == pytest.approx(math.radians(30.0))
    assert spun(math.radians(-30.01)) and not spun(math.radians(29.99))
    assert spun(np.radians([10.0, -31.0, 31.0])).tolist() == [False, True, True]
