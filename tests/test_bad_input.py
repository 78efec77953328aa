"""Bad input anywhere gives one clear line, a non-zero exit and no partial output."""

from __future__ import annotations

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
    _one_line_error(_run(*command, "--out", str(blocker / "sub")), 1, "Not a directory")
    _one_line_error(_run(*command, "--out", str(blocker)), 2, "not a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]  # nothing half-written


def test_hil_run_with_an_impossible_output_directory_starts_nothing(tmp_path: Path) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    _one_line_error(_run("hil", "run", "--out", str(blocker / "sub")), 1, "Not a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]
