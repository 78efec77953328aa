"""When a sensor fault's error left its bound (``bounds.sensor_bound``), the moment issue 18's
detection target counts from: the start of the first stretch over the bound that lasts ``HOLD``
(300 ms) or until the monitor reported, and the campaigns' per-row figures built on it.

* ``exceeded_time``: one run sampled every period (the offline runs, the campaigns' scalar
  reference); ``hold`` counted in periods (``round(hold / dt)`` of them), a stretch reaching the
  run's end counts.
* ``ExceededTracker``: the same, a batch of rows one step at a time (the campaigns' engine).
* ``exceeded_at``: samples at the frames' own times (the fault matrix, from the logged bus);
  ``hold`` counted in time (``t - start >= hold``), a stretch reaching the series' end counts
  only when cut by the report.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from firmware_py import plausibility as pl
from sim_plant.judge.bounds import check_offset, is_braking, sensor_bound

#: How long a fault's error must stay over its bound to count as having left it (s): issue 18's
#: detection target counts from there.
HOLD = 0.3

#: A sample of the falsified signal as the controller got it: (t, error, bound).
ErrorSample = tuple[float, float, float]


def exceeded_time(t: np.ndarray, error: np.ndarray, bound: float | np.ndarray, reported: float | None,
                  hold: float = HOLD) -> float | None:
    """When the error (one per period ``t``, from 0) became larger than ``bound`` to stay so for
    ``hold`` s (or until ``reported``, the monitor's first report, if sooner, or to the run's
    end): the start of the window the detection target counts from, by ``ExceededTracker`` on a
    batch of one.  A brief excursion that falls back within the bound does not start it; None if
    none did."""
    over = np.abs(error) > bound
    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    tracker = ExceededTracker(1, max(1, int(round(hold / dt))), over.size - 1)
    report = -1 if reported is None else int(round(reported / dt))
    for k in range(over.size):
        tracker.step(k, over[k:k + 1], np.array([k == report]))
        if tracker.exceeded[0] >= 0:
            return float(t[tracker.exceeded[0]])
    return None


def exceeded_at(series: list[ErrorSample], until: float | None, hold: float = HOLD) -> float | None:
    """When the error left its bound to stay over it for ``hold`` s, or until ``until`` (the
    report) if sooner; ``None`` if it never did by then.  A brief excursion does not count."""
    start = None
    for t, err, bound in series:
        if until is not None and t > until:
            break
        if abs(err) > bound:
            start = t if start is None else start
            if t - start >= hold:
                return start
        else:
            start = None
    return start if until is not None else None


class ExceededTracker:
    """``exceeded_time`` per row, one step at a time: the step at which the sensor's error became
    larger than its bound to stay so for ``need`` steps, or until the monitor's first fault
    report, or to the run's end (-1: not yet)."""

    def __init__(self, rows: int, need: int, last: int) -> None:
        self.need, self.last = need, last
        self.start = np.full(rows, -1, dtype=np.int64)  # where the current run over the bound began
        self.exceeded = np.full(rows, -1, dtype=np.int64)

    def step(self, k: int, over: np.ndarray, first_report: np.ndarray, ending: np.ndarray | None = None) -> None:
        """Step k: ``over`` the error beyond its bound, ``first_report`` the monitor's first fault now,
        ``ending`` the rows whose run ends with this step (their car spun; None: none)."""
        start = np.where(over, np.where(self.start < 0, k, self.start), -1)
        long_enough = (k - start + 1 >= self.need) | first_report | (k == self.last)
        if ending is not None:
            long_enough |= ending
        found = over & long_enough & (self.exceeded < 0)
        self.exceeded = np.where(found, start, self.exceeded)
        self.start = start


class FaultRows(Protocol):
    """A batch's sensor faults as ``FaultFigures`` reads them (``campaign.batch_faults.BatchFaults``)."""

    onset: np.ndarray  # each row's fault onset (s)
    sensor: np.ndarray  # each row's faulted channel's code (0: none)
    rows: dict[str, np.ndarray]  # channel -> the rows it is faulted in


