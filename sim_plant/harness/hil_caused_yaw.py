"""The yaw rate a HIL run's command caused (issue 18: "the yaw rate its own command causes stays
below 0.05 rad/s"), for a run with a sensor fault: ``caused_yaw_rad_s`` in ``summary.json``'s
``plausibility`` entry, and the words of ``hil run``'s plausibility line.

What the faulty command is measured against is the healthy controller's angle at each step,
taken from a *fault-free twin* of the run: the same scenario, car, actuator, sensors (the same
seed and, with the faults kept dormant, the same noise streams) and calibration without the
sensor fault, played offline
(``offline.plausibility_runs.run``, the plant node's step and the controller's cycle side by
side, with the bus's one-step delay). Only the excursion of the run's applied angle beyond the
twin's or beyond zero counts (``judge.caused_yaw``): the healthy controller's answer to a
disturbance or to the driver after the onset is not the fault's, and neither is a fade to zero
(fading out a command that rejects a disturbance lets the car yaw, but that is the car without
the controller, issue 18's safe state). The excursion is replayed on the run's car from its
state at the onset, with the scenario's loads (side force, braking, grip) at each step, and
with the scenario's driver model correcting the car without the excursion for its own yaw rate
(``driver_gains``; a driver who holds the wheel corrects nothing). A campaign's
``fault_yaw_rate`` is the same figure (docs/campaigns.md, "[criteria]").

Before the onset the twin and the run are the same run; their largest difference there is the
figure's floor (``caused_yaw_twin_mismatch_deg``: the bus carries the measurements quantised to
their DBC resolution, the twin does not; about 0.01 deg in a fast transient). A twin further than
``TWIN_TOLERANCE`` from the run before the onset is no twin, and the run gets no figure (a run
the bus disturbed). That check sees something only where the command moved before the onset by
more than the tolerance; otherwise the note says the twin is unchecked. A controller program
other than the shipped Python or C node (``--controller-cmd``) gets no figure: the twin is the
shipped firmware. The twin's second yaw-rate element is a copy of the first (``plausibility_runs``
models no element of its own), so its pair check sees no difference where the run's may see the
elements' noise; only the twin's monitor sees it. The twin needs lockstep (in realtime the
commands meet the steps by wall clock) and the one-step delay ``run`` models."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from firmware_py import model_regulator as mr
from sim_plant.car import scenario as scn
from sim_plant.car.scenario_play import ScenarioState
from sim_plant.car.sensors import dormant_faults
from sim_plant.car.vehicle import VehicleParams
from sim_plant.harness.hil_steps import Step
from sim_plant.offline import plausibility_runs
from sim_plant.judge.caused_yaw import excursion_yaw, onset_step

#: The twin may differ from the run before the onset by at most this (rad, 0.05 deg: five times
#: the bus's quantisation differences measured in a 3 deg transient).
TWIN_TOLERANCE = math.radians(0.05)


def caused_yaw_figures(steps: list[Step], sc: scn.Scenario, ctrl: mr.ControllerConfig, rate_hz: float, *,
                       lockstep: bool = True, delay_steps: int = 1, controller: bool = True,
                       shipped: bool = True) -> dict[str, Any]:
    """``caused_yaw_rad_s`` (None with ``caused_yaw_note`` saying why) and the twin's mismatch
    before the onset, for the run's ``steps`` (``hil_steps.step_table``) of scenario ``sc`` (its
    sensor faults, the scenario's and its sensor models', included) under the calibration
    ``ctrl``; ``shipped`` False for a controller program that is neither the Python nor the C
    node (``--controller-cmd``), which the twin is not."""
    def none(why: str) -> dict[str, Any]:
        return {"caused_yaw_rad_s": None, "caused_yaw_note": why, "caused_yaw_twin_mismatch_deg": None}

    faults = sc.sensor_config.faults
    if not faults:
        return none("no sensor fault")
    if not controller:
        return none("no controller: no command")
    if not shipped:
        return none("another controller program than the shipped Python or C node: the twin is the shipped one")
    if not lockstep:
        return none("a realtime run: the fault-free twin is a lockstep run")
    if delay_steps != 1:
        return none(f"the fault-free twin has the bus's one-step delay, the run {delay_steps}")
    onset = min(f.start for f in faults)
    k0 = onset_step([s.t_s for s in steps], onset)
    if k0 is None or k0 + 1 >= len(steps):
        return none("the run ends at the fault's onset")
    # The faults kept but dormant: the twin's sensors draw from the run's noise streams.
    healthy_sc = replace(sc.without_sensor_faults(), sensors=dormant_faults(sc.sensor_config))
    config = healthy_sc.sensor_config
    twin = plausibility_runs.run(healthy_sc, 1.0 / rate_hz, controller=ctrl,
                                 second_yaw=config if config.yaw_rate_redundant_present else None,
                                 second_speed=config.speed_redundant_present)
    n = min(len(steps), len(twin.aux))
    healthy = [float(x) for x in twin.aux[:n]]
    mismatch = max((abs(steps[i].aux_applied_rad - healthy[i]) for i in range(min(k0, n))), default=0.0)
    if mismatch > TWIN_TOLERANCE:
        return none(f"the fault-free twin differs from the run by {math.degrees(mismatch):.3f} deg before the onset "
                    "(another controller?)")
    # A command that did not move before the onset tests the twin against nothing there.
    before = healthy[:min(k0, n)]
    checked = bool(before) and max(before) - min(before) > TWIN_TOLERANCE
    run = steps[k0:n]
    scene = ScenarioState(sc)
    car = VehicleParams(v=run[0].v_m_s, mu=run[0].mu, mass=sc.mass)
    figure = excursion_yaw([s.aux_applied_rad for s in run], 1.0 / rate_hz, car, sc.plant,
                           [s.driver_angle_rad for s in run], [s.m_z_nm for s in run], run[0].beta_rad,
                           run[0].yaw_rate_rad_s, healthy=healthy[k0:n], mu=[s.mu for s in run],
                           loads=[scene.loads(s.t_s) for s in run],
                           driver_gain=driver_gains(scene, run, 1.0 / rate_hz))
    return {"caused_yaw_rad_s": figure,
            "caused_yaw_note": f"the excursion beyond a fault-free twin's command, replayed on the {sc.plant} car"
                               + ("" if checked else " (the twin unchecked: the command did not move before the onset)"),
            "caused_yaw_twin_mismatch_deg": math.degrees(mismatch)}


def driver_gains(scene: ScenarioState, steps: list[Step], ts: float) -> list[float]:
    """Each step's ``ScenarioState.correction_gain`` (the scenario's events played up to it, at
    the trace's speed): how the driver model corrects a replayed car (``excursion_yaw``)."""
    gains = []
    for s in steps:
        scene.advance_to(s.t_s)
        scene.v = s.v_m_s
        gains.append(scene.correction_gain(s.t_s, ts))
    return gains
