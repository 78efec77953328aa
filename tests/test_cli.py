"""``mrsteer sim``: the paper numbers, JSON contracts and argument errors, through the real CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from firmware_py import model_regulator as mr
from mrsteer_cli.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mrsteer_cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


def _json(capsys: pytest.CaptureFixture[str], *args: str) -> dict:
    assert main([*args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path, str]:
    out = tmp_path_factory.mktemp("paper")
    proc = _run("sim", "paper", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout), out, proc.stderr


def test_paper_numbers_within_two_percent(paper_run: tuple[dict, Path, str]) -> None:
    result, _, _ = paper_run
    assert result["limited_peak_aux_steer_deg"] == pytest.approx(1.86, rel=0.02)
    assert result["standard_peak_aux_steer_deg"] == pytest.approx(2.24, rel=0.02)
    assert result["saturation_threshold_nm"] == pytest.approx(6119.0, rel=0.02)
    assert len(result["conditions"]) == 6


def test_paper_writes_every_figure_as_png_and_csv(paper_run: tuple[dict, Path, str]) -> None:
    result, out, stderr = paper_run
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(f"{f}.{ext}" for f in ("fig8_steering_step", "fig9_yaw_moment_step", "fig10_aux_steer")
                           for ext in ("png", "csv"))
    for png in out.glob("*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    header = (out / "fig9_yaw_moment_step.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "t_s" and len(header) == 1 + 6 * 3
    assert "[6/6]" in stderr  # progress is shown


def test_paper_figure10_csv_holds_the_quoted_peaks(paper_run: tuple[dict, Path, str]) -> None:
    _, out, _ = paper_run
    rows = (out / "fig10_aux_steer.csv").read_text().splitlines()
    cols = rows[0].split(",")
    data = [list(map(float, r.split(","))) for r in rows[1:]]
    for form, paper in (("limited", 1.86), ("standard", 2.24)):
        i = cols.index(f"{form}_aux_steer_deg")
        assert max(abs(r[i]) for r in data) == pytest.approx(paper, rel=0.02)


# Runs the CLI in-process with matplotlib unimportable (a None entry in sys.modules makes
# every `import matplotlib` raise ImportError).
_WITHOUT_MATPLOTLIB = ("import sys\nsys.modules['matplotlib'] = None\nfrom mrsteer_cli.cli import main\n"
                       "sys.exit(main(sys.argv[1:]))")


def _run_without_matplotlib(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", _WITHOUT_MATPLOTLIB, *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_paper_json_needs_no_plotting_library(tmp_path: Path) -> None:
    proc = _run_without_matplotlib(tmp_path, "sim", "paper", "--json")
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["limited_peak_aux_steer_deg"] == pytest.approx(1.86, rel=0.02)
    assert result["files"] == [] and list(tmp_path.iterdir()) == []  # no figures unless --out asks


def test_paper_figures_without_plotting_library_are_one_clear_error(tmp_path: Path) -> None:
    proc = _run_without_matplotlib(tmp_path, "sim", "paper", "--json", "--out", "figs")
    assert proc.returncode == 2 and "matplotlib" in proc.stderr and proc.stdout == ""
    assert not (tmp_path / "figs").exists()


def test_paper_text_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "paper", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1.86" in out and "2.24" in out and "6119" in out


def test_disturbance_json_contract(capsys: pytest.CaptureFixture[str]) -> None:
    r = _json(capsys, "sim", "disturbance", "--mz", "4000", "--v", "20", "--mu", "1", "--controller", "limited")
    for key in ("peak_aux_steer_deg", "final_aux_steer_deg", "peak_yaw_rate_rad_s", "final_yaw_rate_rad_s",
                "saturated", "stable"):
        assert key in r
    assert r["saturated"] is False and r["stable"] is True
    # Limited integrator on dry road: d.c. loop gain K, so delta_mr settles at
    # K/(1+K) times the steer that cancels M_z: M_z (c_f + c_r) / (c_f c_r L) (section 3 data).
    full = 4000 * 180000 / (84000 * 96000 * 2.57)
    cfg = mr.ControllerConfig()  # the shipped schedule: 20 m/s is one of its breakpoints
    k = cfg.schedule_k[cfg.schedule_speed.index(20.0)]
    assert r["schedule"]["k"] == list(cfg.schedule_k)
    assert r["final_aux_steer_deg"] == pytest.approx(-(k / (1 + k)) * full * 57.29577951308232, rel=1e-3)


def test_disturbance_discrete_with_delay(capsys: pytest.CaptureFixture[str]) -> None:
    paper = ("--k", "10", "--tau", "0.006", "--model-delay", "0")  # the continuous design, run at 1 kHz
    cont = _json(capsys, "sim", "disturbance", "--mz", "3000", "--v", "30", "--mu", "0.9", *paper)
    disc = _json(capsys, "sim", "disturbance", "--mz", "3000", "--v", "30", "--mu", "0.9", "--ts", "0.001",
                 "--delay-steps", "1", *paper)
    assert disc["delay_steps"] == 1 and disc["ts"] == 0.001
    assert disc["stable"] is True
    assert disc["final_yaw_rate_rad_s"] == pytest.approx(cont["final_yaw_rate_rad_s"], rel=0.01)
    assert disc["peak_aux_steer_deg"] == pytest.approx(cont["peak_aux_steer_deg"], rel=0.1)


def test_no_controller_means_no_aux_steer(capsys: pytest.CaptureFixture[str]) -> None:
    r = _json(capsys, "sim", "disturbance", "--mz", "1000", "--v", "20", "--mu", "1", "--controller", "none")
    assert r["peak_aux_steer_deg"] == 0.0
    # Uncontrolled d.c. gain of eq. (16) at v = 20, mu = 1.
    a0 = 84000 * 96000 * 2.57**2 + (96000 * 1.32 - 84000 * 1.25) * 1296 * 400
    assert r["final_yaw_rate_rad_s"] == pytest.approx(1000 * 180000 * 20 / a0, rel=1e-3)


def test_steer_is_normalised(capsys: pytest.CaptureFixture[str]) -> None:
    r = _json(capsys, "sim", "steer", "--v", "20", "--mu", "1", "--controller", "none")
    assert r["final_yaw_rate_norm"] == pytest.approx(1.0, abs=1e-3)
    low = _json(capsys, "sim", "steer", "--v", "20", "--mu", "0.8", "--controller", "none")
    ctrl = _json(capsys, "sim", "steer", "--v", "20", "--mu", "0.8", "--controller", "standard")
    assert low["final_yaw_rate_norm"] < 0.97  # the slippery car under-responds...
    assert ctrl["final_yaw_rate_norm"] == pytest.approx(1.0, abs=1e-3)  # ...the regulator restores eq. (18)
    assert "peak_yaw_rate_norm" in ctrl


def test_threshold_matches_a_disturbance_run_at_that_moment(capsys: pytest.CaptureFixture[str]) -> None:
    thr = _json(capsys, "sim", "threshold", "--v", "25", "--mu", "1")["threshold_nm"]
    below = _json(capsys, "sim", "disturbance", "--mz", str(thr * 0.999), "--v", "25", "--mu", "1")
    above = _json(capsys, "sim", "disturbance", "--mz", str(thr * 1.001), "--v", "25", "--mu", "1")
    assert not below["saturated"] and above["saturated"]


@pytest.mark.parametrize("args,needle", [
    (["sim", "disturbance", "--mz", "100", "--v", "-5", "--mu", "1"], "--v"),
    (["sim", "disturbance", "--mz", "100", "--v", "20", "--mu", "0"], "--mu"),
    (["sim", "disturbance", "--mz", "100", "--v", "20", "--mu", "1.6"], "--mu"),
    (["sim", "disturbance", "--mz", "inf", "--v", "20", "--mu", "1"], "--mz"),
    (["sim", "disturbance", "--mz", "100", "--v", "nan", "--mu", "1"], "--v"),
    (["sim", "disturbance", "--mz", "100", "--v", "20", "--mu", "1", "--controller", "pid"], "--controller"),
    (["sim", "steer", "--v", "20", "--mu", "1", "--ts", "-0.001"], "--ts"),
    (["sim", "steer", "--v", "20", "--mu", "1", "--delay-steps", "x"], "--delay-steps"),
    (["sim", "threshold", "--controller", "none"], "--controller"),
    (["sim", "bogus"], "invalid choice"),
])
def test_bad_arguments_give_one_line_and_exit_2(args: list[str], needle: str) -> None:
    proc = _run(*args)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert proc.stdout == ""


def test_out_that_is_a_file_is_refused_without_writing(tmp_path: Path) -> None:
    f = tmp_path / "taken"
    f.write_text("keep me")
    proc = _run("sim", "paper", "--out", str(f))
    assert proc.returncode == 2 and "not a directory" in proc.stderr
    assert f.read_text() == "keep me"


@pytest.mark.parametrize("cmd", [[], ["sim"], ["sim", "disturbance"], ["sim", "steer"], ["sim", "threshold"],
                                 ["sim", "paper"]])
def test_every_command_has_help(cmd: list[str]) -> None:
    proc = _run(*cmd, "--help")
    assert proc.returncode == 0 and "usage:" in proc.stdout


def test_model_delay_defaults_follow_the_gains(capsys: pytest.CaptureFixture[str]) -> None:
    base = ("sim", "disturbance", "--mz", "1000", "--v", "20", "--mu", "1", "--ts", "0.002")
    assert _json(capsys, *base)["model_delay_steps"] == mr.ControllerConfig().model_delay_steps == 1
    assert _json(capsys, *base, "--k", "10", "--tau", "0.006")["model_delay_steps"] == 0  # the paper's law
    assert _json(capsys, *base, "--k", "10", "--tau", "0.006", "--model-delay", "1")["model_delay_steps"] == 1


def test_sim_with_actuator_and_sensors_reports_applied_and_commanded_angle(capsys: pytest.CaptureFixture[str],
                                                                           tmp_path: Path) -> None:
    base = ("sim", "disturbance", "--mz", "1000", "--v", "20", "--mu", "1", "--ts", "0.002", "--k", "5",
            "--tau", "0.05", "--model-delay", "1")
    plain = _json(capsys, *base)
    assert "peak_applied_aux_deg" not in plain  # the ideal loop's output is as it was
    slow = tmp_path / "slow.toml"
    slow.write_text("time_constant_s = 0.05\n")
    lagged = _json(capsys, *base, "--actuator", str(slow))
    # A lagging actuator applies less than it is commanded at the peak; the command is larger.
    assert lagged["peak_applied_aux_deg"] < lagged["peak_aux_steer_deg"]
    assert lagged["peak_aux_steer_deg"] > plain["peak_aux_steer_deg"]
    noisy = [_json(capsys, *base, "--sensors", "default", "--seed", s)["final_aux_steer_deg"] for s in ("1", "1", "2")]
    assert noisy[0] == noisy[1] != noisy[2]  # seeded and reproducible


@pytest.mark.parametrize("args,needle", [
    (["sim", "disturbance", "--mz", "100", "--v", "20", "--mu", "1", "--ts", "0.002", "--actuator", "nofile.toml"],
     "--actuator"),
    (["sim", "steer", "--v", "20", "--mu", "1", "--ts", "0.002", "--sensors", "default", "--seed", "-1"], "--seed"),
    (["sim", "disturbance", "--mz", "100", "--v", "20", "--mu", "1", "--ts", "0", "--actuator", "default"],
     "--ts > 0"),
])
def test_bad_model_arguments_give_one_line_and_exit_2(args: list[str], needle: str) -> None:
    proc = _run(*args)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], proc.stderr
