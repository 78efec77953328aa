"""Real-time set-up of a loop process where the OS permits it: SCHED_FIFO priority, CPU
pinning, and the resident set size for the memory-growth report."""

from __future__ import annotations

import os
from typing import Any


def rss_kb() -> int:
    """Resident set size now, in KiB (Linux /proc; 0 where unavailable)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") // 1024)
    except (OSError, ValueError, IndexError):
        return 0


def apply_platform(rt_priority: int, cpu: int | None) -> dict[str, Any]:
    """Real-time priority and CPU pinning, where the OS permits them; says what happened."""
    out: dict[str, Any] = {"rt_priority": 0, "cpu_affinity": sorted(os.sched_getaffinity(0))}
    if rt_priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt_priority))
            out["rt_priority"] = rt_priority
        except (OSError, AttributeError) as exc:
            out["rt_priority_denied"] = str(exc)
    if cpu is not None:
        try:
            os.sched_setaffinity(0, {cpu})
        except (OSError, ValueError) as exc:
            out["cpu_denied"] = str(exc)
        out["cpu_affinity"] = sorted(os.sched_getaffinity(0))
    return out
