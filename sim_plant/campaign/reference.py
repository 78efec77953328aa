"""The scalar reference of the batch engine: one scenario in closed loop with the firmware's own
``step()``, built from the product's scalar classes only.

``run`` is the lockstep plant node's step (``sim_plant.nodes.plant.PlantNode.step``, one step of
loop delay) with the bus taken out: ``scenario.ScenarioState`` (events, loads, the driver
model), ``plants.Car`` (the nonlinear car), ``actuator.Actuator`` (the command handling) and
``actuator_dynamics.PositionActuator``, ``sensors.Sensors``, and
``model_regulator.ModelRegulator``.  The batch engine must equal it (the test of
``tests/test_campaign_engine.py``), and ``mrsteer bench --only campaign`` times it as the
scalar firmware loop the engine is measured against.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass

import numpy as np

from firmware_py import model_regulator as mr
from sim_plant.car import scenario as scn
from sim_plant.car.actuator import Actuator, ActuatorConfig
from sim_plant.car.actuator_dynamics import PositionActuator
from sim_plant.car.plants import Car
from sim_plant.car.sensors import Sensors


@dataclass(frozen=True)
class ReferenceRun:
    """Per step: the true yaw rate and side slip at the step's start, and the command."""

    r: np.ndarray
    beta: np.ndarray
    command: np.ndarray
    status: np.ndarray
    final_speed: float


def run(sc: scn.Scenario, config: mr.ControllerConfig | None, ts: float = 0.002) -> ReferenceRun:
    """Play ``sc`` with the controller ``config`` (None: none) in the loop, step by step."""
    scene = scn.ScenarioState(sc)
    car = Car(sc.plant, scene.params(), ts)
    position = PositionActuator(sc.actuator, ts)
    sensors = Sensors(sc.sensors, ts)
    handling = Actuator(ActuatorConfig(), ts)
    ctrl = mr.ModelRegulator(config) if config is not None else None
    pipeline: collections.deque[float] = collections.deque([0.0])
    n = int(round(sc.duration / ts)) + 1
    r_hist, beta_hist, u_hist, status = np.empty(n), np.empty(n), np.empty(n), np.empty(n, dtype=np.int8)
    for k in range(n):
        t = k * ts
        if scene.advance_to(t):
            car.set_params(scene.params())
        car.set_loads(scene.loads(t))
        m_z = scene.m_z
        x = car.x
        driver = scene.driver_angle(t, float(x[1]), ts)
        handling.apply(pipeline.popleft())
        yaw = sensors.yaw_rate(float(x[1]))
        steer, speed = sensors.steer(driver), sensors.speed(scene.v)
        u = ctrl.step(steer, yaw, speed) if ctrl is not None else 0.0
        pipeline.append(u)
        handling.command_received()  # lockstep: the answer arrived
        # The controller's status as a clean monitor sends it: every check running, none tripped
        # (the actuator's authority limit then bounds only size and rate; the batch engine has
        # neither the monitor nor this second limit yet: docs/campaigns.md).
        handling.status_received(0)
        handling.tick()
        position.step(handling.applied)
        r_hist[k], beta_hist[k], u_hist[k] = x[1], x[0], u
        status[k] = ctrl.state.status if ctrl is not None else mr.STATUS_INACTIVE
        car.advance(driver + position.mean, m_z)  # PlantNode.step: the position's mean over the step
        scene.v = car.v
    return ReferenceRun(r_hist, beta_hist, u_hist, status, car.v)
