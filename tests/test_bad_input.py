"""Bad input anywhere gives one clear line, exit status 2 and no partial output."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import mrsteer_dbc


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mrsteer_cli", *args], capture_output=True, text=True, timeout=120)


def _one_line_error(proc: subprocess.CompletedProcess[str], code: int, needle: str) -> None:
    assert proc.returncode == code, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines and needle in lines[-1] and "Traceback" not in proc.stderr, proc.stderr


@pytest.mark.parametrize("text,needle", [
    (None, "DBC file not found"),
    ("garbage\n", "cannot load DBC"),
    ("profile", "unsupported E2E profile 'P99'"),
])
def test_a_bad_dbc_is_one_clear_error(tmp_path: Path, text: str | None, needle: str) -> None:
    path = tmp_path / "bus.dbc"
    if text == "profile":
        path.write_text(mrsteer_dbc.DBC_PATH.read_text().replace('"E2E_Profile" BO_ 257 "P01A"',
                                                                  '"E2E_Profile" BO_ 257 "P99"'))
    elif text is not None:
        path.write_text(text)
    _one_line_error(_run("design", "busload", "--bitrate", "500000", "--dbc", str(path)), 2, needle)


@pytest.mark.parametrize("command", [["vectors"], ["sim", "paper"]])
def test_an_output_directory_that_cannot_exist_is_one_clear_error(tmp_path: Path, command: list[str]) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    _one_line_error(_run(*command, "--out", str(blocker / "sub")), 2, f"{blocker} is not a directory")
    _one_line_error(_run(*command, "--out", str(blocker)), 2, "not a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]  # nothing half-written


def test_hil_run_with_an_impossible_output_directory_starts_nothing(tmp_path: Path) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    _one_line_error(_run("hil", "run", "--out", str(blocker / "sub")), 2, f"{blocker} is not a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


# ---------------------------------------------------------------------- every file a command writes

def _limited(max_bytes: int):  # type: ignore[no-untyped-def]
    """preexec_fn: files may not grow past ``max_bytes``, the way a full disk stops them
    (Python ignores SIGXFSZ, so the write fails with EFBIG).  Works for root too."""
    import resource

    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (max_bytes, max_bytes))

    return apply


def _run_limited(args: list[str], max_bytes: int, module: str = "mrsteer_cli") -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True, timeout=300,
                          preexec_fn=_limited(max_bytes))


NODES = {  # each process that writes files at its end, run briefly on python-can's in-process bus
    "controller": ["controller", "--interface", "virtual", "--channel", "x", "--duration", "0.6"],
    "plant": ["plant", "--interface", "virtual", "--channel", "x", "--mode", "lockstep", "--no-controller",
              "--duration", "0.6"],
}
OUTPUT_FLAGS = [("controller", "--stats-out"), ("plant", "--stats-out"), ("plant", "--trace-out")]


@pytest.mark.parametrize("node,flag", OUTPUT_FLAGS)
def test_an_impossible_output_file_is_refused_before_the_run(tmp_path: Path, node: str, flag: str) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    _one_line_error(_run(*NODES[node], flag, str(blocker / "out.json")), 2, "is not an existing directory")
    _one_line_error(_run(*NODES[node], flag, str(tmp_path)), 2, "is a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into any directory")
def test_an_unwritable_directory_is_refused_before_the_run(tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    _one_line_error(_run(*NODES["plant"], "--trace-out", str(locked / "t.csv")), 2, "is not writable")


@pytest.mark.parametrize("node,flag", OUTPUT_FLAGS)
def test_a_full_disk_at_the_end_is_one_error_and_leaves_nothing(tmp_path: Path, node: str, flag: str) -> None:
    out = tmp_path / "out"
    proc = _run_limited([*NODES[node], flag, str(out)], 100)
    _one_line_error(proc, 2, f"cannot write {out}: File too large")
    assert list(tmp_path.iterdir()) == []  # no partial file, no temporary file


def test_a_full_disk_leaves_no_partial_vector_set(tmp_path: Path) -> None:
    out = tmp_path / "vectors"
    out.mkdir()
    (out / "keep.txt").write_text("earlier content\n")
    proc = _run_limited(["vectors", "--out", str(out)], 50_000)  # the first files fit, a later one not
    _one_line_error(proc, 2, "File too large")
    assert [p.name for p in out.iterdir()] == ["keep.txt"]  # not some vectors written, some not


SERVERS = {  # processes that run until signalled, and write their statistics then
    "bridge": (["-m", "sim_plant.nodes.fault_bridge", "--interface", "virtual", "--vehicle", "a", "--controller", "b"],
               "bridging"),
    "logger": (["-m", "sim_plant.nodes.logger", "--interface", "virtual", "--channel", "a"], "ready"),
}


@pytest.mark.parametrize("server", sorted(SERVERS))
def test_signalled_servers_refuse_impossible_outputs_and_survive_a_full_disk(tmp_path: Path, server: str) -> None:
    argv, ready = SERVERS[server]
    extra = ["--out", str(tmp_path / "log.txt")] if server == "logger" else []
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    proc = subprocess.run([sys.executable, *argv, *extra, "--stats-out", str(blocker / "s.json")],
                          capture_output=True, text=True, timeout=120)
    _one_line_error(proc, 2, "is not an existing directory")
    blocker.unlink()
    if server == "logger":
        bad = subprocess.run([sys.executable, *argv, "--out", str(tmp_path / "no" / "log.txt")],
                             capture_output=True, text=True, timeout=120)
        _one_line_error(bad, 2, "cannot write")
    stats = tmp_path / "stats.json"
    p = subprocess.Popen([sys.executable, *argv, *extra, "--stats-out", str(stats)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, preexec_fn=_limited(5))
    stream = p.stdout if server == "logger" else p.stderr
    assert ready in stream.readline()
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 2 and f"cannot write {stats}: File too large" in err and "Traceback" not in err
    assert [q.name for q in tmp_path.iterdir()] == (["log.txt"] if server == "logger" else [])


@pytest.mark.parametrize("extra,needle", [(["--slow-motion", "0.5"], "--slow-motion must be in [1, 100]"),
                                          (["--slow-motion", "2"], "--slow-motion is for --mode realtime")])
def test_a_plant_refuses_slow_motion_it_cannot_run(extra: list[str], needle: str) -> None:
    _one_line_error(_run(*NODES["plant"], *extra), 2, needle)


def test_a_bridge_refuses_an_out_of_range_value_its_frame_cannot_carry() -> None:
    argv = SERVERS["bridge"][0]
    proc = subprocess.run([sys.executable, *argv, "--fault", '{"kind": "out_of_range", "param": 5.0}'],
                          capture_output=True, text=True, timeout=120)
    _one_line_error(proc, 2, "5 does not fit YawRate_YawRate's 16-bit field (-3.2768 to 3.2767)")
