"""The yaw rate a faulty sensor's command caused (issue 18's "the yaw rate its own command causes
stays below 0.05 rad/s", ``CAUSED_YAW_TARGET``), replayed on the run's own car from what its trace
recorded: the fault matrix's ``caused_yaw``, ``hil run``'s ``caused_yaw_rad_s``, the campaigns'
``fault_yaw_rate`` (their engine steps the same replay beside each row: ``kept``) and the offline
runs' ``MonitorRun.caused_yaw`` all take it from here.

The *excursion* of an applied front-wheel angle ``a`` is its distance outside the range from
the healthy controller's angle ``h`` to zero, the safe state: ``a - clamp(a, min(0, h),
max(0, h))``. Fading toward zero, or backing off to anywhere between, is not counted. ``h`` is
the angle held at the onset where the run is in a steady state there (the fault matrix's rows),
or, per step, what a fault-free twin of the run applied (``hil run``: the healthy controller's
answer to whatever else happens after the onset, a disturbance or the driver, is then not
counted either).

The figure is the peak over the run of |r - r'|, where r is the car's yaw rate under the
applied angles and r' under the same angles without their excursion, both from the state at
the onset with the same driver angle, yaw moment, friction and loads. Where the run's driver
corrects the yaw rate (the scenario's driver model, ``ScenarioState.correction_gain``), the replay
without the excursion has that driver correct its own car: its angle is the recorded one plus the
correction the difference r' - r would have added since the onset (``driver_gain``; clamped as the
driver's, on the recorded angle: the driver model clamps its whole integral, which differs only
while the recorded angle sits at the clamp). Replayed open-loop, the recorded corrections (made for
the car that had the excursion) would drive the other car off by themselves: on a low-mu road under
a yaw moment, into a spin that no command caused.

* the paper's linear car (eqs. 14/16, exact ZOH): by superposition r - r' is the car's
  response to the excursion alone from rest (less the driver's correction of the difference),
  computed so; exact for that car.
* the nonlinear car (``sim_plant.car.nonlinear``, magic-formula tyres): the two runs, each from
  the onset's side slip, yaw rate and speed, with the side force, deceleration and grip of each
  step when given (``loads``; a trace records only the yaw moment). Near the grip limit the
  tyres' slope is lower than at zero slip, and the figure is then below the linear car's for
  the same excursion.

The angles are held over each step as the trace records them. With an actuator of its own
dynamics (``sim_plant.car.actuator_dynamics``) the trace's angle is its position at the end of
the step and the plant drove the car with the step's mean, half a step (1 ms at 500 Hz) later
than this replay; the actuator's lag itself is in the recorded angles.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim_plant.car.disturbances import Loads
from sim_plant.car.nonlinear import NonlinearPlant
from sim_plant.car.plants import LINEAR, NONLINEAR, PLANTS
from sim_plant.car.scenario_play import DRIVER_LIMIT
from sim_plant.car.vehicle import DiscretePlant, VehicleParams


#: Issue 18's bound on the yaw rate a faulty sensor's command may cause, rad/s (met at or below
#: it, as a campaign's criteria are).
CAUSED_YAW_TARGET = 0.05
#: Where no fault-free twin gives the healthy controller's angle (the fault matrix), the angle
#: held at the onset stands for it when it moved less than this in the ``STEADY_TIME`` before
#: (rad, 0.5 deg). Measured on the matrix's baselines' traces from the sensor rows' onset (1.0 s),
#: they moved 0.03 deg (paper-fig9) and 0.19 deg (the curve, still settling), and the figure
#: there, the floor of a fault-free run, is 0.0004 and 0.00001 rad/s. The frozen row starts in
#: the yaw moment's transient (degrees in 0.1 s) and gets none.
STEADY_MOVE = 8.7e-3
STEADY_TIME = 0.1


def kept(a: float | np.ndarray, h: float | np.ndarray) -> float | np.ndarray:
    """The applied angle ``a`` clamped to [min(0, h), max(0, h)] (rad): what of it the healthy
    controller's ``h`` or the safe state explains (floats, or arrays of rows)."""
    if np.ndim(a) == 0 and np.ndim(h) == 0:
        return min(max(a, min(0.0, h)), max(0.0, h))
    return np.clip(a, np.minimum(h, 0.0), np.maximum(h, 0.0))


def excursion(a: float | np.ndarray, h: float | np.ndarray) -> float | np.ndarray:
    """The part of the applied angle ``a`` outside [min(0, h), max(0, h)] (rad)."""
    return a - kept(a, h)


