"""The yaw rate a sensor row's command made the car turn at (issue 18's "the yaw rate its own
command causes stays below 0.05 rad/s"), from the plant's trace.

The matrix's scenarios run the paper's linear car (eqs. 14/16), in their steady state when a
sensor fault starts. By superposition, the yaw rate the command *changed* since the onset
causes is the car's response to the applied auxiliary angle less its value at the onset. That
response is the same single-track model, exact ZOH at the plant's step, at the trace's speed and
friction at the onset and the scenario's mass. The figure assumes the fault-free command would
have held its onset value. With the wheel held in a steady state it nearly does; the baseline
rows give less than 0.002 rad/s (tests/test_fault_matrix_plausibility.py). The matrix reports
the figure and does not judge it: a stuck yaw rate breaks the target (docs/controller.md,
"What the 50 ms redundant frame allows").
"""

from __future__ import annotations

import bisect

from sim_plant.car import scenario
from sim_plant.car.vehicle import DiscretePlant, VehicleParams
from sim_plant.harness.faults.evidence import Evidence
from sim_plant.harness.faults.settings import CURVE, CURVE_SCENARIO

#: Issue 18's bound on the yaw rate a faulty sensor's command may cause, rad/s.
CAUSED_YAW_TARGET = 0.05


def caused_yaw(e: Evidence, start: float) -> float | None:
    """The largest |r| the applied angle's change since ``start`` (epoch s, the fault's onset
    on the trace's wall clock) gives the linear car, to the run's end; ``None`` when the trace
    has no step at or after ``start``, or no speed and friction columns."""
    tr, cols = e.trace, e.trace.columns
    i0 = bisect.bisect_left(tr.wall, start)
    if i0 >= len(tr.t) - 1 or "v_m_s" not in cols or "mu" not in cols:
        return None
    sc = CURVE_SCENARIO if e.row.scenario == CURVE else scenario.load(e.row.scenario)
    car = DiscretePlant(VehicleParams(v=cols["v_m_s"][i0], mu=cols["mu"][i0], mass=sc.mass), tr.t[i0 + 1] - tr.t[i0])
    a0, peak = tr.applied[i0], 0.0
    for a in tr.applied[i0:]:
        car.advance(a - a0, 0.0)
        peak = max(peak, abs(float(car.x[1])))
    return peak
