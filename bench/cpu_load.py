"""A bounded CPU load that a benchmark starts and always stops: ``procs`` busy-loop processes.

Bounded twice: in number (``procs``, one per core by default) and in time. The context manager
stops them on leaving, whether the block ended, raised or was interrupted (Ctrl-C); and each
process also ends by itself after ``max_seconds``, so a bench killed outright (SIGKILL) leaves
no load behind for longer than that. The processes run at the bench's own niceness (0 unless
the bench itself runs under ``nice``): the same priority as the plant, the broker and the
latency probe, which is what a loaded machine means for them.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from types import TracebackType

# A pure busy loop: no memory, no I/O, one core's worth of work until its deadline.
BUSY_LOOP = "import sys, time\nend = time.monotonic() + float(sys.argv[1])\nwhile time.monotonic() < end:\n    pass\n"
STOP_WAIT_S = 5.0


def default_procs() -> int:
    """One busy loop per core: every core has a runnable competitor for the nodes."""
    return os.cpu_count() or 1


@dataclass
class CpuLoad:
    """``procs`` busy-loop processes for at most ``max_seconds``; use as ``with CpuLoad(2, 60):``."""

    procs: int
    max_seconds: float
    children: list[subprocess.Popen[bytes]] = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        if self.procs < 0:
            raise ValueError(f"CPU load: the number of processes must be >= 0, got {self.procs}")
        if not self.max_seconds > 0:
            raise ValueError(f"CPU load: the time bound must be > 0 s, got {self.max_seconds}")

    def start(self) -> None:
        """Start the processes (none for ``procs == 0``); any already running are stopped first."""
        self.stop()
        try:
            for _ in range(self.procs):
                self.children.append(subprocess.Popen(
                    [sys.executable, "-c", BUSY_LOOP, repr(float(self.max_seconds))],
                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        except BaseException:
            self.stop()
            raise

    def running(self) -> int:
        """How many of the processes are still running."""
        return sum(1 for c in self.children if c.poll() is None)

    def pids(self) -> list[int]:
        return [c.pid for c in self.children]

    def stop(self) -> None:
        """Terminate every process and wait for it (killed if it does not end in 5 s)."""
        for c in self.children:
            if c.poll() is None:
                c.terminate()
        deadline = time.monotonic() + STOP_WAIT_S
        for c in self.children:
            try:
                c.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                c.kill()
                c.wait()
        self.children.clear()

    def __enter__(self) -> CpuLoad:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()
