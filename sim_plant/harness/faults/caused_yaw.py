"""The yaw rate a sensor row's command made the car turn at (issue 18's "the yaw rate its own
command causes stays below 0.05 rad/s"), from the plant's trace.

What the faulty sensor's command is measured against: anything between what the healthy
controller would hold and the safe state is not counted. The healthy controller's value is the
applied angle at the onset, where the row starts in a steady state (``judge.caused_yaw.steady``).
The safe state is zero: fading out a command that was rejecting paper-fig9's 4000 Nm lets the car yaw at
0.2 rad/s, but that is the car without the controller, not the fault. The same holds when the
faulty controller backs off toward zero before its report, which it is allowed to do at any
time.

The command's *excursion* is the applied angle's distance outside [min(0, a0), max(0, a0)].
The figure is the peak yaw rate the excursion gives the run's own car
(``sim_plant.judge.caused_yaw``): the plant's car (the paper's linear one, eqs. 14/16,
exact by superposition; or the nonlinear one, replayed with and without the excursion from the
trace's side slip and yaw rate at the onset) at the plant's step, the trace's speed at the onset
and friction at each step, the scenario's mass, the trace's driver angle and yaw moment (the
sensor rows' only loads: the matrix's scenarios carry no side force, braking or grip change,
``settings.scenario_toml`` refuses them). The trace's applied angle is the actuator's position, so an actuator with
its own dynamics is in it.

A campaign's ``fault_yaw_rate`` is this figure against its fault-free twin's angle at each step,
as ``hil run``'s; its ``twin_yaw_rate``, |r − r of the fault-free twin|, counts the fade and any
backing-off as well (docs/campaigns.md), even on a straight road: the fade of the little the twin
holds against the sensors' bias and noise. The matrix judges the figure on every sensor row at
every rate against ``judge.caused_yaw.CAUSED_YAW_TARGET`` (``verdicts_plausibility.judge_caused_yaw``;
docs/faults.md, "The sensor rows").
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

from sim_plant.car.plants import LINEAR
from sim_plant.car.vehicle import VehicleParams
from sim_plant.harness.faults.evidence import Evidence
from sim_plant.harness.faults.settings import row_scenario
from sim_plant.judge.caused_yaw import STEADY_TIME, excursion_yaw, steady


@dataclass(frozen=True)
class CausedYaw:
    """The figure (rad/s), or ``None`` with the reason there is none."""

    value: float | None
    reason: str = ""


def caused_yaw(e: Evidence, start: float) -> CausedYaw:
    """The largest |r| the applied angle's excursion (the module's docstring) from ``start``
    (epoch s, the fault's onset on the trace's wall clock) to the run's end gives the run's
    car, or why there is none."""
    setup = e.setup
    sc = row_scenario(e.row.scenario)
    kind = setup.plant or sc.plant
    tr, cols = e.trace, e.trace.columns
    needs = ("v_m_s", "mu") if kind == LINEAR else ("v_m_s", "mu", "beta_rad", "yaw_rate_rad_s",
                                                    "driver_angle_rad", "m_z_nm")
    if any(name not in cols for name in needs):
        return CausedYaw(None, f"the plant's trace has no {', '.join(n for n in needs if n not in cols)}")
    # The last step at or before the onset: a bridge fault's first falsified frame is stamped
    # after the step that sent it, and the step after may already apply the answer to it.
    i0 = bisect.bisect_right(tr.wall, start) - 1
    if i0 < 0 or i0 >= len(tr.t) - 1:
        return CausedYaw(None, "the plant's trace does not span the onset")
    before = tr.applied[bisect.bisect_left(tr.t, tr.t[i0] - STEADY_TIME, hi=i0 + 1):i0 + 1]
    if not steady(before):
        return CausedYaw(None, "the command was moving at the onset")
    car = VehicleParams(v=cols["v_m_s"][i0], mu=cols["mu"][i0], mass=sc.mass)
    ts = tr.t[i0 + 1] - tr.t[i0]
    mu = cols["mu"][i0:]
    if kind == LINEAR:
        return CausedYaw(excursion_yaw(tr.applied[i0:], ts, car, mu=mu))
    return CausedYaw(excursion_yaw(tr.applied[i0:], ts, car, kind, cols["driver_angle_rad"][i0:], cols["m_z_nm"][i0:],
                                   cols["beta_rad"][i0], cols["yaw_rate_rad_s"][i0], mu=mu))
