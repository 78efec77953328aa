"""Offline closed loop with the plausibility monitor and the authority limiter: the evidence
behind ``firmware_py.plausibility``'s thresholds (docs/controller.md, "Plausibility monitor").

``run`` plays a scenario on its car (``sim_plant.car``: plant, loads, driver model, actuator,
sensors with their faults) with the firmware's ``step()`` in the loop, as the plant node and the
controller do on the bus, without a bus: each sensor value is held at its DBC cycle (driver angle
and yaw rate every control period, speed every 10 ms, ``MRS_RedundantSensors`` every 50 ms,
all sampled at the step they are sent at), the command acts one period later.  The monitor sees
what the controller sees, and the controller is ``firmware_py.cycle``: monitor, law and
authority limiter in the node's order; the limited command reaches the actuator a period later.
``cut`` is the cycle's ``cut_checks``: the shipped pairs, or another mask to weigh against them.

``second_yaw`` adds the yaw-rate sensor's second element (issue 18's decision,
docs/decisions/0003-a-second-yaw-rate-element-and-the-cut.md): a sensor of its own configuration (noise stream,
offset), never faulted, sampled with the first as one ``MRS_YawRate`` frame would carry both,
for the monitor's pair check, as ``MRS_YawRate`` carries it; without it the car has none (NaN:
the check paused).

``second_speed`` gives the monitor the second speed (``RedundantSensors_Speed2``), the
scenario's own ``speed_redundant`` sensor (with its faults), held at the redundant frame's cycle;
without it the monitor has none (NaN: the speed pair paused), as before the bus carried it.

The error of a faulted sensor is measured against a second, fault-free copy of the same sensor
models (same seed, same streams), so it is the fault's own contribution, noise excluded, plus
the healthy sensors' constant offsets that its check sees with it (``judge.bounds.check_offset``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from firmware_py import cycle
from firmware_py import model_regulator as mr
from firmware_py import authority as au
from firmware_py import plausibility as pl
from mrsteer_dbc import names
import mrsteer_dbc
from sim_plant.car import scenario as scn
from sim_plant.car.scenario_play import ScenarioState
from sim_plant.car.actuator_dynamics import PositionActuator
from sim_plant.car.plants import Car
from sim_plant.car.sensors import CHANNELS, SensorConfig, Sensors
from sim_plant.car.vehicle import VehicleParams
from sim_plant.judge.bounds import check_offset, sensor_bound
from sim_plant.judge.caused_yaw import excursion_yaw, onset_step
from sim_plant.judge.detection import HOLD, exceeded_time

#: Each channel's bus cycle as a multiple of the 2 ms control period (from the DBC).
_MESSAGE = {"yaw_rate": names.MSG_YAW, "steer": names.MSG_STEER, "speed": names.MSG_SPEED,
            "lat_accel": names.MSG_REDUNDANT, "steer_redundant": names.MSG_REDUNDANT,
            "speed_redundant": names.MSG_REDUNDANT}


def cycles(ts: float) -> dict[str, int]:
    """Each channel's bus cycle in periods of ``ts`` (the plant node's ``every``): the channel is
    sent, and the controller's value of it renewed, at the steps k with k % cycle == 0."""
    contract = mrsteer_dbc.load()
    return {ch: max(1, round((contract.cycle_time_s(_MESSAGE[ch], ts) or ts) / ts)) for ch in _MESSAGE}


