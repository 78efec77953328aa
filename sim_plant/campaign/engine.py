"""The batch engine: every sample of a ``SampleSet`` in closed loop with one calibration of the
firmware's law, the realistic car around it, one numpy operation per time step for all rows.

One step k (t = k ts) is the lockstep plant node's (``sim_plant.nodes.plant.PlantNode.step``
with one step of loop delay) and the controller node's cycle
(``firmware_py.controller.node.ControllerNode.control``) without the bus, in their order, as the
scalar oracle ``reference.run`` has them:

1. the scenario's event at its onset (the M_z step, the driver's panic window) and the
   disturbances' loads at t (``loads``);
2. the driver model (``scenario_play.ScenarioState.driver_angle``): frozen during the panic time,
   then a slow correction of the yaw rate;
3. the actuator's command handling (``actuator.Actuator``) takes the command sent the step
   before through its own authority limit, on the plausibility bits of the last status frame
   (sent every 50 periods, read by the plant two steps after they were computed; DEGRADED
   before the first);
4. the sensors read every channel (``BatchSensors``): the driver's angle and the yaw rate (both
   its elements) sent every period, the speed every 10, the lateral acceleration (the car's a_y
   at the actuator's position as the step begins), the second steering channel and the second
   speed every 25 (``MRS_RedundantSensors``), each held between;
5. the controller: the C port's control cycle (``mrs_cycle_step``: the plausibility monitor
   given the command sent the period before, the law held on its suspicion, the authority
   limiter on its bits, cut and fade) for every row in one call (``c_cycle.CycleBatch``, the
   actuators' own limiters ``c_cycle.AuthorityBatch``); the state reported FAULT on
   ``PLAUS_FAULT``;
6. the actuator's position follows the handled command, and the car advances with the
   driver's angle plus the position's mean over the step.

The rows are split into two groups that run apart, so that neither pays for the other's
arithmetic: the yaw-moment step and the side wind (all wheels intact, speed constant); split-mu
braking and the blow-out (speed integrated, every wheel evaluated on its own: a split-mu row's
wheels keep their axle's B, which gives its values bitwise).  Split-mu rows alone could share
each axle's tyre curve, but a third group's numpy calls cost more than their wheels' curves
(each call's fixed cost is about that of a thousand rows' arithmetic).

A row whose car spins (``nonlinear.spun``: its side slip beyond the model's validity) ends at
that step, as the reference's run does: its figures are those up to it (``batch_tally.Ends``).  Its
arithmetic runs on with the batch, since taking a row out of every stage's arrays costs more
than carrying it, but nothing after its last step enters its figures or its traces.

``simulate`` returns, per row, the figures the criteria judge (``METRICS``).
"""

from __future__ import annotations

import math

import numpy as np

from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from sim_plant.campaign.batch_faults import BatchFaults
from sim_plant.campaign.batch_sensors import BatchSensors
from sim_plant.campaign.c_cycle import AuthorityBatch, CycleBatch
from sim_plant.campaign.batch_tally import Ends, Tally, end_traces, scatter
from sim_plant.campaign.reference import authority_limit, status_cycle
from sim_plant.campaign.loads import BLOCK, EVENT_SLACK, SPLIT, BLOWOUT, GripLoads, IntactLoads
from sim_plant.campaign.params import NOISE_SEED, SampleSet
from sim_plant.car.actuator_dynamics import BatchPositionActuator
from sim_plant.car.nonlinear import BASE, BatchCar
from sim_plant.car.scenario_play import DRIVER_LIMIT
from sim_plant.car.tyres import Tyres
from sim_plant.judge.caused_yaw import kept as kept_of
from sim_plant.judge.detection import FaultFigures
from sim_plant.offline.plausibility_runs import cycles

