"""Child processes of a supervised run (the HIL runner, the fault matrix): each started with
its stderr in a file and bound to die with its parent, waited for until it says it is ready,
and stopped with SIGTERM, then SIGKILL if it will not go.

``spawn`` executes a fresh interpreter, as a user would start the node.  ``spawn_preloaded``
forks the supervisor, which imported the node's modules once, and runs the node's
``main(argv)`` in the child: its own process, sockets, signal handlers and exit status, without
paying the interpreter's start-up each time.

Each child runs in a process group of its own: Ctrl-C at the terminal reaches the supervisor
only, which stops its children in order (SIGTERM: the controller's final zero command, the
loggers' last frames) rather than having every process stop at once on its own.  The fault matrix starts five processes per row
and restarts the controller mid-run; under QEMU without KVM a fresh interpreter takes 10-20 s
to import python-can, numpy and cantools.  (Not ``multiprocessing``'s forkserver: its children
re-import the caller's ``__main__``, which breaks a plain script that calls the runner.)
"""

from __future__ import annotations

import ctypes
import importlib
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from firmware_py.platform.fallback_wire import socket_path


class RunError(RuntimeError):
    """A supervised run failed; the message says which process and how."""


@dataclass
class Proc:
    name: str
    popen: subprocess.Popen | _Forked
    stderr: IO[bytes]


# Held (blocked) in the supervisor while it forks: CPython runs at-fork hooks (logging's lock) in
# Python, and a KeyboardInterrupt raised inside one is printed as "Exception ignored" and lost, so a
# Ctrl-C that lands during a fork would be swallowed and the run go on.  Held, the signal waits and
# is raised on the way out of the fork, in the supervisor's own code.
HELD_DURING_FORK = {signal.SIGINT, signal.SIGTERM}


@contextmanager
def _signals_held() -> Iterator[None]:
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_DURING_FORK)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _pdeathsig() -> None:  # runs in the child between fork and exec
    # The mask survives fork and exec: the node must get the signals the supervisor held.
    signal.pthread_sigmask(signal.SIG_UNBLOCK, HELD_DURING_FORK)
    os.setpgid(0, 0)  # out of the terminal's foreground group: Ctrl-C is the supervisor's to handle
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def spawn(name: str, argv: list[str], work: Path, env: dict[str, str], stdout: bool = False) -> Proc:
    err = open(work / f"{name.replace(' ', '_')}.stderr", "w+b")
    with _signals_held():
        popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL,
                                 stdout=subprocess.PIPE if stdout else subprocess.DEVNULL,
                                 stderr=err, env=env, preexec_fn=_pdeathsig)
    return Proc(name, popen, err)


class _Forked:
    """The part of ``subprocess.Popen`` the supervisor uses, for a forked node."""

    def __init__(self, process: multiprocessing.process.BaseProcess, stdout: IO[bytes] | None) -> None:
        self.process = process
        self.pid = process.pid
        self.stdout = stdout

    @property
    def returncode(self) -> int | None:
        return self.process.exitcode

    def poll(self) -> int | None:
        return self.process.exitcode

    def wait(self, timeout: float | None = None) -> int:
        self.process.join(timeout)
        if self.process.exitcode is None:
            raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout or 0.0)
        return self.process.exitcode

    def send_signal(self, sig: int) -> None:
        if self.process.exitcode is None:
            os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def _run_node(name: str, entry: str, argv: list[str], env: dict[str, str], stdout: str, stderr: str) -> None:
    """The forked child: the node's name, stdio and environment, then its ``main``."""
    _pdeathsig()
    _name_process(name)
    for fd, path in ((1, stdout), (2, stderr)):
        target = os.open(path, os.O_WRONLY | os.O_APPEND)
        os.dup2(target, fd)
        os.close(target)
    # The supervisor's sys.stdout/stderr may write elsewhere than fds 1 and 2 (pytest's capture
    # does): the node gets its own, line-buffered as a terminal would have them.
    sys.stdout = open(1, "w", buffering=1, closefd=False)
    sys.stderr = open(2, "w", buffering=1, closefd=False)
    os.environ.clear()
    os.environ.update(env)
    module, _, func = entry.partition(":")
    sys.exit(getattr(importlib.import_module(module), func)(argv))


def _name_process(name: str) -> None:
    """The node's name where ``ps -o comm``, ``top`` and /proc/PID/comm show it: a forked node's
    command line is its supervisor's."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(15, name.replace(" ", "-").encode()[:15])  # PR_SET_NAME, at most 15 bytes
    except OSError:
        pass


_FORK = multiprocessing.get_context("fork")


def spawn_preloaded(name: str, entry: str, argv: list[str], work: Path, env: dict[str, str],
                    stdout: bool = False) -> Proc:
    """Start ``entry`` (``"module:function"``, called with ``argv``) in a child forked from this
    process; stderr (and stdout if asked, else nothing) go to files in ``work``.  Call it from a
    single-threaded supervisor: a fork copies only the calling thread."""
    importlib.import_module(entry.partition(":")[0])  # once here, inherited by every child
    stem = work / name.replace(" ", "_")
    err = open(f"{stem}.stderr", "w+b")
    out_path = f"{stem}.stdout" if stdout else os.devnull
    out = open(out_path, "w+b") if stdout else None
    process = _FORK.Process(target=_run_node, args=(name, entry, argv, env, out_path, err.name), name=name)
    with _signals_held():
        process.start()
    return Proc(name, _Forked(process, out), err)


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


#: s a process still running after ``stop``'s timeout gets to write its threads' stacks
STACKS_GRACE = 1.0


def stop(p: Proc, timeout: float = 10.0) -> None:
    """SIGTERM, then after ``timeout`` s SIGUSR1 (a bus process's ``run_node`` has every thread's
    stack written to its stderr file on it; another process may just end) and SIGKILL."""
    if p.popen.poll() is None:
        p.popen.send_signal(signal.SIGTERM)
        try:
            p.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            p.popen.send_signal(signal.SIGUSR1)
            try:
                p.popen.wait(STACKS_GRACE)
            except subprocess.TimeoutExpired:
                pass
            p.popen.kill()
            p.popen.wait()
    if p.popen.stdout is not None:
        p.popen.stdout.close()
    p.stderr.close()
