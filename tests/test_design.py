"""Design checks (issue 5): margins, tuning and bus load against independent constructions."""

from __future__ import annotations

import cmath
import json
import math
from dataclasses import replace

import numpy as np
import pytest

import mrsteer_dbc
from firmware_py import model_regulator as mr
from mrsteer_cli.cli import main
from mrsteer_dbc.busload import bus_load, frame_bits, max_rate_hz
from sim_plant.offline import margins as M
from sim_plant.offline import tuning as T
from sim_plant.offline.closed_loop import discrete_loop_poles
from sim_plant.car.vehicle import VehicleParams, state_space

SMALL = M.Envelope(speeds=(5.0, 20.0, 50.0), frictions=(0.3, 1.0), masses=(1296.0, 1800.0))


def _radius(p: VehicleParams, cfg: mr.ControllerConfig, n: int, gain: complex = 1.0) -> float:
    return float(np.max(np.abs(discrete_loop_poles(p, mr.configure(cfg), n, gain))))


def _delayed_loop(p: VehicleParams, c: mr.Coefficients, n: int, extra: float, z: complex) -> complex:
    """L(z) with ``extra`` more samples of continuous-time delay before the ZOH plant, built
    independently of the loop matrix: the modified z-transform of the plant, from expm."""
    from scipy.linalg import expm

    ss = state_space(p)
    whole, frac = divmod(extra, 1.0)

    def held(seconds: float) -> tuple[np.ndarray, np.ndarray]:  # (e^{A s}, int_0^s e^{A x} dx B)
        aug = np.zeros((3, 3))
        aug[:2, :2], aug[:2, 2] = ss.A, ss.B[:, 0]
        e = expm(aug * seconds)
        return e[:2, :2], e[:2, 2]

    phi, _ = held(c.ts)
    phi_late, g_late = held((1.0 - frac) * c.ts)
    g_early = phi_late @ held(frac * c.ts)[1]
    x = np.linalg.solve(z * np.eye(2) - phi, g_late + g_early / z)
    plant = (ss.C[0, :2] @ x) * z ** (-(n + int(whole)))
    inverse_kn = c.wheelbase / p.v + c.k_us * p.v  # 1/K_n(v), eq. (15)
    return M.law_response(c, z, p.v) * plant * inverse_kn


@pytest.mark.parametrize("model_delay", [0, 1, 2])
@pytest.mark.parametrize("delay", [0, 1, 3])
def test_loop_transfer_function_and_state_matrix_agree(model_delay: int, delay: int) -> None:
    # Every closed-loop pole of the state matrix is a zero of 1 + L(z): two independent forms.
    cfg = replace(mr.PREVIOUS_CONFIG, k=5.0, tau=0.05, ts=0.005, model_delay_steps=model_delay)
    p = VehicleParams(v=20.0, mu=0.6)
    loop = M.LoopResponse(p, mr.configure(cfg), delay)
    for z in discrete_loop_poles(p, mr.configure(cfg), delay):
        if abs(z) > 1e-9:
            assert abs(1.0 + loop.at_z(z)) < 1e-6 * max(1.0, abs(loop.at_z(z)))


@pytest.mark.parametrize("cfg,delay", [
    (M.paper_config(0.0005), 1),
    (replace(mr.PREVIOUS_CONFIG, k=4.0, tau=0.1, tau_n=0.05, ts=0.005), 1),
    (replace(mr.PREVIOUS_CONFIG, k=20.0, tau=0.02, ts=0.002, model_delay_steps=1), 1),
    (replace(mr.PREVIOUS_CONFIG, k=3.0, tau=0.05, ts=0.01), 2),
])
def test_margins_are_where_the_perturbed_loop_reaches_the_stability_limit(cfg: mr.ControllerConfig,
                                                                            delay: int) -> None:
    p = VehicleParams(v=5.0, mu=1.0)
    m = M.point_margins(p, cfg, delay)
    assert m.stable
    # Gain margin: the loop scaled by it has a pole on the unit circle; a little less stays inside.
    g = 10.0 ** (m.gain_margin_db / 20.0)
    assert _radius(p, cfg, delay, g) == pytest.approx(1.0, abs=1e-7)
    assert _radius(p, cfg, delay, g * 0.99) < 1.0
    # Phase margin: L turned by PM (one way or the other) touches -1 on the unit circle.
    turned = [_radius(p, cfg, delay, cmath.exp(s * 1j * math.radians(m.phase_margin_deg))) for s in (1, -1)]
    assert min(abs(r - 1.0) for r in turned) < 1e-7
    # Delay margin: the loop with that much more delay has a pole on the unit circle, at the
    # reported frequency, where |L| of the delayed loop is 1 (a gain crossover of it).
    d = m.delay_margin_samples
    assert m.delay_margin_s == pytest.approx(d * cfg.ts)
    coeffs = mr.configure(cfg)
    for extra, inside in ((d - 1e-3, True), (d + 1e-3, False)):
        assert bool(np.max(np.abs(discrete_loop_poles(p, coeffs, delay, extra_delay=extra))) < 1.0) is inside
    z_c = cmath.exp(2j * math.pi * m.delay_crossover_hz * cfg.ts)
    assert abs(_delayed_loop(p, coeffs, delay, d, z_c)) == pytest.approx(1.0, abs=1e-3)