@dataclass
class MonitorRun:
    t: np.ndarray
    bits: np.ndarray  # CtrlStatus_Plausibility per period
    r_true: np.ndarray
    aux: np.ndarray  # the command applied
    error: np.ndarray  # the faulted sensor's error as its check sees it (+ check_offset; 0 without a fault)
    fault_sensor: str | None
    margins: dict[str, float]  # each check's largest residual over the run / its bound
    held: dict[str, np.ndarray]  # what the controller and the monitor saw, per channel (and yaw_rate_redundant)
    beta: np.ndarray
    flags: np.ndarray | None = None  # the monitor's detailed flags per period (None: not kept)

    def caused_yaw(self, start: float, car: VehicleParams) -> float:
        """The peak |r| that the command's excursion from ``start`` on gives the linear ``car``
        (eqs. 14/16): as the fault matrix's ``caused_yaw``, only what lies outside the range
        from the angle applied at the onset's step (``judge.caused_yaw.onset_step``: the last
        the fault cannot have moved, its command acting a period later; the healthy
        controller's, in a steady state) to zero."""
        k0 = onset_step(self.t, start)
        dt = float(self.t[1] - self.t[0])
        return 0.0 if k0 is None else excursion_yaw([float(a) for a in self.aux[k0:]], dt, car)

    def first(self, mask: np.ndarray) -> float | None:
        idx = np.flatnonzero(mask)
        return float(self.t[idx[0]]) if idx.size else None

    @property
    def fault_time(self) -> float | None:
        """When the monitor first reported a fault (PLAUS_YAW or PLAUS_STEER)."""
        return self.first((self.bits & pl.PLAUS_FAULT) != 0)

    @property
    def report_time(self) -> float | None:
        """When the monitor first reported the fault or the latched degraded state (issue 18's
        report: a lateral acceleration that disagrees with a yaw rate its second element
        confirms is DEGRADED, ``plausibility.OUTSIDE_MODEL``); a missing input's DEGRADED is
        no report.  Without ``flags``, the fault only."""
        outside = 0 if self.flags is None else (self.flags & pl.OUTSIDE_MODEL) != 0
        return self.first(((self.bits & pl.PLAUS_FAULT) != 0) | outside)

    def exceeded_time(self, bound: float | np.ndarray, hold: float = HOLD) -> float | None:
        """``judge.detection.exceeded_time`` of this run's error against ``bound``."""
        return exceeded_time(self.t, self.error, bound, self.report_time, hold)


def error_bound(sensor: str, cfg: pl.PlausibilityConfig, run: MonitorRun) -> float | np.ndarray:
    """``sensor_bound`` per period of an offline run: the true yaw rate, the speed the
    controller held, the pair running while the second element's value is there."""
    return sensor_bound(sensor, cfg, run.r_true, run.held["speed"], np.isfinite(run.held["yaw_rate_redundant"]))


# One loop that is the plant node's step and the controller's cycle side by side; long because
# each of its stages is a few lines that read best in order.
def run(sc: scn.Scenario, ts: float = 0.002, monitor: pl.PlausibilityConfig | None = None,
        controller: mr.ControllerConfig | None = None, authority: au.AuthorityConfig | None = None,
        second_yaw: SensorConfig | None = None, cut: int = pl.CUT_CHECKS,
        second_speed: bool = False) -> MonitorRun:
    every = cycles(ts)
    scene = ScenarioState(sc)
    car = Car(sc.plant, scene.params(), ts)
    actuator = PositionActuator(sc.actuator, ts)
    sensors, clean = Sensors(sc.sensor_config, ts), Sensors(sc.sensors, ts)
    second = Sensors(replace(second_yaw, faults=()), ts) if second_yaw is not None else None
    faulted = sc.sensor_faults[0].sensor if sc.sensor_faults else None
    onset = sc.sensor_faults[0].start if sc.sensor_faults else math.inf
    bias = sc.sensors.biases()
    if second_yaw is not None:
        bias["yaw_rate_redundant"] = second_yaw.biases()["yaw_rate"]
    if faulted == "speed_redundant" and not second_speed:
        raise ValueError("a fault of the second speed needs second_speed=True (the monitor reads it only then)")
    coefficients = cycle.configure(controller if controller is not None else mr.ControllerConfig(),
                                   monitor if monitor is not None else pl.PlausibilityConfig(ts=ts),
                                   authority if authority is not None else au.AuthorityConfig(ts=ts), cut)
    state, inputs = cycle.CycleState(), cycle.CycleInputs()
    n = int(round(sc.duration / ts)) + 1
    out = {k: np.zeros(n) for k in ("bits", "flags", "r", "aux", "err", "beta")}
    seen = {ch: np.zeros(n) for ch in (*CHANNELS, "yaw_rate_redundant", "speed_redundant")}
    held: dict[str, float] = {"yaw_rate_redundant": math.nan, "speed_redundant": math.nan}
    margins = dict.fromkeys(("kinematic", "steer_pair", "model", "yaw_pair", "turn", "speed_pair"), 0.0)
    pipeline: deque[float] = deque([0.0])
    applied = 0.0
    for k in range(n):
        t = k * ts
        if scene.advance_to(t):
            car.set_params(scene.params())
        car.set_loads(scene.loads(t))
        r_now = float(car.x[1])
        driver = scene.driver_angle(t, r_now, ts)
        y = car.outputs(driver + applied, scene.m_z)
        truth = {"yaw_rate": float(y[0]), "steer": driver, "speed": scene.v, "lat_accel": float(y[2]),
                 "steer_redundant": driver}
        sensors.at(t)
        clean.at(t)
        read = {ch: getattr(sensors, ch)(truth[ch]) for ch in CHANNELS}
        wheels = scene.v * (1.0 - car.loads.wheel_slip)  # the non-driven wheels' speed, slip and all
        if second_speed:
            read["speed_redundant"] = sensors.speed_redundant(wheels)
            if k % every["speed_redundant"] == 0:
                held["speed_redundant"] = read["speed_redundant"]
        if faulted is not None:
            true_value = wheels if faulted == "speed_redundant" else truth[faulted]
            out["err"][k] = read[faulted] - getattr(clean, faulted)(true_value) + check_offset(
                faulted, bias, scene.v, t >= onset)
        if second is not None:
            second.at(t)
            r_2 = second.yaw_rate(truth["yaw_rate"])
            if k % every["yaw_rate"] == 0:
                held["yaw_rate_redundant"] = r_2
        for ch in CHANNELS:
            if k % every[ch] == 0:
                held[ch] = read[ch]
        inputs.delta_driver = inputs.monitor_driver = held["steer"]
        inputs.delta_driver_redundant, inputs.lat_accel = held["steer_redundant"], held["lat_accel"]
        inputs.yaw_rate, inputs.yaw_rate_redundant = held["yaw_rate"], held["yaw_rate_redundant"]
        inputs.speed, inputs.speed_redundant = held["speed"], held["speed_redundant"]
        pipeline.append(cycle.step(coefficients, state, inputs))
        applied = actuator.step(pipeline.popleft())
        out["bits"][k], out["r"][k], out["aux"][k] = state.plausibility, float(y[0]), applied
        out["beta"][k] = float(y[1])
        out["flags"][k] = state.monitor.flags
        for ch in seen:
            seen[ch][k] = held[ch]
        st = state.monitor
        for key, value in (("kinematic", st.kin_err), ("steer_pair", st.pair_err), ("model", st.model_err),
                           ("yaw_pair", st.yaw_pair_err), ("turn", st.turn_err),
                           ("speed_pair", st.speed_pair_err)):
            margins[key] = max(margins[key], value)
        # as the plant node: the car gets the lagging actuator's mean position over the step
        car.advance(driver + actuator.mean, scene.m_z)
        if not car.linear:
            scene.v = car.v
    return MonitorRun(np.arange(n) * ts, out["bits"].astype(int), out["r"], out["aux"], out["err"], faulted,
                     margins, seen, out["beta"], out["flags"].astype(int))


