"""Plays a scenario (``scenario.Scenario``) step by step: its events, the disturbances' loads
and the driver model, as the plant node, the offline loops and the campaign's reference run
them."""

from __future__ import annotations

import math

from sim_plant.car import disturbances as dist
from sim_plant.car.scenario import Scenario
from sim_plant.car.vehicle import VehicleParams, steering_tf

#: The driver's front-wheel angle stays within this, rad (``ScenarioState.driver_angle``).
DRIVER_LIMIT = 0.6


class ScenarioState:
    """Plays a scenario: what the road, the car and the driver do at time t."""

    def __init__(self, sc: Scenario) -> None:
        self.sc = sc
        self._next = 0
        self.v = sc.v
        self.mu = sc.mu
        self.m_z = 0.0
        self.steer_intent = 0.0
        self.panic_until = -math.inf
        self.correction = 0.0
        self._loads = sc.disturbances

    def params(self) -> VehicleParams:
        return VehicleParams(v=self.v, mu=self.mu, mass=self.sc.mass)

    def advance_to(self, t: float) -> bool:
        """Apply the events due by t; True if the operating point (v, mu) changed."""
        changed = False
        events = self.sc.events
        while self._next < len(events) and events[self._next].t <= t + 1e-12:
            e = events[self._next]
            self._next += 1
            if e.kind == "yaw_moment":
                self.m_z = e.value
                self.panic_until = e.t + self.sc.driver.reaction_time
            elif e.kind == "steer":
                self.steer_intent = e.value
            elif e.kind == "steer_norm":
                self.steer_intent = e.value / steering_tf(VehicleParams(v=self.v, mu=1.0, mass=self.sc.mass)).dc_gain()
            elif e.kind == "mu":
                self.mu = e.value
                self.panic_until = e.t + self.sc.driver.reaction_time
                changed = True
            elif e.kind == "speed":
                self.v = e.value
                changed = True
            elif e.load is not None:  # a physical disturbance: a shock to the driver like a mu change
                self.panic_until = e.t + self.sc.driver.reaction_time
        return changed

    def correction_gain(self, t: float, dt: float) -> float:
        """How far the driver's correction moves in a step of ``dt`` at t per rad/s of yaw-rate
        error (``driver_angle``'s integrator; rad per rad/s): dt / (time_constant K_n(v)) while
        the driver corrects (``model`` mode, past the panic time), else 0.  A replay of a run
        under another command (``judge.caused_yaw.excursion_yaw``) lets its driver correct its own car."""
        return dt / self.sc.driver.time_constant / self._nominal_gain() if self._correcting(t) else 0.0

    def loads(self, t: float) -> dist.Loads:
        """What the physical disturbances do to the car at t (``disturbances.NO_LOADS`` if none)."""
        return dist.sum_loads(self._loads, t) if self._loads else dist.NO_LOADS

    def driver_angle(self, t: float, yaw_rate: float, dt: float) -> float:
        """The driver's front-wheel angle: the scripted intent plus, in ``model`` mode, a slow
        integrating correction that drives the yaw rate back to what the intent asks for on a
        dry road, frozen during the panic reaction time after each disturbance."""
        if self._correcting(t):
            nominal = self._nominal_gain()
            error = yaw_rate - nominal * self.steer_intent
            self.correction -= dt / self.sc.driver.time_constant * error / nominal
        angle = self.steer_intent + self.correction
        return max(-DRIVER_LIMIT, min(DRIVER_LIMIT, angle))

    def _correcting(self, t: float) -> bool:
        """The driver model corrects the yaw rate at t (``model`` mode, past the panic time)."""
        return self.sc.driver.mode == "model" and t >= self.panic_until

    def _nominal_gain(self) -> float:
        """K_n(v) at the current speed: the dry road's steady yaw rate per rad of steering."""
        return steering_tf(VehicleParams(v=self.v, mu=1.0, mass=self.sc.mass)).dc_gain()
