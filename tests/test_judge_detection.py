"""When a sensor fault's error left its bound (``sim_plant.judge.detection``), on small runs
whose answers are counted by hand."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_py import plausibility as pl
from sim_plant.judge.detection import ExceededTracker, FaultFigures, exceeded_at, exceeded_time

T = np.arange(10) * 0.1  # ten periods of 0.1 s: a hold of 0.3 s is three periods
OVER = np.array([0, 2, 2, 0, 2, 2, 2, 2, 0, 0], dtype=float)  # against a bound of 1


def test_a_stretch_counts_once_it_lasts_the_hold() -> None:
    assert exceeded_time(T, OVER, 1.0, None, hold=0.3) == pytest.approx(0.4)  # steps 1-2 are too short
    assert exceeded_time(T, -OVER, 1.0, None, hold=0.3) == pytest.approx(0.4)  # |error|
    assert exceeded_time(T, OVER, 2.0, None, hold=0.3) is None  # never over (2 is not beyond 2)


def test_a_report_or_the_runs_end_cuts_the_hold_short() -> None:
    assert exceeded_time(T, OVER, 1.0, 0.2, hold=0.3) == pytest.approx(0.1)  # over until the report
    assert exceeded_time(T, OVER, 1.0, 0.3, hold=0.3) == pytest.approx(0.4)  # back within at the report
    late = np.array([0] * 8 + [2, 2], dtype=float)
    assert exceeded_time(T, late, 1.0, None, hold=0.3) == pytest.approx(0.8)  # to the run's end
    bound = np.array([1.0] * 5 + [3.0] * 5)  # a bound per period
    assert exceeded_time(T, OVER, bound, None, hold=0.3) is None


def test_the_tracker_follows_each_row_of_a_batch() -> None:
    tracker = ExceededTracker(3, need=3, last=9)
    rows = np.stack([OVER, np.roll(OVER, 2), np.zeros(10)], axis=1) > 1.0
    report = np.zeros((10, 3), dtype=bool)
    report[4, 1] = True  # row 1 (over at 3-4 and 6-9) is reported at step 4: its stretch 3-4 counts
    for k in range(10):
        tracker.step(k, rows[k], report[k])
    assert tracker.exceeded.tolist() == [4, 3, -1]
    unreported = ExceededTracker(1, need=3, last=9)
    for k in range(10):
        unreported.step(k, rows[k, 1:2], np.zeros(1, dtype=bool))
    assert unreported.exceeded.tolist() == [6]


def test_the_frames_own_times_count_the_hold_in_time() -> None:
    series = [(0.0, 0.0, 1.0), (0.1, 2.0, 1.0), (0.2, 2.0, 1.0), (0.3, 2.0, 1.0), (0.4, 2.0, 1.0)]
    assert exceeded_at(series, None, hold=0.3) == pytest.approx(0.1)
    assert exceeded_at(series[:4], None, hold=0.3) is None  # 0.2 s over, and no report
    assert exceeded_at(series[:4], 0.25, hold=0.3) == pytest.approx(0.1)  # over until the report
    assert exceeded_at(series, 0.05, hold=0.3) is None  # reported before it left the bound


class _Rows:
    """Two rows: a steering channel's fault from 0.2 s, and none."""

    onset = np.array([0.2, 0.0])
    sensor = np.array([1, 0])
    rows = {"steer": np.array([True, False])}


@pytest.mark.parametrize("block", [1, 64, 400], ids=("step by step", "in blocks", "at once"))
def test_fault_figures_count_alarms_before_the_onset_and_the_detection_from_the_bound(block: int) -> None:
    ts, n = 0.002, 400
    cfg = pl.PlausibilityConfig(ts=ts)
    judge = FaultFigures(_Rows(), n, ts)
    k = np.arange(n)
    error = np.stack([np.where(k >= 120, 2.0 * cfg.steer_bound, 0.0), np.zeros(n)], axis=1)  # over from step 120
    bits = np.stack([np.where(k == 50, pl.PLAUS_DEGRADED, np.where(k >= 180, pl.PLAUS_STEER, 0)),
                     np.where(k == 7, pl.PLAUS_DEGRADED, 0)], axis=1)
    for k0 in range(0, n, block):
        s = slice(k0, k0 + block)
        if block == 1:
            judge.step(k0, error[k0], bits[k0], np.zeros(2), np.full(2, 20.0))
        else:
            judge.steps(k0, error[s], bits[s], np.zeros((bits[s].shape[0], 2)), np.full((bits[s].shape[0], 2), 20.0))
    figures = judge.result()
    assert figures["false_alarms"].tolist() == [1, 1]  # step 50 (a DEGRADED: no report); the other row's 7
    assert figures["detection_time"][0] == pytest.approx((180 - 120) * ts)
    assert np.isnan(figures["detection_time"][1])