def test_paper_tuning_holds_at_1khz_with_one_sample_of_delay_but_not_at_500hz() -> None:
    fast = M.envelope_margins(M.paper_config(0.001), 1, SMALL)
    slow = M.envelope_margins(M.paper_config(0.002), 1, SMALL)
    assert fast.stable and 0.0 < fast.worst()["gain_margin_db"] < 1.0  # stable, but barely
    assert not slow.stable and slow.worst()["max_pole_radius"] > 1.0


def test_worst_case_names_its_operating_point() -> None:
    res = M.envelope_margins(M.paper_config(0.001), 1, SMALL)
    w = res.worst()
    at = w["where"]["gain_margin_db"]
    point = next(p for p in res.points if (p.v, p.mu, p.mass) == (at["v"], at["mu"], at["mass"]))
    assert point.gain_margin_db == w["gain_margin_db"] == min(p.gain_margin_db for p in res.points)
    assert len(res.points) == len(SMALL)


def test_shipped_default_keeps_its_margins_over_the_whole_default_envelope() -> None:
    res = M.envelope_margins(mr.ControllerConfig(), 1, with_delay_margin=False)
    w = res.worst()
    assert res.stable
    assert w["gain_margin_db"] >= T.GM_MIN_DB - 1e-6
    assert w["phase_margin_deg"] >= T.PM_MIN_DEG - 1e-6


@pytest.mark.slow
def test_tuning_beats_every_feasible_point_of_a_plain_grid_search() -> None:
    ts, delay = 0.01, 1
    env = SMALL
    res = T.tune(ts, delay, env)
    assert res.margins.stable
    assert res.margins.worst()["gain_margin_db"] >= T.GM_MIN_DB
    assert res.margins.worst()["phase_margin_deg"] >= T.PM_MIN_DEG
    # An independent plain grid search with exact margins on the same envelope.
    best = math.inf
    for k in (1.0, 2.0, 4.0, 8.0, 16.0):
        for tau in (0.01, 0.03, 0.1, 0.3):
            for m in (0, 1):
                cfg = replace(mr.PREVIOUS_CONFIG, ts=ts, k=k, tau=tau, tau_n=0.02, model_delay_steps=m)
                em = M.envelope_margins(cfg, delay, env, with_delay_margin=False)
                w = em.worst()
                if em.stable and w["gain_margin_db"] >= 6.0 and w["phase_margin_deg"] >= 45.0:
                    best = min(best, T.objective(cfg, delay))
    assert best < math.inf
    assert res.objective_peak_yaw_rate <= best + 1e-12


def test_frame_bits_match_the_can_frame_format() -> None:
    # 8 data bytes: 111 bits bare, 135 with worst-case stuffing (Davis et al. 2007).
    assert frame_bits(8, False) == 111 and frame_bits(8, True) == 135
    assert frame_bits(0, False) == 47 and frame_bits(0, True) == 55
    with pytest.raises(ValueError):
        frame_bits(9, True)