def steady(before: Sequence[float] | np.ndarray) -> bool:
    """Whether the applied angles of the ``STEADY_TIME`` up to the onset moved less than
    ``STEADY_MOVE``: the angle held there then stands for the healthy controller's."""
    return bool(len(before)) and max(before) - min(before) <= STEADY_MOVE


def onset_step(t: Sequence[float] | np.ndarray, onset: float) -> int | None:
    """The first step of ``t`` (s, the run's own clock) at or after ``onset`` (1 ns of rounding
    allowed: k ts may fall short of an onset on the step grid); None past the run's end."""
    k = int(np.searchsorted(np.asarray(t, dtype=float), onset - 1e-9, side="left"))
    return k if k < len(t) else None


def excursion_yaw(applied: Sequence[float], ts: float, car: VehicleParams, kind: str = LINEAR,
                  driver: Sequence[float] | None = None, m_z: Sequence[float] | None = None,
                  beta0: float = 0.0, r0: float = 0.0, *, healthy: Sequence[float] | None = None,
                  mu: Sequence[float] | None = None, loads: Sequence[Loads] | None = None,
                  driver_gain: Sequence[float] | None = None) -> float:
    """The peak |r - r'| (rad/s; the module's docstring) over ``applied``, the angles applied
    from the onset's step on, each held over one step of ``ts`` s, on the car ``kind``
    (``sim_plant.car.plants.PLANTS``) at ``car``'s speed and friction. ``healthy`` is the
    healthy controller's angle of each step (default: ``applied[0]``, the one held at the
    onset); ``mu`` the road's friction of each step (default ``car.mu`` throughout). The
    nonlinear car also needs the driver's front-wheel angle and the yaw moment of each step
    (``driver``, ``m_z``), the onset's state (``beta0``, ``r0``) and, where they act, the loads
    of each step (their side force, deceleration and grip; their yaw moment is ``m_z``'s).
    ``driver_gain``: how far the driver's correction moves in each step per rad/s of the yaw
    rate's difference (``ScenarioState.correction_gain``; default none: a driver who does not
    correct). Every sequence has ``applied``'s length. The linear car's figure depends only on
    the angles, the friction, the driver's gains and the car."""
    if kind not in PLANTS:
        raise ValueError(f"plant must be one of {', '.join(PLANTS)}, got {kind!r}")
    n = len(applied)
    for name, seq in (("healthy", healthy), ("mu", mu), ("loads", loads), ("driver_gain", driver_gain)):
        if seq is not None and len(seq) != n:
            raise ValueError(f"{name} has {len(seq)} steps, the applied angles {n}")
    if not n:
        return 0.0
    held = healthy if healthy is not None else [applied[0]] * n
    road = mu if mu is not None else [car.mu] * n
    gains = driver_gain if driver_gain is not None else [0.0] * n
    peak = 0.0
    correction = 0.0  # what the driver without the excursion has added to the recorded angle
    if kind == LINEAR:
        plant = DiscretePlant(car, ts)  # r - r' from rest: the excursion less the correction
        for a, h, m, g in zip(applied, held, road, gains):
            if m != plant.params.mu:
                plant.set_params(plant.params.at(mu=m))
            correction += g * float(plant.x[1])  # (r' - r = -(r - r'))
            plant.advance(excursion(a, h) - correction, 0.0)
            peak = max(peak, abs(float(plant.x[1])))
        return peak
    assert kind == NONLINEAR
    if driver is None or m_z is None or not len(driver) == len(m_z) == n:
        raise ValueError("the nonlinear car's replay needs the driver angle and the yaw moment of every step")
    actual, without = NonlinearPlant(car, ts), NonlinearPlant(car, ts)
    for plant in (actual, without):
        plant.set_state(beta0, r0, driver[0] + applied[0])
    for k, (a, h, d, m) in enumerate(zip(applied, held, driver, m_z)):
        correction -= gains[k] * float(without.x[1] - actual.x[1])
        d_without = max(-DRIVER_LIMIT, min(DRIVER_LIMIT, d + correction)) if correction else d
        load = loads[k] if loads is not None else None
        for plant in (actual, without):
            if road[k] != plant.params.mu:
                plant.set_params(plant.params.at(mu=road[k]), keep_speed=True)
            if load is not None:
                plant.set_grip(load.grip)
        f_y, a_x = (load.f_y, load.a_x) if load is not None else (0.0, 0.0)
        actual.advance(d + a, m, f_y, a_x)
        without.advance(d_without + a - excursion(a, h), m, f_y, a_x)
        peak = max(peak, abs(float(actual.x[1] - without.x[1])))
    return peak
