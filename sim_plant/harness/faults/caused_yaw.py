"""The yaw rate a sensor row's command made the car turn at (issue 18's "the yaw rate its own
command causes stays below 0.05 rad/s"), from the plant's trace.

What the faulty sensor's command is measured against: anything between what the healthy
controller would hold and the safe state is not caused by the fault. The healthy controller's
value is the applied angle at the onset, where the row starts in a steady state
(``STEADY_MOVE``). The safe state is zero: fading out a command that was rejecting paper-fig9's 4000 Nm lets
the car yaw at 0.2 rad/s, but that is the car without the controller, not the fault. The
command's *excursion* is the applied angle's distance outside [min(0, a0), max(0, a0)]. The
figure is the peak yaw rate the excursion gives the linear car. That car is the plant's own
(eqs. 14/16, exact ZOH at the plant's step, the trace's speed and friction at the onset, the
scenario's mass), and the figure is exact for it by superposition.

The matrix reports this figure and does not judge it, because the target is not met for a yaw
rate stuck while the car is not turning: docs/controller.md, "What the 50 ms redundant frame
allows".
"""

from __future__ import annotations

import bisect

from sim_plant.car import scenario
from sim_plant.car.vehicle import DiscretePlant, VehicleParams
from sim_plant.harness.faults.evidence import Evidence
from sim_plant.harness.faults.settings import CURVE, CURVE_SCENARIO

#: Issue 18's bound on the yaw rate a faulty sensor's command may cause, rad/s.
CAUSED_YAW_TARGET = 0.05
#: The onset counts as a steady state when the applied angle moved less than this in the
#: ``STEADY_TIME`` before it (rad, 0.25 deg). The held value then stands for the healthy
#: controller's. Measured on the baselines' traces from the sensor rows' onset (1.0 s): they moved
#: 0.03 deg (paper-fig9) and 0.19 deg (the curve, still settling), and the figure on them is
#: 0.0004 and 0.008 rad/s. The frozen row starts in the yaw moment's transient and gets none.
STEADY_MOVE = 4.4e-3
STEADY_TIME = 0.1


def caused_yaw(e: Evidence, start: float) -> float | None:
    """The largest |r| the applied angle's excursion (the module's docstring) from ``start``
    (epoch s, the fault's onset on the trace's wall clock) to the run's end gives the linear
    car.  ``None`` when the applied angle was still moving before the onset, because the healthy
    command is then unknown (the frozen row starts in the yaw moment's transient); also ``None``
    when the trace has no step after ``start`` or no speed and friction columns."""
    tr, cols = e.trace, e.trace.columns
    i0 = bisect.bisect_left(tr.wall, start)
    if i0 >= len(tr.t) - 1 or "v_m_s" not in cols or "mu" not in cols:
        return None
    before = [a for t, a in zip(tr.t[:i0 + 1], tr.applied[:i0 + 1]) if t >= tr.t[i0] - STEADY_TIME]
    if max(before) - min(before) > STEADY_MOVE:
        return None
    sc = CURVE_SCENARIO if e.row.scenario == CURVE else scenario.load(e.row.scenario)
    car = DiscretePlant(VehicleParams(v=cols["v_m_s"][i0], mu=cols["mu"][i0], mass=sc.mass), tr.t[i0 + 1] - tr.t[i0])
    a0, peak = tr.applied[i0], 0.0
    low, high = min(0.0, a0), max(0.0, a0)
    for a in tr.applied[i0:]:
        car.advance(a - min(max(a, low), high), 0.0)
        peak = max(peak, abs(float(car.x[1])))
    return peak
