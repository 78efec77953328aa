"""Every error of every ``mrsteer`` command is one line on stderr that starts ``mrsteer:``, exit
status 2, no traceback, and nothing written; Ctrl-C stops every process a run started and is one
line and exit status 130; a ``--rate-hz`` without a calibration of its own is refused by every
command in the same words."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import mrsteer_dbc
from conftest import ctrl_c_reaches_it
from firmware_py import calibration_file
from firmware_py.calibration import RATE_CALIBRATIONS, ControllerConfig
from firmware_py.controller.options import RateError, calibration_for_rate
from mrsteer_dbc import names
from mrsteer_cli.cli import main

ROOT = Path(__file__).resolve().parents[1]
RATE_WORDS = "rate-hz 250: no calibration for 250 Hz; there is one for 100, 200, 500 and 1000 Hz"
UNWRITABLE = "/proc/1/mrsteer-out"  # a directory no one may create, root included


def _files(tmp_path: Path) -> list[str]:
    """Everything under the test's directory, the fixtures' files included."""
    return sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))


@pytest.fixture
def place(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working directory with the bad inputs: a file, a directory, a malformed TOML, a log."""
    (tmp_path / "afile").write_text("x\n")
    (tmp_path / "adir").mkdir()
    (tmp_path / "bad.toml").write_text("not toml [[\n")
    c = mrsteer_dbc.load()
    yaw = c.encode(names.MSG_YAW, {"YawRate_YawRate": 0.01}, 0).hex().upper()
    (tmp_path / "x.log").write_text(f"(1700000000.000000) vcan0 {c.frame_id(names.MSG_YAW):03X}#{yaw}\n")
    monkeypatch.chdir(tmp_path)  # a stray default output would land here, and be seen
    return tmp_path


# argv (OUT: an output directory that must stay unwritten), and what the one line says
CASES = [
    # a bus that cannot be had here: refused before anything starts
    (["hil", "run", "--interface", "socketcan", "--channel", "vcan7", "--out", "OUT"], "SocketCAN|vcan7"),
    (["hil", "run", "--interface", "nosuchiface", "--out", "OUT"],
     "--interface nosuchiface: python-can has no such interface; usable here: mrsteer .*python-can knows .*socketcan"),
    (["hil", "run", "--interface", "virtual", "--out", "OUT"], "virtual bus lives inside one process"),
    (["faults", "run", "--interface", "nosuchiface", "--channels", "a,b"], "no such interface"),
    (["controller", "--interface", "nosuchiface"], "no such interface"),
    (["plant", "--interface", "socketcan", "--channel", "vcan7", "--duration", "1"], "SocketCAN|vcan7"),
    (["faults", "bridge", "--interface", "nosuchiface", "--vehicle", "a", "--controller", "b"], "no such interface"),
    # --rate-hz without a calibration for the rate: every command alike
    (["hil", "run", "--rate-hz", "250", "--out", "OUT"], RATE_WORDS),
    (["hil", "demo", "--rate-hz", "250", "--out", "OUT"], RATE_WORDS),
    (["hil", "evidence", "--rate-hz", "250", "--out", "OUT"], RATE_WORDS),
    (["controller", "--rate-hz", "250", "--interface", "virtual", "--duration", "0.2"], RATE_WORDS),
    (["faults", "run", "--rate-hz", "250"], RATE_WORDS),
    (["replay", "x.log", "--rate-hz", "250", "--out", "OUT"], RATE_WORDS),
    (["bench", "--only", "loop", "--loop-rate-hz", "250"], RATE_WORDS),
    (["hil", "run", "--rate-hz", "200", "--calibration", str(ROOT / "tests/vectors/previous_500hz.cfg"),
      "--out", "OUT"], "--rate-hz 200: the --calibration file is made for 500 Hz"),
    # an output directory that cannot be: refused before the work
    (["hil", "run", "--out", "afile/sub"], "--out afile/sub: afile is not a directory"),
    (["hil", "run", "--out", UNWRITABLE], "not writable"),
    (["hil", "demo", "--out", "afile"], "afile is not a directory"),
    (["sim", "paper", "--out", "afile/x"], "afile is not a directory"),
    (["vectors", "--out", UNWRITABLE], "not writable"),
    (["replay", "x.log", "--out", UNWRITABLE], "not writable"),
    (["campaign", "run", str(ROOT / "campaigns/example.toml"), "--out", "afile"], "exists and is not a directory"),
    (["design", "tune", "--schedule", "--out", "adir"], "--out adir is a directory"),
    # files that are directories, missing or malformed: the reason, never an errno
    (["hil", "run", "--scenario", "adir", "--out", "OUT"], "adir: cannot read: Is a directory$"),
    (["hil", "run", "--scenario", "bad.toml", "--out", "OUT"], "bad.toml: not valid TOML"),
    (["hil", "run", "--scenario", "no-such-scenario", "--out", "OUT"], "no built-in scenario or file named"),
    (["campaign", "run", "missing.toml", "--out", "OUT"], "missing.toml: cannot read: No such file or directory$"),
    (["design", "busload", "--bitrate", "500000", "--dbc", "adir"], "cannot load DBC adir: Is a directory$"),
    (["replay", "adir"], "adir: is a directory"),
    (["hil", "run", "--controller-cmd", "/nonexistent/ecu", "--out", "OUT"], "/nonexistent/ecu: no such program"),
    # argument errors, parsed by each command's own parser
    (["sim", "steer", "--v", "1000", "--mu", "1"], "argument --v: speed v must be in"),
    (["controller", "--cpu", "999"], "--cpu must be in"),
]


