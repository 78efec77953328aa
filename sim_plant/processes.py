"""Child processes of a supervised run (the HIL runner, the fault matrix): each started with
its stderr in a file and bound to die with its parent, waited for until it says it is ready,
and stopped with SIGTERM, then SIGKILL if it will not go."""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from sim_plant.vbus import socket_path


class RunError(RuntimeError):
    """A supervised run failed; the message says which process and how."""


@dataclass
class Proc:
    name: str
    popen: subprocess.Popen
    stderr: IO[bytes]


def _pdeathsig() -> None:  # runs in the child between fork and exec
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def spawn(name: str, argv: list[str], work: Path, env: dict[str, str], stdout: bool = False) -> Proc:
    err = open(work / f"{name.replace(' ', '_')}.stderr", "w+b")
    popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE if stdout else subprocess.DEVNULL,
                             stderr=err, env=env, preexec_fn=_pdeathsig)
    return Proc(name, popen, err)


def tail(p: Proc) -> str:
    try:
        p.stderr.flush()
        p.stderr.seek(0)
        lines = [ln for ln in p.stderr.read().decode(errors="replace").splitlines() if ln.strip()]
    except (OSError, ValueError):
        return ""
    return f" (last words: {lines[-1]})" if lines else ""


def wait_ready(p: Proc, timeout: float = 120.0) -> None:
    assert p.popen.stdout is not None
    os.set_blocking(p.popen.stdout.fileno(), False)
    deadline = time.monotonic() + timeout
    buf = b""
    while time.monotonic() < deadline:
        if p.popen.poll() is not None:
            raise RunError(f"{p.name} exited with status {p.popen.returncode} before it was ready{tail(p)}")
        chunk = p.popen.stdout.read() or b""
        buf += chunk
        if b"ready" in buf:
            return
        time.sleep(0.02)
    raise RunError(f"{p.name} did not become ready")


def wait_stderr(p: Proc, marker: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if p.popen.poll() is not None:
            raise RunError(f"{p.name} exited with status {p.popen.returncode} before it was ready{tail(p)}")
        p.stderr.flush()
        with open(p.stderr.name, "rb") as f:
            if marker.encode() in f.read():
                return
        time.sleep(0.02)
    raise RunError(f"{p.name} did not become ready")


def wait_for_socket(channel: str, broker: Proc) -> None:
    path = socket_path(channel)
    deadline = time.monotonic() + 10.0
    while not path.exists():
        if broker.popen.poll() is not None:
            raise RunError(f"bus broker exited with status {broker.popen.returncode}{tail(broker)}")
        if time.monotonic() > deadline:
            raise RunError("bus broker did not come up")
        time.sleep(0.02)


def stop(p: Proc, timeout: float = 10.0) -> None:
    if p.popen.poll() is None:
        p.popen.send_signal(signal.SIGTERM)
        try:
            p.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            p.popen.kill()
            p.popen.wait()
    if p.popen.stdout is not None:
        p.popen.stdout.close()
    p.stderr.close()