class FaultFigures:
    """The figures of a batch's sensor faults, one engine step at a time: ``false_alarms``
    (alarms before the fault's onset, or in the whole run without one) and ``detection_time``
    (from the error leaving ``sensor_bound`` with ``check_offset`` for ``HOLD`` to the report)."""

    def __init__(self, faults: FaultRows, n: int, ts: float,
                 bias: dict[str, float | np.ndarray] | None = None) -> None:
        rows = faults.onset.size
        self.faults, self.ts = faults, ts
        self.bias = bias if bias is not None else {}  # the healthy offsets (check_offset's), per row
        self.cfg = pl.PlausibilityConfig(ts=ts)
        self.faulted = faults.sensor != 0
        self.tracker = ExceededTracker(rows, max(1, int(round(HOLD / ts))), n - 1)
        self.reported = np.zeros(rows, dtype=bool)
        self.report_step = np.full(rows, -1, dtype=np.int64)
        self.alarms = np.zeros(rows, dtype=np.int64)
        # Each faulted channel's bound, each step at the true r and v (a campaign's car has the
        # yaw-rate sensor's second element, so the pair runs, and the second speed; below the
        # monitor's speed_min every bound is infinite).
        self.channels = dict(faults.rows)
        self.v_prev: np.ndarray | None = None  # the true speed the step before (is_braking's test)
        self.speed_faulted = any(ch in ("speed", "speed_redundant") for ch in self.channels)  # braking matters

    def step(self, k: int, error: np.ndarray, bits: np.ndarray, r_true: np.ndarray, v_true: np.ndarray,
             flags: np.ndarray | int = 0, live: np.ndarray | None = None, ending: np.ndarray | None = None) -> None:
        """Step k: the faulted channels' errors, the monitor's bits, the true yaw rate and speed,
        the monitor's detailed flags (their OUTSIDE_MODEL is a report; a missing input's
        DEGRADED is not); ``live`` the rows whose run includes step k (None: all; a run that spun
        has ended), ``ending`` those whose run ends with it (None: none)."""
        def one(x: np.ndarray | int | None) -> np.ndarray | int | None:
            return x if x is None or np.ndim(x) == 0 else np.asarray(x)[None]
        self.steps(k, one(error), one(bits), one(r_true), one(v_true), one(flags), one(live), one(ending))

    def steps(self, k0: int, error: np.ndarray, bits: np.ndarray, r_true: np.ndarray, v_true: np.ndarray,
              flags: np.ndarray | int = 0, live: np.ndarray | None = None, ending: np.ndarray | None = None) -> None:
        """``step`` over the steps k0, k0 + 1, ... at once: every argument steps x rows (a
        single run: a batch of one, a column)."""
        m = np.shape(error)[0]
        if live is not None:
            bits, flags = np.where(live, bits, 0), np.where(live, flags, 0)
        t = (k0 + np.arange(m))[:, None] * self.ts
        after = self.faulted & (self.faults.onset <= t)
        self.alarms += np.count_nonzero((bits != 0) & ~after, axis=0)
        fault = ((bits & pl.PLAUS_FAULT) != 0) | ((flags & pl.OUTSIDE_MODEL) != 0)  # the report
        fault = np.broadcast_to(fault, after.shape)
        earlier = np.logical_or.accumulate(fault, axis=0)[:-1]  # a report in the block's steps before
        seen_before = self.reported | np.vstack([np.zeros_like(fault[:1]), earlier])
        first = fault & ~seen_before
        self.reported = self.reported | fault.any(axis=0)
        self.report_step = np.where(first.any(axis=0), k0 + np.argmax(first, axis=0), self.report_step)
        braking: bool | np.ndarray = False
        if self.speed_faulted:  # only a speed's bound widens while the car brakes
            v_before = np.vstack([v_true[:1] if self.v_prev is None else self.v_prev[None], v_true[:-1]])
            braking = is_braking(v_before, v_true, self.ts, self.cfg)
            if self.v_prev is None:
                braking[0] = False
            self.v_prev = v_true[-1].copy()
        bound = np.full(np.shape(error), np.inf)
        seen = error
        for channel, on in self.channels.items():
            bound = np.where(on, sensor_bound(channel, self.cfg, r_true, v_true, True, speed_pair=True,
                                              braking=braking), bound)
            seen = np.where(on, error + check_offset(channel, self.bias, v_true, after), seen)
        over = np.abs(seen) > bound
        if live is not None:
            over = over & live
        for j in range(m):
            self.tracker.step(k0 + j, over[j], first[j], None if ending is None else ending[j])

    def result(self) -> dict[str, np.ndarray]:
        ex, rep, ts = self.tracker.exceeded, self.report_step, self.ts
        late = np.where(rep < 0, np.inf, np.maximum(0.0, rep * ts - ex * ts))
        return {"false_alarms": self.alarms,
                "detection_time": np.where(~self.faulted, np.nan, np.where(ex < 0, 0.0, late))}
