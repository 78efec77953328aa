"""Sensor faults in a batch: ``sensor_faults.FaultedChannel.input`` vectorised for the kinds a
campaign samples, one fault per row at most, and the error each one makes.

A row's fault is its ``fault_sensor`` (``params.FAULT_CHANNELS``; ``none``: no fault),
``fault_kind`` (``params.FAULT_KINDS``: ``stuck``, ``offset``, ``gain``, ``drift``, the
``SensorFault`` kinds ``stuck``, ``bias``, ``scale``, ``drift``), ``fault_onset`` and the value
``params.fault_value`` makes of its ``fault_size``.  It acts on the channel's input, before the
sensor's noise, filter and quantisation, from the onset (``start <= t``) to the end, with the
scalar's arithmetic: ``value``, ``x + value``, ``x * value``, ``x + value (t - start)``.

``BatchSensors`` applies ``input`` to each channel; the error of a faulted reading is the
reading less that of the same sensor without the fault (``plausibility_runs.run``'s ``clean``
copy), which ``ExceededTracker`` follows against the monitor's bound, with the healthy sensors'
offsets its check sees (``plausibility_runs.check_offset``).
"""

from __future__ import annotations

import numpy as np

from firmware_py import plausibility as pl
from sim_plant.campaign.params import FAULT_CHANNELS, FAULT_KINDS, SampleSet, fault_value
from sim_plant.offline.plausibility_runs import check_offset, is_braking, sensor_bound


class BatchFaults:
    """The rows' sensor faults: ``input(channel, t, x)`` is x as the faulted channel's sensing
    element gives it at time t (x itself in the rows without a fault on ``channel``)."""

    def __init__(self, s: SampleSet) -> None:
        sensor = s["fault_sensor"].astype(np.int64)
        kind = s["fault_kind"].astype(np.int64)
        self.onset = s["fault_onset"]
        self.value = fault_value(sensor, kind, s["fault_size"])
        self.sensor = sensor
        #: channel -> its faulted rows (only the channels some row faults)
        self.rows = {ch: sensor == code for code, ch in enumerate(FAULT_CHANNELS)
                     if ch != "none" and bool((sensor == code).any())}
        self.kinds = {name: kind == code for code, name in enumerate(FAULT_KINDS)}

    def input(self, channel: str, t: float, x: np.ndarray) -> np.ndarray:
        rows = self.rows.get(channel)
        if rows is None:
            return x
        on = rows & (self.onset <= t)
        if not on.any():
            return x
        k, value = self.kinds, self.value
        x = np.where(on & k["stuck"], value, x)
        x = np.where(on & k["offset"], x + value, x)
        x = np.where(on & k["gain"], x * value, x)
        return np.where(on & k["drift"], x + value * (t - self.onset), x)


class ExceededTracker:
    """``plausibility_runs.MonitorRun.exceeded_time`` per row, one step at a time: the step at
    which the sensor's error became larger than its bound to stay so for ``need`` steps, or
    until the monitor's first fault report, or to the run's end (-1: not yet)."""

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


#: How long a fault's error must stay over its bound to count as having left it (s): issue 18's
#: detection target counts from there (``MonitorRun.exceeded_time``'s default ``hold``, which
#: the reference uses: the equality test holds the two together).
HOLD = 0.3


class FaultFigures:
    """The figures of a batch's sensor faults, one engine step at a time: ``false_alarms``
    (alarms before the fault's onset, or in the whole run without one) and ``detection_time``
    (``engine.METRICS``; ``fault_yaw_rate`` and ``twin_yaw_rate`` are the engine's, from a
    fault-free twin)."""

    def __init__(self, faults: BatchFaults, n: int, ts: float,
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
        if live is not None:
            bits, flags = np.where(live, bits, 0), np.where(live, flags, 0)
        after = self.faulted & (self.faults.onset <= k * self.ts)
        self.alarms += (bits != 0) & ~after
        fault = ((bits & pl.PLAUS_FAULT) != 0) | ((flags & pl.OUTSIDE_MODEL) != 0)  # the report
        first = fault & ~self.reported
        self.reported |= fault
        self.report_step = np.where(first, k, self.report_step)
        braking = False
        if self.speed_faulted:  # only a speed's bound widens while the car brakes
            braking = False if self.v_prev is None else is_braking(self.v_prev, v_true, self.ts, self.cfg)
            self.v_prev = v_true.copy()
        bound = np.full(error.shape, np.inf)
        seen = error
        for channel, on in self.channels.items():
            bound = np.where(on, sensor_bound(channel, self.cfg, r_true, v_true, True, speed_pair=True,
                                              braking=braking), bound)
            seen = np.where(on, error + check_offset(channel, self.bias, v_true, after), seen)
        over = np.abs(seen) > bound
        self.tracker.step(k, over if live is None else over & live, first, ending)

    def result(self) -> dict[str, np.ndarray]:
        ex, rep, ts = self.tracker.exceeded, self.report_step, self.ts
        late = np.where(rep < 0, np.inf, np.maximum(0.0, rep * ts - ex * ts))
        return {"false_alarms": self.alarms,
                "detection_time": np.where(~self.faulted, np.nan, np.where(ex < 0, 0.0, late))}
