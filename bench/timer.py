"""Per-call timing: the median over repeated batches of a call."""

from __future__ import annotations

import statistics
import time
from typing import Callable


def per_call_us(fn: Callable[[], object], calls: int, repeats: int) -> dict[str, float]:
    """Median, p10 and p90 over ``repeats`` batches of the mean time of one call, in us."""
    fn()  # warm up
    per = []
    clock = time.perf_counter_ns
    for _ in range(repeats):
        t0 = clock()
        for _ in range(calls):
            fn()
        per.append((clock() - t0) / calls / 1000.0)
    per.sort()
    return {"median_us": statistics.median(per), "p10_us": per[len(per) // 10],
            "p90_us": per[min(len(per) - 1, (9 * len(per)) // 10)]}
