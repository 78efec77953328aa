"""The scalar reference of the batch engine: one scenario in closed loop with the controller
node's arithmetic, built from the product's scalar classes only.

``run`` is the lockstep plant node's step (``sim_plant.nodes.plant.PlantNode.step``, one step of
loop delay) and the controller node's cycle (``firmware_py.controller.node.ControllerNode.control``)
with the bus taken out:

* the plant: ``scenario_play.ScenarioState`` (events, loads, the driver model), ``plants.Car`` (the
  nonlinear car; its a_y from ``Car.outputs`` at the actuator's position as the step begins),
  ``actuator.Actuator`` (the command handling and its authority limit) and
  ``actuator_dynamics.PositionActuator``, ``sensors.Sensors`` (every channel read every step,
  each on its own stream, and the yaw-rate sensor's second element and the second speed);
* the bus: each channel held at its DBC cycle (``plausibility_runs.cycles``: driver angle and
  yaw rate every period, the speed every 10, ``MRS_RedundantSensors`` (a_y, the second steering
  channel and the second speed) every 25), the command one
  period late, ``MRS_CtrlStatus`` every 50 periods, its plausibility bits reaching the actuator
  two steps after they were computed (the plant reads the frame while it waits for the next
  command, after that step's command handling);
* the controller: the node's cycle (``firmware_py.cycle``: one monitor step per period, the law
  held by the monitor's suspicion, the authority limiter) on the held samples; the state the
  node reports is FAULT on ``step()``'s FAULT or ``PLAUS_FAULT``, else DEGRADED on
  ``PLAUS_DEGRADED``, else ``step()``'s (``reported_fault``, ``reported_saturated``).

A run ends at the step whose car has spun (``nonlinear.spun``: its side slip beyond the model's
validity): that step is its last, and the car is not advanced past it.

The batch engine must equal it (``tests/test_campaign_engine.py``), and ``mrsteer bench --only
campaign`` times it as the scalar firmware loop the engine is measured against.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, replace

import numpy as np

import mrsteer_dbc
from firmware_py import authority as au
from firmware_py import cycle as cy
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from mrsteer_dbc.names import MSG_CMD, MSG_STATUS, SIG_CMD_ANGLE
from sim_plant.car import scenario as scn
from sim_plant.car.scenario_play import ScenarioState
from sim_plant.car.actuator import Actuator, ActuatorConfig
from sim_plant.car.actuator_dynamics import PositionActuator
from sim_plant.car.nonlinear import spun
from sim_plant.car.plants import Car
from sim_plant.car.sensors import CHANNELS, SPEED_REDUNDANT, Sensors
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.judge.caused_yaw import excursion_yaw
from sim_plant.judge.detection import FaultFigures
from sim_plant.offline.plausibility_runs import cycles


@dataclass(frozen=True)
class ReferenceRun:
    """Per step to the run's last (its end, or the step its car spun at): the true yaw rate and
    side slip at the step's start, the command sent (after the authority limiter), ``step()``'s
    status, the plausibility bits and the limiter's flags, and the actuator position's mean over
    the step (the angle the car got besides the driver's)."""

    r: np.ndarray
    beta: np.ndarray
    command: np.ndarray
    status: np.ndarray
    bits: np.ndarray
    authority: np.ndarray
    final_speed: float
    false_alarms: int  # steps with a plausibility bit before the sensor fault's onset (all, without one)
    detection_time: float  # engine.METRICS' definition, by judge.detection.FaultFigures (NaN: no fault)
    fault_yaw_rate: float  # judge.caused_yaw.excursion_yaw against the fault-free twin (engine.METRICS; NaN: no fault)
    twin_yaw_rate: float  # |r - r of the fault-free twin|, largest from the onset (NaN: no fault)
    applied: np.ndarray
    spun: bool  # the car spun at the last step (``nonlinear.spun``)
    advanced: int  # steps whose car was advanced: all of them, or all but the last after a spin


#: ``mr.reported_state`` for every law status and every ``CtrlStatus_Plausibility`` value (3 bits),
#: out of the start state: the node's rule, tabulated so that arrays of steps x rows index it.
_REPORTED = np.array([[mr.reported_state(status, bits, False) for bits in range(8)] for status in range(8)],
                     dtype=np.int8)


def reported_states(status: np.ndarray, bits: np.ndarray) -> np.ndarray:
    """The state the controller node reports (``mr.reported_state``), element-wise over steps
    or steps x rows of ``step()``'s status and the monitor's bits."""
    return _REPORTED[status, bits & 7]


def reported_fault(status: np.ndarray, bits: np.ndarray) -> np.ndarray:
    """The steps the controller node reports FAULT: ``step()``'s FAULT (an input out of range)
    or the monitor's ``PLAUS_FAULT``."""
    return reported_states(status, bits) == mr.STATUS_FAULT


def reported_saturated(status: np.ndarray, bits: np.ndarray) -> np.ndarray:
    """The steps the controller node reports SATURATED: ``step()``'s SATURATED, unless the
    monitor's bits make the state FAULT or DEGRADED (the limiter may be fading the command)."""
    return reported_states(status, bits) == mr.STATUS_SATURATED


def status_cycle(ts: float) -> int:
    """``MRS_CtrlStatus``'s cycle in control periods (``ControllerNode.status_every``)."""
    return max(1, int(round((mrsteer_dbc.load().cycle_time_s(MSG_STATUS) or 0.1) / ts)))


def authority_limit(config: mr.ControllerConfig) -> float:
    """The controller's authority limit: its ``aux_limit`` within the command's DBC range (the node's)."""
    return min(config.aux_limit, mrsteer_dbc.load().signal_range(MSG_CMD, SIG_CMD_ANGLE)[1])


# The plant node's step and the controller's cycle side by side; long because each stage is a
# few lines that read best in the order the bus runs them.
def run(sc: scn.Scenario, config: mr.ControllerConfig | None, ts: float = 0.002) -> ReferenceRun:
    """Play ``sc`` with the controller ``config`` (None: none, and no monitor) in the loop."""
    scene = ScenarioState(sc)
    car = Car(sc.plant, scene.params(), ts)
    position = PositionActuator(sc.actuator, ts)
    sensors = Sensors(sc.sensor_config, ts)
    fault = sc.sensor_config.faults[0] if sc.sensor_config.faults else None
    bias = sc.sensor_config.biases()  # the healthy offsets the fault's check sees with it
    # the same sensors without the fault: an identity fault in its place keeps every noise stream
    # where the faulted copy has it (the second yaw-rate element's follows the faults')
    clean = None if fault is None else Sensors(
        replace(sc.sensors, faults=(SensorFault(fault.sensor, "scale", fault.start, 1.0),)), ts)
    handling = Actuator(ActuatorConfig(), ts)
    ctrl = None if config is None else cy.Cycle(config, pl.PlausibilityConfig(ts=ts),
                                                 au.AuthorityConfig(ts=ts, u_max=authority_limit(config)))
    ci = cy.CycleInputs()
    cs = cy.CycleState() if ctrl is None else ctrl.state
    every, status_every = cycles(ts), status_cycle(ts)
    pipeline: collections.deque[float] = collections.deque([0.0])
    n = int(round(sc.duration / ts)) + 1
    r_hist, beta_hist, u_hist = np.empty(n), np.empty(n), np.empty(n)
    applied, driver_hist, m_z_hist, mu_hist, v_hist, gain_hist = (np.empty(n) for _ in range(6))
    loads_hist = []
    status, bits_hist, auth, flags_hist = (np.zeros(n, dtype=np.int64) for _ in range(4))
    error, speed_true = np.zeros(n), np.zeros(n)
    held: dict[str, float] = {}
    command = 0.0  # the command sent the period before: what acts on the car now
    in_flight: int | None = None  # a status frame's plausibility bits, not yet read by the plant
    for k in range(n):
        t = k * ts
        if scene.advance_to(t):
            car.set_params(scene.params())
        car.set_loads(scene.loads(t))
        m_z = scene.m_z
        x = car.x
        driver = scene.driver_angle(t, float(x[1]), ts)
        handling.apply(pipeline.popleft())
        if in_flight is not None:  # read while the plant waits for this step's command
            handling.status_received(in_flight)
            in_flight = None
        y = car.outputs(driver + position.position, m_z)
        truth = {"yaw_rate": float(y[0]), "steer": driver, "speed": scene.v, "lat_accel": float(y[2]),
                 "steer_redundant": driver}
        sensors.at(t)
        read = {ch: getattr(sensors, ch)(truth[ch]) for ch in CHANNELS}
        yaw_rate_2 = read["yaw_rate_redundant"] = sensors.yaw_rate_redundant(truth["yaw_rate"])  # every period
        # the second speed: read every step (the plant's sensor), sent in MRS_RedundantSensors
        wheels = scene.v * (1.0 - car.loads.wheel_slip)  # the non-driven wheels' speed, slip and all
        read[SPEED_REDUNDANT] = sensors.speed_redundant(wheels)
        truth["yaw_rate_redundant"], truth[SPEED_REDUNDANT] = truth["yaw_rate"], wheels
        if fault is not None and clean is not None:
            clean.at(t)
            error[k] = read[fault.sensor] - getattr(clean, fault.sensor)(truth[fault.sensor])
        for ch in (*CHANNELS, SPEED_REDUNDANT):
            if k % every[ch] == 0:
                held[ch] = read[ch]
        speed_true[k] = scene.v
        u, bits, state = 0.0, 0, mr.STATUS_INACTIVE  # no controller: no command, no status
        if ctrl is not None:
            ci.delta_driver = ci.monitor_driver = held["steer"]
            ci.yaw_rate, ci.speed, ci.lat_accel = held["yaw_rate"], held["speed"], held["lat_accel"]
            ci.delta_driver_redundant, ci.yaw_rate_redundant = held["steer_redundant"], yaw_rate_2
            ci.speed_redundant = held[SPEED_REDUNDANT]
            u = ctrl.step(ci)
            bits, state, flags_hist[k] = cs.plausibility, cs.law.status, cs.monitor.flags
            if (k + 1) % status_every == 0:
                in_flight = bits
        command = u
        pipeline.append(u)
        handling.command_received()  # lockstep: the answer arrived
        handling.tick()
        position.step(handling.applied)
        r_hist[k], beta_hist[k], u_hist[k] = x[1], x[0], u
        status[k], bits_hist[k], auth[k] = state, bits, cs.authority.flags
        applied[k], driver_hist[k], m_z_hist[k] = position.mean, driver, m_z + car.loads.m_z
        mu_hist[k], v_hist[k], gain_hist[k] = scene.params().mu, car.v, scene.correction_gain(t, ts)
        loads_hist.append(car.loads)
        if spun(float(x[0])):
            last = advanced = k  # the car has left its model: the run ends with this step
            break
        car.advance(driver + position.mean, m_z)  # PlantNode.step: the position's mean over the step
        scene.v = car.v
    else:
        last, advanced = n - 1, n
    kept = slice(0, last + 1)
    r_hist, beta_hist, u_hist, applied, status, bits_hist, auth, flags_hist, error, speed_true = (
        a[kept] for a in (r_hist, beta_hist, u_hist, applied, status, bits_hist, auth, flags_hist, error, speed_true))
    caused, clean = math.nan, None
    if fault is not None and ctrl is not None:
        # the yaw rate the fault makes the command cause: the excursion beyond the same run
        # without it, replayed on the car from the onset (as hil run's figure), over the steps
        # both cars were advanced
        clean = run(replace(sc, sensor_faults=(), sensors=replace(sc.sensors, faults=())), config, ts)
        k0 = int(np.argmax(np.arange(n) * ts >= fault.start))
        k1 = min(advanced, clean.advanced)
        car_at_onset = replace(scene.params(), v=float(v_hist[k0]), mu=float(mu_hist[k0]))
        caused = excursion_yaw(applied[k0:k1], ts, car_at_onset, sc.plant, driver_hist[k0:k1], m_z_hist[k0:k1],
                               float(beta_hist[k0]), float(r_hist[k0]), healthy=clean.applied[k0:k1],
                               mu=mu_hist[k0:k1], loads=loads_hist[k0:k1], driver_gain=gain_hist[k0:k1]) \
            if k0 <= last else 0.0
    elif fault is not None:
        caused = 0.0  # no controller: nothing caused
    # (without a controller nothing is reported or caused: no fault figures, as the engine's)
    figures = fault_figures(fault if ctrl is not None else None, ts, bits_hist, r_hist, error, speed_true,
                            None if clean is None else clean.r, flags_hist, bias)
    if fault is None:
        figures = (figures[0], math.nan, math.nan)
    elif ctrl is None:
        figures = (figures[0], 0.0, 0.0)
    return ReferenceRun(r_hist, beta_hist, u_hist, status, bits_hist, auth, car.v, figures[0], figures[1],
                        caused, figures[2], applied, advanced < n, advanced)


def fault_figures(fault: SensorFault | None, ts: float, bits: np.ndarray, r: np.ndarray, error: np.ndarray,
                  v: np.ndarray, r_clean: np.ndarray | None, flags: np.ndarray,
                  bias: dict[str, float]) -> tuple[int, float, float]:
    """(false_alarms, detection_time, twin_yaw_rate) of a run: the engine's judge
    (``judge.detection.FaultFigures``) on a batch of one, with the fault's own
    ``error``, the true yaw rate ``r`` and speed ``v``, the healthy offsets ``bias``; the run's
    last step its end (a spin's); twin_yaw_rate the largest |r - ``r_clean``| from the onset
    over the steps both runs have (0 without ``r_clean``)."""
    t = np.arange(bits.size) * ts
    after = t >= fault.start if fault is not None else np.zeros(bits.size, dtype=bool)
    if fault is None:
        return int(np.count_nonzero(bits != 0)), 0.0, 0.0
    rows = _OneFault(np.array([fault.start]), np.array([1]), {fault.sensor: np.array([True])})
    judge = FaultFigures(rows, bits.size, ts, bias)
    judge.steps(0, error[:, None], bits[:, None], r[:, None], v[:, None], flags[:, None])
    figures = judge.result()
    m = 0 if r_clean is None else min(r.size, r_clean.size)  # (a run that spun ends early)
    twin = float(np.max(np.where(after[:m], np.abs(r[:m] - r_clean[:m]), 0.0), initial=0.0))
    return int(figures["false_alarms"][0]), float(figures["detection_time"][0]), twin


@dataclass(frozen=True)
class _OneFault:
    """A run's sensor fault as ``FaultFigures`` reads a batch's (``judge.detection.FaultRows``)."""

    onset: np.ndarray
    sensor: np.ndarray
    rows: dict[str, np.ndarray]
