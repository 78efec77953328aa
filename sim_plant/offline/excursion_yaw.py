"""The yaw rate a command's excursion made the car turn at (issue 18's "the yaw rate its own
command causes"), replayed on the run's own car from what its trace recorded.

The *excursion* of an applied front-wheel angle ``a`` is its distance outside the range from
the angle held at the onset ``a0`` (the healthy controller's, in a steady state) to zero, the
safe state: ``a - clamp(a, min(0, a0), max(0, a0))``. Fading toward zero, or backing off to
anywhere between, is not counted.

The figure is the peak over the run of |r - r'|, where r is the car's yaw rate under the
applied angles and r' under the same angles without their excursion, both from the state at
the onset with the same driver angle and yaw moment:

* the paper's linear car (eqs. 14/16, exact ZOH): by superposition r - r' is the car's
  response to the excursion alone from rest, computed so; exact for that car.
* the nonlinear car (``sim_plant.car.nonlinear``, magic-formula tyres): the two runs, each from
  the onset's side slip, yaw rate and speed. Near the grip limit the tyres' slope is lower than
  at zero slip, and the figure is then below the linear car's for the same excursion. Only the
  loads a trace records are replayed (the yaw moment): a side force, a braking deceleration or a
  changed grip is not, so on a car with one of those acting the figure is the car's answer
  without it (``excursion_yaw``'s callers say so).

The angles are held over each step as the trace records them. With an actuator of its own
dynamics (``sim_plant.car.actuator_dynamics``) the trace's angle is its position at the end of
the step and the plant drove the car with the step's mean, half a step (1 ms at 500 Hz) later
than this replay; the actuator's lag itself is in the recorded angles.
"""

from __future__ import annotations

from collections.abc import Sequence

from sim_plant.car.nonlinear import NonlinearPlant
from sim_plant.car.plants import LINEAR, NONLINEAR, PLANTS
from sim_plant.car.vehicle import DiscretePlant, VehicleParams


def excursion(a: float, a0: float) -> float:
    """The part of the applied angle ``a`` outside [min(0, a0), max(0, a0)] (rad)."""
    return a - min(max(a, min(0.0, a0)), max(0.0, a0))


def excursion_yaw(applied: Sequence[float], ts: float, car: VehicleParams, kind: str = LINEAR,
                  driver: Sequence[float] | None = None, m_z: Sequence[float] | None = None,
                  beta0: float = 0.0, r0: float = 0.0) -> float:
    """The peak |r - r'| (rad/s; the module's docstring) over ``applied``, the angles applied
    from the onset's step on (``applied[0]`` is the held one), each held over one step of
    ``ts`` s, on the car ``kind`` (``sim_plant.car.plants.PLANTS``) at ``car``'s speed and
    friction. The nonlinear car also needs the driver's front-wheel angle and the yaw moment of
    each step (``driver``, ``m_z``; the same lengths as ``applied``) and the onset's state
    (``beta0``, ``r0``); the linear car's figure depends on none of them."""
    if kind not in PLANTS:
        raise ValueError(f"plant must be one of {', '.join(PLANTS)}, got {kind!r}")
    if not applied:
        return 0.0
    a0, peak = applied[0], 0.0
    if kind == LINEAR:
        plant = DiscretePlant(car, ts)
        for a in applied:
            plant.advance(excursion(a, a0), 0.0)
            peak = max(peak, abs(float(plant.x[1])))
        return peak
    assert kind == NONLINEAR
    if driver is None or m_z is None or not len(driver) == len(m_z) == len(applied):
        raise ValueError("the nonlinear car's replay needs the driver angle and the yaw moment of every step")
    actual, without = NonlinearPlant(car, ts), NonlinearPlant(car, ts)
    for plant in (actual, without):
        plant.set_state(beta0, r0, driver[0] + a0)
    for a, d, m in zip(applied, driver, m_z):
        actual.advance(d + a, m)
        without.advance(d + a - excursion(a, a0), m)
        peak = max(peak, abs(float(actual.x[1] - without.x[1])))
    return peak