#: Per-row results: name -> unit, description.
METRICS = {
    "peak_yaw_rate": ("rad/s", "largest |r| of the run (the car's true yaw rate)"),
    "peak_side_slip": ("deg", "largest |beta| of the run"),
    "time_at_limit": ("s", "time the reported state was SATURATED: the law's command at the actuator's +-3 deg, "
                           "the monitor neither faulted nor degraded (reference.reported_saturated)"),
    "fault_steps": ("", "steps the controller reported a fault: step()'s input ranges or the monitor's"),
    "false_alarm_steps": ("", "steps the monitor reported PLAUS_FAULT or PLAUS_DEGRADED"),
    "plausibility_bits": ("", "the monitor's CtrlStatus_Plausibility bits, OR over the run"),
    "authority_steps": ("", "periods the controller's authority limiter bound the command"),
    "false_alarms": ("", "steps with PLAUS_FAULT or PLAUS_DEGRADED before the sensor fault's onset (all, without one)"),
    "detection_time": ("s", "first PLAUS_FAULT or OUTSIDE_MODEL (DEGRADED) less when the fault's error (plus "
                            "the healthy biases its check sees: judge.bounds.check_offset) left "
                            "its bound (judge.bounds.sensor_bound; either speed's: the speed pair's; none below "
                            "speed_min) for 0.3 s "
                            "(0: it never did, or was reported before, or no controller; inf: never reported; "
                            "NaN: no sensor fault)"),
    "fault_yaw_rate": ("rad/s", "the yaw rate the faulty sensor makes the command cause: largest |r - r'| from "
                                "the sensor fault's onset, r' the same car without the applied angle's excursion "
                                "beyond the fault-free twin's and zero (judge.caused_yaw, as hil run's "
                                "caused_yaw_rad_s; a fade is not counted; 0 without a controller, NaN without "
                                "a sensor fault)"),
    "twin_yaw_rate": ("rad/s", "largest |r - r of the fault-free twin| (each at its step's start) from the sensor "
                               "fault's onset: the fault's "
                               "whole cost to the car, the disturbance rejection a fade gives up included (0 "
                               "without a controller, NaN without a sensor fault)"),
    "peak_command": ("deg", "largest |auxiliary command|"),
    "final_yaw_rate": ("rad/s", "r at the end (of a spun run: at the spin)"),
    "final_speed": ("m/s", "v at the end (of a spun run: at the spin)"),
    "spun": ("", "the car spun: its side slip passed the model's validity (nonlinear.SPIN_SIDE_SLIP), and the run "
                 "ended there: every figure is up to that step"),
    "spin_time": ("s", "when it spun (NaN: it did not)"),
}
ACTUATOR_LIMIT_DEG = 3.0


def steps_of(duration: float, ts: float) -> int:
    """Steps of a run (``PlantNode.run``)."""
    return int(round(duration / ts)) + 1


