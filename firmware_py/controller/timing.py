"""The controller's clock: lateness of each cycle start and the phase lock of the cycle grid
to the yaw-rate frames' arrival."""

from __future__ import annotations

import array
import math

SENSORS_WATCHDOG_S = 1.0  # sensors trigger: wall time without a yaw-rate frame before a cycle runs anyway
STOP_POLL_S = 0.05  # sensors trigger: the slice a frame is waited for in, so a stop is seen this soon
DEFAULT_SYNC_OFFSET = 50e-6  # s after the yaw-rate frame's arrival that the cycle aims to start
SYNC_GAIN = 0.1  # fraction of the phase error corrected per cycle
SYNC_MAX_SLEW = 0.02  # largest correction per cycle, as a fraction of the period
SYNC_POLL_S = 20e-6  # polling step inside that window
SYNC_WINDOW = 0.25  # how long a cycle waits for a late yaw-rate frame, as a fraction of the period


class LatenessHistogram:
    """Cycle-start lateness in fixed 1 us bins up to 50 ms, preallocated: a run of any length
    costs no memory (a C port keeps the same uint32 array)."""

    BIN_S = 1e-6
    BINS = 50_000

    def __init__(self) -> None:
        self.counts = array.array("I", bytes(4 * (self.BINS + 1)))  # the last bin is overflow
        self.n = 0
        self.max = 0.0

    def add(self, late: float) -> None:
        i = int(late / self.BIN_S) if late > 0.0 else 0
        self.counts[i if i < self.BINS else self.BINS] += 1
        self.n += 1
        if late > self.max:
            self.max = late

    def percentile(self, q: float) -> float:
        """Upper edge of the bin holding the q-quantile (the max if it lies in the overflow)."""
        if self.n == 0:
            return 0.0
        rank = min(self.n, max(1, math.ceil(q * self.n)))
        seen = 0
        for i, c in enumerate(self.counts):
            seen += c
            if seen >= rank:
                return self.max if i == self.BINS else min((i + 1) * self.BIN_S, self.max)
        return self.max


def phase_correction(arrival: float, cycle_start: float, period: float, offset: float) -> float:
    """Shift of the next deadline that moves cycle starts toward ``arrival + offset``.

    The error is wrapped into half a period either way (the grid may lock onto the nearest
    frame), a fraction SYNC_GAIN of it is corrected, at most SYNC_MAX_SLEW of a period per
    cycle, so sensor jitter cannot drag the loop around.
    """
    err = arrival + offset - cycle_start
    err -= period * round(err / period)
    limit = SYNC_MAX_SLEW * period
    return max(-limit, min(limit, SYNC_GAIN * err))