def test_bus_load_is_the_sum_of_frames_over_cycle_times() -> None:
    c = mrsteer_dbc.load()
    load = bus_load(c, 500_000, 100.0)
    expected = 0.0
    for msg in c.db.messages:
        cycle = 0.01 if c.is_control_loop(msg.name) else msg.cycle_time / 1000.0
        expected += (47 + 8 * msg.length + (34 + 8 * msg.length - 1) // 4) / cycle
    assert load.load_percent_worst == pytest.approx(100.0 * expected / 500_000)
    assert load.load_percent_nominal < load.load_percent_worst


def test_default_configuration_stays_under_40_percent_worst_case_at_500k() -> None:
    c = mrsteer_dbc.load()
    default = bus_load(c, 500_000)
    assert default.rate_hz == pytest.approx(1.0 / mr.ControllerConfig().ts)
    assert default.load_percent_worst < 40.0
    limit = max_rate_hz(c, 500_000, 40.0)
    assert bus_load(c, 500_000, limit).load_percent_worst == pytest.approx(40.0)
    assert default.rate_hz <= limit


def test_design_cli_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "margins", "--ts", "0.001", "--delay-steps", "1", "--k", "10", "--tau", "0.006",
                 "--model-delay", "0", "--v-grid", "5:50:2", "--mu-grid", "1", "--mass-grid", "1296", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stable"] is True and len(out["points"]) == 2
    assert set(out["worst"]) >= {"max_pole_radius", "gain_margin_db", "phase_margin_deg", "where"}
    assert main(["design", "busload", "--bitrate", "500000", "--rate-hz", "1000", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["load_percent_worst"] > 40.0  # 1 kHz does not fit the budget
    assert {m["name"] for m in out["messages"]} >= {"MRS_YawRate", "MRS_AuxSteerCmd"}


@pytest.mark.parametrize("argv,needle", [
    (["design", "margins", "--v-grid", "5:50"], "speed grid must be"),
    (["design", "margins", "--mu-grid", "0:1:3"], "friction grid must satisfy"),
    (["design", "margins", "--model-delay", "9"], "model_delay_steps"),
    (["design", "busload", "--bitrate", "0"], "bitrate must be"),
])
def test_design_cli_rejects_bad_input_with_one_line(argv: list[str], needle: str,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and needle in err


def test_delay_margin_of_the_shipped_design_counts_the_crossover_near_nyquist() -> None:
    """At 5 m/s on dry road the loop gain is 1.27 at Nyquist with 0 deg phase.  One more whole
    sample of delay is unstable there, so the margin is below one sample: 0.90, not the 1.48
    that phase margin over crossover frequency gives.  At (5, 0.8, 1800) it is 0.99.  (The
    calibration shipped before issue 15, on the ideal loop.)"""
    cfg = mr.PREVIOUS_CONFIG
    for point, expected in (((5.0, 1.0, 1296.0), 0.897), ((5.0, 0.8, 1800.0), 0.993)):
        p = VehicleParams(v=point[0], mu=point[1], mass=point[2])
        m = M.point_margins(p, cfg, 1)
        assert m.delay_margin_samples == pytest.approx(expected, abs=2e-3)
        assert m.delay_crossover_hz == pytest.approx(0.5 / cfg.ts)  # the pole leaves at z = -1
        assert _radius(p, cfg, 2) > 1.0  # one more whole sample: unstable, as the margin says


def test_a_whole_sample_of_extra_delay_is_the_same_loop_as_one_more_delay_step() -> None:
    c = mr.configure(mr.ControllerConfig())  # the shipped law: schedule, nominal actuator and filter
    p = VehicleParams(v=12.0, mu=0.5)
    a = np.sort_complex(discrete_loop_poles(p, c, 3))
    b = np.sort_complex(discrete_loop_poles(p, c, 1, extra_delay=2.0))
    assert np.max(np.abs(a - b)) < 1e-12


def test_design_margins_reference_reports_every_constraint(capsys: pytest.CaptureFixture[str]) -> None:
    grid = ("--v-grid", "5:50:2", "--mu-grid", "1", "--mass-grid", "1296")
    assert main(["design", "margins", *grid, "--json"]) == 0
    ideal = json.loads(capsys.readouterr().out)
    assert "constraints" not in ideal  # without the flags: today's output
    assert main(["design", "margins", "--reference", *grid, "--json"]) == 0
    ref = json.loads(capsys.readouterr().out)
    worst = ref["constraints"]["worst"]
    assert set(worst) == {"max_pole_radius", "gain_margin_db", "phase_margin_deg", "extra_delay_pole_radius",
                          "tau_range_pole_radius", "noise_rms_deg", "threshold_nm"}
    # The shipped calibration meets every constraint on the reference loop ...
    assert ref["stable"] and ref["constraints"]["passes"], ref["constraints"]["failing"]
    assert len(ref["constraints"]["points"]) == 2 and len(ref["constraints"]["dry_road"]["points"]) == 3
    # ... and the one shipped before issue 15 is unstable there (the 30 Hz filter).
    previous = ("--k", "43", "--tau", "0.0212", "--tau-n", "0.02", "--model-delay", "1")
    assert main(["design", "margins", "--reference", *grid, *previous, "--json"]) == 0
    old = json.loads(capsys.readouterr().out)
    assert not old["stable"] and not old["constraints"]["passes"]
    assert old["constraints"]["worst"]["max_pole_radius"]["where"] == {"v": 5.0, "mu": 1.0, "mass": 1296.0}
    assert main(["design", "margins", "--reference", *grid, *previous]) == 0
    assert "FAIL" in capsys.readouterr().out


@pytest.mark.parametrize("argv,needle", [
    (["design", "margins", "--actuator", "nofile.toml"], "no such file"),
    (["design", "margins", "--reference", "--sensors", "ideal"], "--reference sets"),
])
def test_design_model_flags_reject_bad_input(argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    assert code == 2 and needle in capsys.readouterr().err


def test_design_margins_as_the_readme_writes_it_on_the_shipped_schedule(capsys: pytest.CaptureFixture[str]) -> None:
    """README: ``mrsteer design margins`` (here with --quick, its 24-point envelope): the shipped
    calibration is a speed schedule, and the table says so breakpoint by breakpoint."""
    assert main(["design", "margins", "--quick"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0] == (
        "limited model regulator, gains scheduled over v 5/10/20/30/40/50 m/s: K 10.4/27/10/10/6.3/4.5, "
        "tau 54.72/252/61.6/149.6/93.44/77.55 ms, tau_n 34/89/120/255/275/305 ms; nominal actuator 20 ms, "
        "filter 30 Hz")
    assert "24 operating points: STABLE everywhere" in out
    assert main(["design", "margins", "--quick", "--v-grid", "20", "--mu-grid", "1", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    # a grid option overrides --quick's axis, the others stay --quick's
    assert [(p["v"], p["mu"], p["mass"]) for p in res["points"]] == [(20.0, 1.0, 1296.0), (20.0, 1.0, 1800.0)]
    assert res["schedule"]["k"] == list(mr.ControllerConfig().schedule_k)


def test_design_busload_defaults_to_the_500_kbit_bus(capsys: pytest.CaptureFixture[str]) -> None:
    """docs/architecture.md: ``mrsteer design busload`` as written, the bus the shipped design budgets."""
    assert main(["design", "busload", "--json"]) == 0
    default = json.loads(capsys.readouterr().out)
    assert main(["design", "busload", "--bitrate", "500000", "--json"]) == 0
    assert default == json.loads(capsys.readouterr().out)
    assert default["load_percent_worst"] < 40.0


@pytest.mark.parametrize("command", ["margins", "tune", "compare"])
def test_quick_is_the_same_24_point_envelope_in_every_design_command(command: str) -> None:
    from mrsteer_cli import design_cli
    from mrsteer_cli.cli import build_parser

    quick = design_cli._envelope(build_parser().parse_args(["design", command, "--quick"]))
    assert quick == M.QUICK_ENVELOPE and len(quick) == 24
    assert design_cli._envelope(build_parser().parse_args(["design", command])) == M.Envelope()
    assert len(design_cli._envelope(build_parser().parse_args(["design", command, "--quick", "--mass-grid",
                                                               "1500"]))) == 12


def test_a_coarse_tune_searches_a_ninth_of_the_grid_and_keeps_the_margins() -> None:
    """``design tune --quick``: every third K and tau of the grid; the result still meets the margins."""
    res = T.tune(0.01, 1, SMALL, coarse=True)
    per_structure = len(T.K_GRID[::T.COARSE_STRIDE]) * len(T.TAU_GRID[::T.COARSE_STRIDE]) * len(T.TAU_N_GRID)
    assert res.screened in (per_structure, 2 * per_structure)  # one or both delay structures
    assert per_structure * 8 < len(T.K_GRID) * len(T.TAU_GRID) * len(T.TAU_N_GRID)
    w = res.margins.worst()
    assert res.margins.stable and w["gain_margin_db"] >= T.GM_MIN_DB and w["phase_margin_deg"] >= T.PM_MIN_DEG
