"""The life of a bus process after its bus is open: signals, the ready line, bus failures,
shutdown and the outputs written at exit."""

from __future__ import annotations

import faulthandler
import signal
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

import can

from firmware_py.platform.cli import describe, fail
from firmware_py.platform.files import write_atomic

Outputs = Sequence[tuple[Path | None, Callable[[], str | bytes]]]


def run_node(prog: str, bus: can.BusABC | Sequence[can.BusABC], run: Callable[[], Any], stop: Callable[..., Any],
             outputs: Outputs = (), ready: str | None = None) -> int:
    """The life of a bus process after its bus is open.

    SIGINT and SIGTERM call ``stop`` (the loop ends after its current cycle); ``ready`` is then
    printed on stderr (a supervisor may signal from that moment on); a bus failure is
    one line and exit status 2; the bus (or each of them) is always shut down; then each output whose path was
    given is written whole (``write_atomic``), and one that cannot be is one line and exit 2.
    """
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        # A supervisor that finds the process still running long after SIGTERM sends SIGUSR1
        # before it kills it (sim_plant.harness.processes.stop), so that where every thread
        # hung is on stderr afterwards.
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    except (AttributeError, ValueError, OSError, RuntimeError):
        pass  # stderr is no file (a test capturing it): no stacks, nothing else changes
    if ready is not None:
        print(f"{prog}: {ready}", file=sys.stderr, flush=True)
    code = 0
    try:
        run()
    except can.CanError as exc:
        code = fail(prog, f"bus failed: {describe(exc)}")
    finally:
        for b in [bus] if isinstance(bus, can.BusABC) else bus:
            b.shutdown()
    for path, render in outputs:
        if path is None:
            continue
        try:
            write_atomic(path, render())
        except OSError as exc:
            code = fail(prog, f"cannot write {path}: {exc.strerror or exc}")
    return code
