"""The schedule tuner (issue 15): its result meets every constraint on the envelope it was given."""

from __future__ import annotations

import json
import math

import pytest

from firmware_py import calibration_file
from firmware_py import model_regulator as mr
from mrsteer_cli.cli import main
from sim_plant.car.vehicle import VehicleParams
from sim_plant.offline import constraints as C
from sim_plant.offline import schedule_tuning as S
from sim_plant.offline.loop_plant import LoopModels
from sim_plant.offline.margins import Envelope, envelope_margins

ENVELOPE = ["--v-grid", "5:50:4", "--mu-grid", "0.1:1:2", "--mass-grid", "1296:1800:2"]


def test_gains_round_trip_through_tau_q() -> None:
    cfg = mr.ControllerConfig()
    back = S.with_gains(cfg, S.gains(cfg))
    for a, b in zip((cfg.schedule_k, cfg.schedule_tau, cfg.schedule_tau_n),
                    (back.schedule_k, back.schedule_tau, back.schedule_tau_n)):
        assert a == pytest.approx(b, rel=1e-12)
    # tau_Q = tau / (1 + K): the shipped table's 9.0 ms at 10 m/s.
    assert math.exp(S.gains(cfg)[1][1]) == pytest.approx(0.009, rel=1e-9)


def test_a_breakpoint_influences_the_speeds_between_its_neighbours() -> None:
    v = mr.ControllerConfig().schedule_speed
    assert S.influence(v, 1) == (5.0, 20.0)
    assert S.local_speeds(v, 1, 2.5, 5.0, 50.0) == [5.0, 7.5, 10.0, 12.5, 15.0, 17.5, 20.0]
    assert S.local_speeds(v, 0, 2.5, 5.0, 50.0) == [5.0, 7.5, 10.0]


@pytest.mark.slow
def test_quick_schedule_tune_meets_every_constraint_on_its_envelope(tmp_path, capsys) -> None:
    out = tmp_path / "tuned.cfg"
    rc = main(["design", "tune", "--schedule", "--quick", *ENVELOPE, "--out", str(out), "--json"])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["passes"]
    cfg = calibration_file.load(out)
    assert cfg.schedule_k == tuple(res["schedule"]["k"])
    # Independently of the tuner's own report: every constraint, on the interpolated law, at every
    # point of the envelope it was given.
    env = Envelope(speeds=(5.0, 20.0, 35.0, 50.0), frictions=(0.1, 1.0), masses=(1296.0, 1800.0))
    models = LoopModels.reference()
    m = envelope_margins(cfg, 1, env, models=models, with_delay_margin=False)
    report = C.evaluate(cfg, 1, m, models)
    for key, w in report.worst().items():
        limit, largest = C.LIMITS[key]
        assert w["value"] is not None, key
        assert (w["value"] < limit if largest else w["value"] >= limit), (key, w)
    # Never worse than the start at the Figure-10 point.
    fig10 = VehicleParams().at(v=10.0, mu=1.0)
    assert (C.peak_yaw_rate(fig10, cfg, 1, models)
            <= C.peak_yaw_rate(fig10, mr.ControllerConfig(), 1, models) + 1e-12)
    assert res["breakpoints"][1]["v"] == 10.0 and res["constraints"]["worst"]["noise_rms_deg"]["where"]


@pytest.mark.parametrize("argv,needle", [
    (["--schedule", "--ts", "0.001"], "keep their defaults"),
    (["--out", "x.cfg"], "need --schedule"),  # --start and --out
    (["--schedule", "--out", "/no/such/dir/x.cfg"], "is not an existing directory"),
])
def test_schedule_tune_rejects_bad_input_with_one_line(argv, needle, capsys) -> None:
    try:
        code = main(["design", "tune", *argv])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert needle in err and "\n" not in err