def steady_curve(v: float, mu: float, a_y: float = 2.0, duration: float = 2.5, plant: str = "nonlinear",
                 ramp: float = 0.4, **kw: Any) -> scn.Scenario:
    """The realistic car at ``v`` on ``mu`` steering into a curve of about ``a_y`` (m/s^2, capped
    at 60 % of the grip) from 0.2 s, the wheel turned at a steady rate over ``ramp`` s (in 2 ms
    ``steer`` steps: a driver steering normally, not a step; 0 = a step), then held."""
    from sim_plant.car.actuator_dynamics import ActuatorModelConfig
    from sim_plant.car.sensors import SensorConfig
    from sim_plant.car.vehicle import steering_tf

    a = min(a_y, 0.6 * 9.81 * mu)
    gain = steering_tf(VehicleParams(v=v, mu=1.0)).dc_gain()  # r / delta on a dry road
    delta = a / v / gain
    n = max(1, round(ramp / 0.002))
    events = tuple(scn.Event(0.2 + i * 0.002, "steer", delta * (i + 1) / n) for i in range(n))
    return scn.Scenario("curve", duration, v=v, mu=mu, events=events, plant=plant,
                        actuator=ActuatorModelConfig.default(), sensors=SensorConfig(seed=kw.pop("seed", 1)), **kw)


def detection_latency(sc: scn.Scenario, ts: float = 0.002, monitor: pl.PlausibilityConfig | None = None) -> tuple[
        float | None, float | None]:
    """(when the fault's error first exceeded its bound, when the monitor reported it) for ``sc``
    with one sensor fault; either None if it did not happen."""
    cfg = monitor if monitor is not None else pl.PlausibilityConfig(ts=ts)
    r = run(sc, ts, cfg)
    if r.fault_sensor is None:
        raise ValueError("the scenario has no sensor fault")
    return r.exceeded_time(error_bound(r.fault_sensor, cfg, r)), r.report_time
