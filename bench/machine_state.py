"""What the machine was doing while a benchmark ran: load average, CPU time by kind, and the
other real-time processes, read from Linux's ``/proc`` (empty figures elsewhere).

A shared machine is never quiet, and a SCHED_FIFO controller is still late when the
hypervisor takes its CPU away (steal) or another real-time process holds it, so the loop
bench states these next to its figures instead of pretending a "quiet" run was quiet.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

PROC = Path("/proc")


@dataclass(frozen=True)
class CpuTimes:
    """The all-CPU line of ``/proc/stat``, in clock ticks."""

    user: int
    nice: int
    system: int
    idle: int
    iowait: int
    irq: int
    softirq: int
    steal: int

    @property
    def total(self) -> int:
        return self.user + self.nice + self.system + self.idle + self.iowait + self.irq + self.softirq + self.steal


def cpu_times(stat: Path = PROC / "stat") -> CpuTimes | None:
    try:
        first = stat.read_text().splitlines()[0].split()
    except (OSError, IndexError):
        return None
    if first[0] != "cpu" or len(first) < 9:
        return None
    return CpuTimes(*(int(v) for v in first[1:9]))


def usage_percent(before: CpuTimes | None, after: CpuTimes | None) -> dict[str, float] | None:
    """Between two snapshots, the share of all CPUs' time: busy (not idle or iowait), of it the
    niced part (other work under ``nice``), and steal (taken by the hypervisor)."""
    if before is None or after is None or after.total <= before.total:
        return None
    span = after.total - before.total
    idle = (after.idle - before.idle) + (after.iowait - before.iowait)
    return {"busy": 100.0 * (span - idle) / span, "niced": 100.0 * (after.nice - before.nice) / span,
            "steal": 100.0 * (after.steal - before.steal) / span}


def realtime_processes(proc: Path = PROC, exclude: frozenset[int] = frozenset()) -> list[dict[str, object]]:
    """User-space processes under SCHED_FIFO or SCHED_RR (kernel threads, with no command line,
    left out): the ones a real-time controller competes with at its own level."""
    out: list[dict[str, object]] = []
    for stat in proc.glob("[0-9]*/stat"):
        pid = int(stat.parent.name)
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmdline = (stat.parent / "cmdline").read_bytes()
        except (OSError, IndexError):
            continue  # the process ended while being read
        # fields from the state (field 3): rt_priority is field 40, policy field 41
        if pid in exclude or not cmdline or len(fields) < 39 or fields[38] not in ("1", "2"):
            continue
        out.append({"pid": pid, "policy": "fifo" if fields[38] == "1" else "rr", "rt_priority": int(fields[37]),
                    "command": cmdline.replace(b"\0", b" ").decode(errors="replace").strip()[:120]})
    return out


def load_average() -> list[float]:
    try:
        return list(os.getloadavg())
    except OSError:
        return []