def nominal_gain(v: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """``steering_tf(VehicleParams(v, mu=1, mass)).dc_gain()``: the driver model's K_n(v)."""
    p = BASE
    c_f, c_r = 1.0 * p.c_f0, 1.0 * p.c_r0
    b0 = c_f * c_r * (p.l_f + p.l_r) * v
    a0 = c_f * c_r * (p.l_f + p.l_r) ** 2 + (c_r * p.l_r - c_f * p.l_f) * mass * v**2
    return b0 / a0


def simulate(samples: SampleSet, config: mr.ControllerConfig | None, duration: float, ts: float = 0.002,
             record: bool = False) -> dict[str, np.ndarray]:
    """Every row in closed loop with ``config`` (None: no controller); ``METRICS`` per row, and
    with ``record`` the traces ``r``, ``beta``, ``command``, ``bits`` (steps x rows) as well.

    A row with a sensor fault runs beside a twin without it (the same sample, noise and all), and
    beside a third car that the row's own angles drive less their *excursion*, the part outside
    the range from the twin's applied angle to zero (``judge.caused_yaw.excursion``): from
    the fault's onset, ``fault_yaw_rate`` is the largest difference of the row's and the third
    car's true yaw rates (the yaw rate the fault makes the command cause, the figure ``hil run``
    reports; a fade toward zero is not counted), ``twin_yaw_rate`` the largest of the row's and
    the twin's (the fault's whole cost, a fade's included)."""
    if config is not None and abs(config.ts - ts) > 1e-15:
        raise ValueError(f"the calibration's step {config.ts:g} s differs from the campaign's {ts:g} s")
    n = len(samples)
    faulted = np.flatnonzero(samples["fault_sensor"] != 0) if config is not None else np.zeros(0, dtype=np.int64)
    twin_of = np.full(n + faulted.size, -1)
    if faulted.size:
        twins = samples.take(faulted)
        twins["fault_sensor"] = np.zeros(faulted.size)
        samples = SampleSet({k: np.concatenate([v, twins[k]]) for k, v in samples.items()})
        twin_of[faulted] = n + np.arange(faulted.size)
    kind = samples["disturbance"]
    grip = (kind == SPLIT) | (kind == BLOWOUT)
    out: dict[str, np.ndarray] = {}
    local = np.full(len(samples), -1)
    for rows in (np.flatnonzero(~grip), np.flatnonzero(grip)):
        if rows.size == 0:
            continue
        local[rows] = np.arange(rows.size)  # a twin has its row's kind: the same group
        twin = np.where(twin_of[rows] >= 0, local[np.maximum(twin_of[rows], 0)], -1)
        steps = steps_of(duration, ts)
        # (the group freed as soon as it has run: the next one's arrays reuse its memory, not fresh pages)
        res = _Group(samples.take(rows), config, ts, grip=bool(grip[rows[0]]), record=record, twin=twin,
                     steps=steps).run(steps)
        for name, values in res.items():
            if name not in out:
                shape = (len(samples),) if values.ndim == 1 else (values.shape[0], len(samples))
                out[name] = np.empty(shape, dtype=values.dtype)
            out[name][..., rows] = values
    return {name: values[..., :n] for name, values in out.items()}


class _Group:
    """Rows that share their tyre and speed treatment, run together."""

    def __init__(self, s: SampleSet, config: mr.ControllerConfig | None, ts: float, grip: bool,
                 record: bool, twin: np.ndarray, steps: int | None = None) -> None:
        self.ts, self.grip, self.record = ts, grip, record
        self.pairs = np.flatnonzero(twin >= 0)  # the rows with a fault-free twin, and their twins
        self.twins = twin[self.pairs]
        self.fault_onset = s["fault_onset"][self.pairs]
        # the faulted rows' car without their command's excursion (before the onset the row's own)
        self.shadow = BatchCar(s["v"][self.pairs], s["mu"][self.pairs], s["mass"][self.pairs], ts) \
            if self.pairs.size else None
        self.shadow_correction = np.zeros(self.pairs.size)  # its driver's, less the row's driver's
        self.mass = s["mass"]
        n = self.mass.size
        self.car = BatchCar(s["v"], s["mu"], s["mass"], ts)
        self.loads = GripLoads(s, self.car) if grip else IntactLoads(s)
        self.actuator = BatchPositionActuator(s["actuator_tau"], s["actuator_rate"], ACTUATOR_LIMIT_DEG, ts)
        # The actuator's own authority limit (actuator.Actuator), on the status frames' bits
        self.act_limiter = AuthorityBatch(ts, math.radians(ACTUATOR_LIMIT_DEG), n)
        self.fault_free = s["fault_sensor"] == 0
        self.faults = None if self.fault_free.all() else BatchFaults(s)
        self.sensors = BatchSensors(s["noise_density"], s["bias"], s[NOISE_SEED], ts, faults=self.faults, steps=steps)
        self.every = cycles(ts)
        if self.every["steer"] != 1 or self.every["yaw_rate"] != 1:
            raise ValueError("the batch engine expects the driver's angle and the yaw rate every period")
        self.status_every = status_cycle(ts)
        # the controller node's cycle (C): the monitor, step() (held on its suspicion), the limiter
        self.cycle = CycleBatch(config, authority_limit(config), n) if config is not None else None
        self.panic_until = s["onset"] + s["reaction_time"]
        self.onset = s["onset"]
        self.gain_step = ts / s["driver_time_constant"]
        self.nominal = None if grip else nominal_gain(self.car.v, self.mass)

    def _loads(self, block: dict, j: int) -> tuple[np.ndarray, np.ndarray | None, Tyres | None]:
        """This step's m_z, side force and tyres (None: the intact axles) from the loads' block."""
        f_y = block["f_y"][j] if block["f_y"] is not None else None
        if not self.grip:
            return block["m_z"][j], f_y, None
        b = block["b"]
        return block["m_z"][j], f_y, Tyres(b[j if b.shape[0] > 1 else 0], block["d"][j])

    # One step of the plant node and the controller node per pass, in their order; long because
    # each stage is a few lines that read best in sequence (the reference's loop, batched).
    def run(self, n: int) -> dict[str, np.ndarray]:
        ts, car, sensors, rows = self.ts, self.car, self.sensors, self.mass.size
        correction = np.zeros(rows)
        pending = np.zeros(rows)  # the command sent the period before (one step of loop delay)
        act_bits = np.full(rows, pl.PLAUS_DEGRADED, dtype=np.int64)  # no status frame yet: unchecked
        act_latched = np.zeros(rows, dtype=np.int64)
        in_flight: np.ndarray | None = None  # a status frame's bits, read by the plant next step
        held: dict[str, np.ndarray] = {}
        cycle = self.cycle
        controlled = cycle is not None
        tally = Tally(rows, controlled)
        ends = Ends(rows, n)
        final = np.empty((3, rows))  # beta, r, v of each row's last step that spun
        term = np.empty(rows)
        traces = {k: np.empty((n, rows)) for k in ("r", "beta", "command", "bits")} if self.record else {}
        red_every, speed_every = self.every["lat_accel"], self.every["speed"]
        # the channels some row faults: with the monitor on, their errors are followed every step
        tracked = sensors.tracked
        speed_faulted = "speed" in tracked
        figures = (FaultFigures(self.faults, n, ts, sensors.biases)
                   if self.faults is not None and controlled else None)
        track_speed = figures is not None and speed_faulted
        track_speed2 = figures is not None and "speed_redundant" in tracked
        track_steer2 = figures is not None and "steer_redundant" in tracked
        fault_yaw, twin_yaw = np.zeros(self.pairs.size), np.zeros(self.pairs.size)
        for k0 in range(0, n, BLOCK):
            t_block = np.arange(k0, min(n, k0 + BLOCK), dtype=float)[:, None] * ts
            block = self.loads.block(t_block)
            # The driver: frozen until panic_until once the event has fired, else correcting.
            steering = (t_block >= self.panic_until) | (self.onset > t_block + EVENT_SLACK)
            all_steering = steering.all(axis=1).tolist()
            for j in range(t_block.shape[0]):
                k = k0 + j
                t = k * ts
                after = self.fault_onset <= t  # the faulted rows' faults have begun
                r = car.r  # (a view: read before the car advances)
                tally.state(j, car.x)
                ending = ends.check(k, car.beta)  # rows whose car spun: this step is their last
                if ending is not None:
                    final[:, ending] = car.x[:, ending]
                live = ends.live(k)  # None: every row's run still on
                nominal = self.nominal if self.nominal is not None else nominal_gain(car.v, self.mass)
                np.multiply(self.gain_step, r, out=term)
                term /= nominal
                if all_steering[j]:
                    correction -= term
                else:
                    correction = np.where(steering[j], correction - term, correction)
                driver = np.add(correction, 0.0)
                np.minimum(driver, DRIVER_LIMIT, out=driver)
                np.maximum(driver, -DRIVER_LIMIT, out=driver)
                # actuator.Actuator.apply, fresh: its authority limit on the last status (its range
                # is the position actuator's own, below)
                handled = self.act_limiter.step(pending, act_bits)
                if in_flight is not None:  # the status frame the plant reads while it waits
                    act_latched |= in_flight & pl.PLAUS_FAULT
                    act_bits, in_flight = in_flight | act_latched, None
                m_z, f_y, tyres = self._loads(block, j)
                # The sensors: every channel every step (the filters run at the plant step), each
                # held at its DBC cycle; a_y at the actuator's position as the step begins.
                sensors.at(k)
                yaw = sensors.yaw_rate(r)
                lat = sensors.lat_filtered(car.lat_accel(driver + self.actuator.position, f_y, tyres))
                if k % red_every == 0 or track_speed2:
                    # the second speed reads the braked rear wheels (GripLoads' wheel_slip)
                    wheels = car.v if "wheel_slip" not in block else car.v * (1.0 - block["wheel_slip"][j])
                if k % red_every == 0:
                    held["lat"], held["steer2"] = sensors.quantised_lat(lat), sensors.steer_redundant(driver)
                    held["speed2"] = sensors.speed_redundant(wheels)
                else:
                    if track_steer2:
                        sensors.steer_redundant(driver)  # its error, every step
                    if track_speed2:
                        sensors.speed_redundant(wheels)
                # (the intact rows' speed is constant, but for a faulted speed sensor's reading)
                if k % speed_every == 0 and (self.grip or k == 0 or speed_faulted):
                    held["speed"] = sensors.speed(car.v)
                elif track_speed:
                    sensors.speed(car.v)  # its error, every step
                steer = sensors.steer(driver)
                if cycle is not None:
                    # (the outputs are the cycle's arrays, overwritten next period: what outlives it is copied)
                    u = cycle.step(steer, held["steer2"], yaw, held["lat"], held["speed"],
                                   sensors.yaw_rate_redundant(r), held["speed2"])
                    bits, flags = cycle.out["plausibility"], cycle.out["monitor_flags"]
                    tally.control(j, u, cycle.out["status"], bits, cycle.out["authority_flags"])
                    if (k + 1) % self.status_every == 0:
                        in_flight = bits.astype(np.int64)
                    if figures is not None:
                        figures.step(k, sensors.error, bits, r, car.v, flags, live, ending)
                    if self.shadow is not None:  # (while both runs are on)
                        whole = np.abs(r[self.pairs] - r[self.twins])
                        on = after if live is None else after & live[self.pairs] & live[self.twins]
                        np.maximum(twin_yaw, np.where(on, whole, 0.0), out=twin_yaw)
                else:
                    u, bits = np.zeros(rows), tally.no_bits
                pending = u
                self.actuator.step(handled)
                if self.record:
                    for name, value in (("r", car.r), ("beta", car.beta), ("command", u), ("bits", bits)):
                        traces[name][k] = value
                # the car gets the position's mean over the step
                delta = driver + self.actuator.mean
                if self.shadow is not None:
                    self._advance_shadow(driver, block, j, m_z, f_y, tyres, after,
                                         steering[j][self.pairs] if not all_steering[j] else None, nominal)
                if self.grip:
                    car.advance(delta, m_z, f_y, block["a_x"][j], tyres, block["mu_max"][j])
                else:
                    car.advance(delta, m_z, f_y, None, None, car.mu)
                if self.shadow is not None:  # (as excursion_yaw: each step's end from the onset's on)
                    caused = np.abs(car.r[self.pairs] - self.shadow.r)
                    moved = ends.advanced(k)  # (while both cars were advanced)
                    on = after if moved is None else after & moved[self.pairs] & moved[self.twins]
                    np.maximum(fault_yaw, np.where(on, caused, 0.0), out=fault_yaw)
            tally.reduce(t_block.shape[0], k0, ends)
        c = tally.counts
        spun = ends.stop < n
        no_fault = np.where(self.fault_free, np.nan, 0.0)  # (a fault without a controller: 0)
        if self.record:
            end_traces(traces, ends.last)
        return {"peak_yaw_rate": tally.peaks[1], "peak_side_slip": np.degrees(tally.peaks[0]),
                "time_at_limit": c["at_limit"] * ts, "fault_steps": c["faults"],
                "false_alarm_steps": c["alarms"], "plausibility_bits": tally.ored,
                "authority_steps": c["authority"], "peak_command": np.degrees(tally.peak_u),
                **(figures.result() if figures is not None else
                   {"false_alarms": c["alarms"].copy(), "detection_time": no_fault.copy()}),
                "fault_yaw_rate": scatter(no_fault, self.pairs, fault_yaw),
                "twin_yaw_rate": scatter(no_fault, self.pairs, twin_yaw),
                "final_yaw_rate": np.where(spun, final[1], car.r), "final_speed": np.where(spun, final[2], car.v),
                "spun": spun, "spin_time": np.where(spun, ends.last * ts, np.nan), **traces}

    def _advance_shadow(self, driver: np.ndarray, block: dict, j: int, m_z: np.ndarray, f_y: np.ndarray | None,
                        tyres: Tyres | None, after: np.ndarray, steering: np.ndarray | None,
                        nominal: np.ndarray) -> None:
        """The third car of each faulted row one step on: the row's loads; the actuator position's
        mean over the step, from the fault's onset on (``after``) less its excursion beyond
        [min(0, h), max(0, h)], h the twin's (``judge.caused_yaw.kept``); the row's driver angle
        plus the correction the driver (where ``steering``; None: every row) would have added for
        this car's yaw rate (``excursion_yaw``'s ``driver_gain``, at the row's speed; clamped on
        the row's clamped angle, as the replay).  Before the onset it is the row's own car: the
        twin's sensors draw their noise apart from the faulted row's, so their commands may differ
        there by a little."""
        at, mean = self.pairs, self.actuator.mean
        shadow = self.shadow
        assert shadow is not None
        step = self.gain_step[at] * (shadow.r - self.car.r[at]) / nominal[at]
        self.shadow_correction -= step if steering is None else np.where(steering, step, 0.0)
        applied, healthy = mean[at], mean[self.twins]
        kept = kept_of(applied, healthy)
        delta = np.clip(driver[at] + self.shadow_correction, -DRIVER_LIMIT, DRIVER_LIMIT)
        delta += np.where(after, kept, applied)
        m_z = np.broadcast_to(m_z, driver.shape)[at]
        f_y = None if f_y is None else np.broadcast_to(f_y, driver.shape)[at]
        if self.grip:
            assert tyres is not None
            shadow.advance(delta, m_z, f_y, block["a_x"][j][at], Tyres(tyres.b[..., at], tyres.d[..., at]),
                           block["mu_max"][j][at])
        else:
            shadow.advance(delta, m_z, f_y, None, None, shadow.mu)
