"""The shipped law (issue 15): speed schedule, nominal actuator and nominal filter in step(),
its calibration and calibration files, and its figures on the reference loop, pinned."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from firmware_py import calibration_file
from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import VehicleParams
from sim_plant.offline import constraints as K
from sim_plant.offline import margins as M
from sim_plant.offline.loop_plant import LoopModels

SHIPPED = mr.ControllerConfig()
REF = LoopModels.reference()


# ------------------------------------------------------------------------------ the schedule


def _constant_at(i: int) -> mr.LawPoint:
    """Breakpoint i's coefficient set, from a constant-gain calibration (configure's own formulas)."""
    k, tau, tau_n = SHIPPED.schedule_k[i], SHIPPED.schedule_tau[i], SHIPPED.schedule_tau_n[i]
    return mr.law_at(mr.configure(mr.constant_gains(SHIPPED, k, tau, tau_n)), SHIPPED.schedule_speed[i])


def test_schedule_is_the_breakpoint_sets_held_outside_and_linear_between() -> None:
    c = mr.configure(SHIPPED)
    v = SHIPPED.schedule_speed
    for i in range(len(v)):
        assert mr.law_at(c, v[i]) == _constant_at(i)
    assert mr.law_at(c, 3.5) == _constant_at(0) and mr.law_at(c, 69.0) == _constant_at(len(v) - 1)
    for i in range(len(v) - 1):
        for f in (0.25, 0.5, 0.9):
            got, a, b = mr.law_at(c, v[i] + f * (v[i + 1] - v[i])), _constant_at(i), _constant_at(i + 1)
            for name in ("a", "g_w0", "g_w1", "g_r0", "g_r1", "q0"):
                expected = (1 - f) * getattr(a, name) + f * getattr(b, name)
                assert getattr(got, name) == pytest.approx(expected, rel=1e-12, abs=1e-15), (i, f, name)


def test_law_at_is_what_step_uses() -> None:
    """step() in open loop at a speed between breakpoints equals the recursion with law_at's set
    (the nominal actuator and filter written out independently here)."""
    c = mr.configure(SHIPPED)
    s = mr.State()
    v = 14.0
    p = mr.law_at(c, v)
    ikn = c.wheelbase / v + c.k_us * v
    rng = np.random.default_rng(5)
    r = 0.002 * rng.standard_normal(400)
    mr.step(c, s, 0.0, 0.0, v)  # initialise at rest
    a_n = math.exp(-SHIPPED.ts / SHIPPED.model_actuator_tau)
    b, a = signal.butter(2, SHIPPED.model_filter_hz, fs=1.0 / SHIPPED.ts)
    z = p_n = 0.0
    zi = np.zeros(2)
    u_prev = 0.0
    for k in range(1, len(r)):
        u = mr.step(c, s, 0.0, float(r[k]), v)
        p_n = a_n * p_n + (1.0 - a_n) * u_prev
        w, zi = signal.lfilter(b, a, [p_n], zi=zi)
        y = p.g_w0 * w[0] - p.g_r0 * ikn * r[k] + z
        assert u == pytest.approx(y, abs=1e-12)
        z = p.g_w1 * w[0] - p.g_r1 * ikn * r[k] + p.a * y
        u_prev = u


def test_nominal_filter_is_scipys_butterworth_and_the_actuator_its_zoh() -> None:
    c = mr.configure(SHIPPED)
    b, a = signal.butter(2, 30.0, fs=500.0)
    np.testing.assert_allclose([c.flt_b0, c.flt_b1, c.flt_b2], b, rtol=1e-13)
    np.testing.assert_allclose([c.flt_a1, c.flt_a2], a[1:], rtol=1e-13)
    assert c.act_a == math.exp(-0.002 / 0.020) and c.act_b == 1.0 - c.act_a
    plain = mr.configure(mr.PREVIOUS_CONFIG)  # disabled: exact pass-through coefficients
    assert (plain.act_a, plain.act_b, plain.flt_b0, plain.flt_b1, plain.flt_b2, plain.flt_a1, plain.flt_a2) == \
        (0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0)


def test_restart_after_a_fault_is_bumpless_with_the_full_nominal_model() -> None:
    c, s = mr.configure(SHIPPED), mr.State()
    for _ in range(400):
        u = mr.step(c, s, 0.0, -0.05, 12.0)
    held = u
    fade = SHIPPED.fade_rate * SHIPPED.ts
    out = [mr.step(c, s, 0.0, math.nan, 12.0) for _ in range(20)]
    assert s.status == mr.STATUS_FAULT and out[-1] == pytest.approx(held - 20 * fade, abs=1e-12)
    prev = out[-1]
    for _ in range(1500):
        u = mr.step(c, s, 0.0, -0.05, 12.0)
        assert abs(u - prev) <= fade + 1e-15
        prev = u
    assert not s.recovering and abs(u - held) < 1e-3  # back on the law's own answer


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(min_value=-0.5, max_value=0.5))
speeds = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(min_value=0.0, max_value=75.0))


@settings(max_examples=200, deadline=None)
@given(inputs=st.lists(st.tuples(finite_or_not, finite_or_not, speeds), min_size=1, max_size=80))
def test_shipped_step_never_exceeds_its_limits_nor_returns_non_finite(inputs) -> None:
    c, s = mr.configure(SHIPPED), mr.State()
    for d, r, v in inputs:
        u = mr.step(c, s, d, r, v)
        assert math.isfinite(u) and abs(u) <= c.u_max
        assert all(math.isfinite(x) for x in (s.z, s.p_n, s.f_s1, s.f_s2))


# ------------------------------------------------------------------------- calibration checks


@pytest.mark.parametrize("change,needle", [
    (dict(k=10.0), "either a gain schedule or constant"),
    (dict(schedule_k=(1.0, 2.0)), "one value per breakpoint"),
    (dict(schedule_speed=(5.0, 10.0, 10.0, 30.0, 40.0, 50.0)), "strictly ascending"),
    (dict(schedule_speed=tuple(float(i + 1) for i in range(9)), schedule_k=(1.0,) * 9, schedule_tau=(0.1,) * 9,
          schedule_tau_n=(0.1,) * 9), "at most 8"),
    (dict(model_delay_steps=0), "needs model_delay_steps >= 1"),
    (dict(model_filter_hz=250.0), "Nyquist"),
    (dict(model_actuator_tau=-0.01), "model_actuator_tau must be >= 0"),
    (dict(schedule_tau=(0.1, 0.1, 0.0, 0.1, 0.1, 0.1)), "tau must be positive"),
    (dict(schedule_k=(1.0, 2.0, math.nan, 4.0, 5.0, 6.0)), "must be finite"),
])
def test_bad_schedules_are_rejected_naming_the_field(change: dict[str, object], needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        mr.configure(replace(SHIPPED, **change))


def test_constant_gains_replace_the_schedule() -> None:
    cfg = mr.constant_gains(SHIPPED, 8.0, 0.03, 0.02)
    c = mr.configure(cfg)
    assert c.n_sched == 1 and mr.law_at(c, 7.0) == mr.law_at(c, 45.0)
    assert cfg.model_actuator_tau == SHIPPED.model_actuator_tau  # the nominal model is kept
    assert mr.plain_law(SHIPPED, 8.0, 0.03, 0.02).model_filter_hz == 0.0


# ------------------------------------------------------------------------- calibration files


@pytest.mark.parametrize("cfg", [SHIPPED, mr.PREVIOUS_CONFIG, mr.PAPER_CONFIG], ids=("shipped", "previous", "paper"))
def test_calibration_files_round_trip_bit_for_bit(cfg: mr.ControllerConfig) -> None:
    assert calibration_file.loads(calibration_file.dumps(cfg)) == cfg


def test_hand_written_constant_gains_replace_the_shipped_schedule() -> None:
    cfg = calibration_file.loads("# paper's\nk = 10\ntau = 0.006\ntau_n = 0.02\nmodel_actuator_tau = 0\n"
                                 "model_filter_hz = 0\nmodel_delay_steps = 0\nts = 0.001\n")
    assert cfg == mr.PAPER_CONFIG


@pytest.mark.parametrize("text,needle", [
    ("kk = 1\n", "cal.cfg:1: unknown key 'kk'"),
    ("# c\nts = fast\n", "cal.cfg:2: ts: not a valid value"),
    ("k 10\n", "expected 'key = value'"),
    ("schedule_k = 1, x\n", "schedule_k: not a valid value"),
    ("k = 5\nschedule_k = 1, 2, 3, 4, 5, 6\n", "either a gain schedule or constant"),
])
def test_bad_calibration_files_name_the_line_and_key(text: str, needle: str) -> None:
    with pytest.raises(calibration_file.CalibrationError, match=needle):
        calibration_file.loads(text, "cal.cfg")


# ------------------------------------------------- the shipped figures on the reference loop


# The reference loop of issue 15: 500 Hz, one sample of delay, the paper's car, a first-order
# 20 ms actuator within +-3 deg (exact ZOH cascade: the car sees the position move within the
# sample), a 2nd-order Butterworth 30 Hz on the measured yaw rate; 4000 Nm at mu = 1, wheel held.
@pytest.mark.parametrize("v,peak,bound", [(10.0, 0.04461, 0.045), (20.0, 0.05532, 1.5 * 0.0377),
                                          (40.0, 0.05770, 1.5 * 0.0409)])
def test_shipped_peak_yaw_rate_on_the_reference_loop(v: float, peak: float, bound: float) -> None:
    got = K.peak_yaw_rate(VehicleParams(v=v, mu=1.0), SHIPPED, 1, REF)
    assert got == pytest.approx(peak, abs=2e-5)
    assert got <= bound


@pytest.mark.parametrize("v,threshold", [(10.0, 6189.5), (20.0, 6241.9), (40.0, 6130.6)])
def test_shipped_applied_saturation_threshold_on_dry_road(v: float, threshold: float) -> None:
    got = K.applied_threshold(VehicleParams(v=v, mu=1.0), SHIPPED, 1, REF)
    assert got == pytest.approx(threshold, abs=1.0)
    assert got >= K.THRESHOLD_MIN_NM


def test_shipped_command_noise_at_its_worst_point() -> None:
    got = K.noise_rms_deg(VehicleParams(v=10.0, mu=1.0), mr.configure(SHIPPED), 1, REF)
    assert got == pytest.approx(0.14561, abs=1e-4) and got <= K.NOISE_MAX_DEG


@pytest.mark.parametrize("models", [REF, LoopModels.ideal()], ids=("reference", "ideal"))
def test_shipped_margins_hold_over_the_default_envelope(models: LoopModels) -> None:
    res = M.envelope_margins(SHIPPED, 1, with_delay_margin=False, models=models)
    w = res.worst()
    assert res.stable and w["max_pole_radius"] < 1.0
    assert w["gain_margin_db"] >= 6.0 and w["phase_margin_deg"] >= 45.0
