"""The benchmarks measure equivalent things: the sweep is the firmware, the numpy baseline is the
same law; and ``mrsteer bench`` runs.  No timing is asserted."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from firmware_py import model_regulator as mr
from mrsteer_bench.loop import loop_timing
from mrsteer_bench.micro import NumpyRegulator
from mrsteer_cli.cli import main
from sim_plant.offline.closed_loop import Experiment, simulate_discrete
from sim_plant.offline.sweep import sweep
from sim_plant.car.vehicle import VehicleParams


@pytest.mark.parametrize("model_delay,delay,ts", [(0, 0, 0.001), (0, 1, 0.001), (1, 1, 0.002), (2, 3, 0.005)])
def test_sweep_is_the_firmware_point_by_point(model_delay: int, delay: int, ts: float) -> None:
    cfg = replace(mr.PREVIOUS_CONFIG, k=8.0, tau=0.03, ts=ts, model_delay_steps=model_delay)
    v, mu, mass = np.array([6.0, 22.0, 48.0]), np.array([1.0, 0.25, 0.6]), np.array([1296.0, 1650.0, 1800.0])
    res = sweep(v, mu, mass, cfg, 4000.0, 0.8, delay)
    assert res.saturated.any() and not res.saturated.all()  # both regimes are exercised
    for i in range(3):
        tr = simulate_discrete(Experiment(VehicleParams(v=v[i], mu=mu[i], mass=mass[i]), mr.Q_LIMITED, cfg,
                                          m_z=4000.0, duration=0.8), ts, delay)
        s = tr.summary()
        assert res.peak_yaw_rate[i] == pytest.approx(s["peak_yaw_rate_rad_s"], rel=1e-12)
        assert res.final_yaw_rate[i] == pytest.approx(s["final_yaw_rate_rad_s"], rel=1e-12)
        assert math.degrees(res.peak_aux[i]) == pytest.approx(s["peak_aux_steer_deg"], rel=1e-12)
        assert bool(res.saturated[i]) == s["saturated"]


def test_numpy_baseline_computes_the_same_law() -> None:
    c = mr.configure(mr.ControllerConfig())
    s, base = mr.State(), NumpyRegulator(c)
    mr.step(c, s, 0.0, 0.0, 20.0)
    base.step(0.0, 0.0, 20.0)
    for k in range(500):
        r, dd = 0.2 * math.sin(0.02 * k), 0.01 * math.cos(0.005 * k)
        assert base.step(dd, r, 20.0) == pytest.approx(mr.step(c, s, dd, r, 20.0), abs=1e-15)


def test_bench_cli_reports_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--quick", "--only", "step", "--only", "receive", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["step"]["max_abs_difference_rad"] < 1e-12 and out["step"]["speedup"] > 0
    assert out["receive"]["frames_rejected"] == 0  # the timed path accepted every frame
    assert out["receive"]["ours"]["median_us"] > 0 and "sweep" not in out


def test_bench_rejects_unknown_names(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--only", "nonsense"])
    assert exc.value.code == 2 and "nonsense" in capsys.readouterr().err


def test_the_campaign_bench_without_the_built_c_cycle_fails_in_one_line_before_any_run(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from sim_plant.campaign import c_cycle

    monkeypatch.setattr(c_cycle, "lib", None)
    monkeypatch.setattr(c_cycle, "_WHY", "No module named 'sim_plant.campaign._c_cycle'")
    assert main(["bench", "--quick", "--only", "step", "--only", "campaign"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mrsteer: bench: the C control cycle"), err  # not step()'s run


def test_loop_benchmark_measures_a_live_controller() -> None:
    r = loop_timing(500.0, 1.5, pin=False)
    assert r["cycles"] > 300 and r["latency_samples"] > 100
    assert r["rss_kb"] > 0 and r["gc_disabled_in_loop"] is True
    assert 0.0 <= r["baseline_lateness_p50_us"] <= r["baseline_lateness_p99_us"]
    assert 0.0 <= r["lateness_p50_us"] <= r["lateness_p99_us"] <= r["lateness_max_us"]