def _code(argv: list[str]) -> int | str | None:
    """``mrsteer argv`` in this process: its exit status, whether returned or raised by a parser."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


@pytest.mark.parametrize("argv,needle", CASES, ids=[" ".join(a[:2]) + f" #{i}" for i, (a, _) in enumerate(CASES)])
def test_an_error_is_one_line_exit_2_and_writes_nothing(place: Path, capsys: pytest.CaptureFixture[str],
                                                        argv: list[str], needle: str) -> None:
    before = _files(place)
    code = _code([str(place / "out") if a == "OUT" else a for a in argv])
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("mrsteer: "), err
    assert re.search(needle, lines[0]), lines[0]
    assert "Traceback" not in err and "Errno" not in err
    assert _files(place) == before  # no output directory, no partial log


def test_a_broker_refuses_a_negative_idle_time(tmp_path: Path) -> None:
    # a subprocess: the old broker took it and served forever
    proc = subprocess.run([sys.executable, "-m", "mrsteer_cli", "bus", "--channel", "t-idle", "--idle-exit", "-1"],
                          capture_output=True, text=True, timeout=60, env={**os.environ, "MRSTEER_BUS_DIR": str(tmp_path)})
    assert proc.returncode == 2 and proc.stderr.splitlines() == [
        "mrsteer: bus: --idle-exit must be a positive number of seconds, got -1"]


def test_the_rate_words_name_the_command_and_nothing_else_differs(place: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    lines = {}
    for argv in (["hil", "run", "--rate-hz", "250"], ["controller", "--rate-hz", "250"], ["faults", "run", "--rate-hz", "250"]):
        assert _code(argv) == 2
        lines[argv[0]] = capsys.readouterr().err.strip()
    assert lines["hil"].startswith("mrsteer: hil run: --rate-hz 250: no calibration for 250 Hz")
    assert lines["controller"] == lines["hil"].replace("hil run", "controller")  # same words, same advice
    assert lines["faults"] == lines["hil"].split(", or give")[0].replace("hil run", "faults run")  # it takes no file


# ---------------------------------------------------------------------------- the shared rate check

def test_a_rate_runs_with_the_calibration_made_for_it(tmp_path: Path) -> None:
    assert calibration_for_rate(None) == ControllerConfig()
    for rate, cfg in RATE_CALIBRATIONS.items():
        assert calibration_for_rate(rate) is cfg and cfg.ts == pytest.approx(1.0 / rate)
    cfg = calibration_file.load(ROOT / "tests/vectors/limited_zoh_200hz_m1.cfg")
    assert calibration_for_rate(200.0, cfg) is cfg and calibration_for_rate(None, cfg) is cfg
    with pytest.raises(RateError, match="the --calibration file is made for 200 Hz"):
        calibration_for_rate(500.0, cfg)
    with pytest.raises(RateError, match="no calibration for 250 Hz"):
        calibration_for_rate(250.0)
    assert calibration_for_rate(250.0, cfg, hand=True).ts == 0.004  # gains by hand: any rate


# ------------------------------------------------------------------------------------------- Ctrl-C

def _children(pid: int) -> set[int]:
    out = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            if int(stat.read_text().rsplit(")", 1)[1].split()[1]) == pid:
                out.add(int(stat.parent.name))
        except (OSError, IndexError, ValueError):
            continue
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _interrupt(tmp_path: Path, argv: list[str], ready: str, kids: int) -> tuple[int, str, set[int]]:
    """Start ``mrsteer argv``, wait for the ``ready`` line on stderr and ``kids`` children, Ctrl-C
    it; its exit status, the stderr after the signal and the children it had."""
    proc = subprocess.Popen([sys.executable, "-m", "mrsteer_cli", *argv], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            env={**os.environ, "MRSTEER_BUS_DIR": str(tmp_path / "bus")},
                            preexec_fn=ctrl_c_reaches_it)
    assert proc.stderr is not None
    try:
        for line in proc.stderr:
            if ready in line:
                break
        else:
            pytest.fail(f"{argv} ended before {ready!r}")
        started: set[int] = set()
        deadline = time.monotonic() + 120  # generous: the machine is loaded
        while len(started) < kids and time.monotonic() < deadline:
            started |= _children(proc.pid)
            time.sleep(0.05)
        assert len(started) >= kids, started
        proc.send_signal(signal.SIGINT)  # Ctrl-C to the runner alone, as `kill -INT` does
        rest = proc.stderr.read()
        code = proc.wait(120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return code, rest, started


def test_ctrl_c_stops_a_realtime_run_and_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "run"
    code, err, started = _interrupt(tmp_path, ["hil", "run", "--mode", "realtime", "--duration", "60", "--out",
                                               str(out)], "running paper-fig9", 4)  # broker, logger, controller, plant
    assert code == 130 and err.splitlines() == [
        f"mrsteer: hil run: interrupted; every process it started is stopped, nothing written to {out}"], err
    assert not out.exists()
    assert not [pid for pid in started if _alive(pid)]


def test_ctrl_c_stops_the_fault_matrix_and_keeps_only_whole_rows(tmp_path: Path) -> None:
    keep = tmp_path / "keep"
    # one row, stretched to 40 s so that it is still running when the signal comes on a loaded
    # machine: its brokers and loggers at least
    code, err, started = _interrupt(tmp_path, ["faults", "run", "--only", "driver steers", "--time-scale", "10",
                                               "--keep", str(keep)], "[1/1]", 3)
    assert code == 130 and err.splitlines() == [
        f"mrsteer: faults run: interrupted: every process it started is stopped, no table; the rows run before it "
        f"are in {keep}/"], err
    assert list(keep.iterdir()) == []  # the interrupted row's half-written files are gone
    assert not [pid for pid in started if _alive(pid)]


def test_ctrl_c_in_an_offline_command_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from sim_plant.harness import replay

    def interrupted(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(replay, "replay", interrupted)
    log = tmp_path / "x.log"
    log.write_text("")
    assert main(["replay", str(log), "--out", str(tmp_path / "out")]) == 130
    assert capsys.readouterr().err.splitlines() == ["mrsteer: replay: interrupted; nothing written"]
    assert [p.name for p in tmp_path.iterdir()] == ["x.log"]


def test_a_failed_output_leaves_no_directory_it_made(tmp_path: Path) -> None:
    from firmware_py.platform.files import staged_directory

    (tmp_path / "kept").mkdir()
    with pytest.raises(RuntimeError), staged_directory(tmp_path / "kept" / "new" / "deeper" / "out") as stage:
        (stage / "half.csv").write_text("1,2\n")
        raise RuntimeError("the run failed")
    assert [p.name for p in tmp_path.rglob("*")] == ["kept"]  # its new parents gone, the old one kept
    with staged_directory(tmp_path / "kept" / "new" / "out") as stage:
        (stage / "whole.csv").write_text("1,2\n")
    assert (tmp_path / "kept" / "new" / "out" / "whole.csv").read_text() == "1,2\n"
