"""The batch engine's bookkeeping: each row's figures from the steps of its run (``Tally``),
and where each row's run ends (``Ends``: at its last step, or at the step its car spun).

A spun row's arithmetic runs on with its batch (taking a row out of every stage's arrays costs
more than carrying it); these keep everything after its last step out of its figures.
"""

from __future__ import annotations

import numpy as np

from sim_plant.campaign.loads import BLOCK
from sim_plant.campaign.reference import reported_fault, reported_saturated
from sim_plant.car.nonlinear import SPIN_SIDE_SLIP


class Tally:
    """The run's per-row figures from each step's values: a step copies them into its row of a
    block (``BLOCK`` steps), and ``reduce`` folds the block in with one operation per figure
    (the counts, the OR of the bits, the peaks), not a dozen small ones every step."""

    def __init__(self, rows: int, controlled: bool) -> None:
        self.controlled = controlled
        self.x = np.empty((BLOCK, 2, rows))  # beta, r as each step begins
        self.u = np.empty((BLOCK, rows))
        self.status = np.empty((BLOCK, rows), dtype=np.int8)
        self.bits = np.empty((BLOCK, rows), dtype=np.int64)
        self.flags = np.empty((BLOCK, rows), dtype=np.int64)
        self.peaks, self.peak_u = np.zeros((2, rows)), np.zeros(rows)  # |beta|, |r|; |u|
        self.counts = {k: np.zeros(rows, dtype=np.int64) for k in ("at_limit", "faults", "alarms", "authority")}
        self.ored = np.zeros(rows, dtype=np.int64)
        self.no_bits = np.zeros(rows, dtype=np.int64)

    def state(self, j: int, x: np.ndarray) -> None:
        self.x[j] = x[:2]

    def control(self, j: int, u: np.ndarray, status: np.ndarray, bits: np.ndarray, flags: np.ndarray) -> None:
        """Step j's command sent, the law's status, the monitor's bits, the limiter's flags."""
        self.u[j], self.status[j], self.bits[j], self.flags[j] = u, status, bits, flags

    def reduce(self, steps: int, k0: int, ends: "Ends") -> None:
        """The block's first ``steps`` rows (steps k0 on) folded in, each row's to its last step
        (``ends``): the state the controller node reports (``reference.reported_fault`` and
        ``reported_saturated``)."""
        x, u = np.abs(self.x[:steps]), np.abs(self.u[:steps])
        status, bits, flags = self.status[:steps], self.bits[:steps], self.flags[:steps]
        on = ends.within(k0, steps)  # (steps, rows), or None: every row on in the whole block
        if on is not None:  # (spun rows only: nothing after their last step counts)
            x = np.where(on[:, None, :], x, 0.0)  # (a spun row's state runs on: never read, but not NaN*0)
            u = np.where(on, u, 0.0)
            bits = np.where(on, bits, 0)
            flags = np.where(on, flags, 0)
        np.maximum(self.peaks, x.max(axis=0), out=self.peaks)
        if not self.controlled:
            return
        np.maximum(self.peak_u, u.max(axis=0), out=self.peak_u)
        at_limit, fault = reported_saturated(status, bits), reported_fault(status, bits)
        if on is not None:
            at_limit &= on
            fault &= on
        c = self.counts
        c["at_limit"] += np.count_nonzero(at_limit, axis=0)
        c["faults"] += np.count_nonzero(fault, axis=0)
        c["alarms"] += np.count_nonzero(bits, axis=0)
        c["authority"] += np.count_nonzero(flags, axis=0)
        self.ored |= np.bitwise_or.reduce(bits, axis=0)


class Ends:
    """Each row's last step: the run's, or the step whose car spun (``nonlinear.spun``, checked
    on the state as each step begins; that step is the row's last, and its car is not advanced
    past it: the reference's ``run``)."""

    def __init__(self, rows: int, n: int) -> None:
        self.last = np.full(rows, n - 1, dtype=np.int64)  # each row's last step
        self.stop = np.full(rows, n, dtype=np.int64)  # its car advanced in the steps before this one
        self.earliest = n  # the smallest stop: no row has ended before it
        self._limit = np.full(rows, SPIN_SIDE_SLIP)  # inf once a row has ended: not checked again
        self._abs, self._over = np.empty(rows), np.empty(rows, dtype=bool)

    def check(self, k: int, beta: np.ndarray) -> np.ndarray | None:
        """The rows whose car spun as step k begins (None: none)."""
        np.abs(beta, out=self._abs)
        np.greater(self._abs, self._limit, out=self._over)
        if not self._over.any():
            return None
        ending = self._over.copy()
        self.last[ending] = self.stop[ending] = k
        self._limit[ending] = np.inf
        self.earliest = min(self.earliest, k)
        return ending

    def live(self, k: int) -> np.ndarray | None:
        """The rows whose run includes step k (None: all of them)."""
        return None if k <= self.earliest else k <= self.last

    def advanced(self, k: int) -> np.ndarray | None:
        """The rows whose car was advanced in step k (None: all of them)."""
        return None if k < self.earliest else k < self.stop

    def within(self, k0: int, steps: int) -> np.ndarray | None:
        """Per step k0 ... k0 + steps - 1 and row, whether the row's run includes it (None: all)."""
        if k0 + steps - 1 <= self.earliest:
            return None
        return np.arange(k0, k0 + steps)[:, None] <= self.last


def end_traces(traces: dict[str, np.ndarray], last: np.ndarray) -> None:
    """Nothing after a row's last step: NaN (its bits 0)."""
    after = np.arange(next(iter(traces.values())).shape[0])[:, None] > last
    for name, trace in traces.items():
        trace[after] = 0 if trace.dtype.kind == "i" else np.nan


def scatter(default: np.ndarray, at: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = default.copy()
    out[at] = values
    return out
