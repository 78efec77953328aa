"""The batch engine: every sample of a ``SampleSet`` in closed loop with one calibration of the
firmware's law, the realistic car around it, one numpy operation per time step for all rows.

One step k (t = k ts) is the lockstep plant node's (``sim_plant.nodes.plant.PlantNode.step``
with one step of loop delay) without the bus, in its order:

1. the scenario's event at its onset (the M_z step, the driver's panic window) and the
   disturbances' loads at t (``loads``);
2. the driver model (``scenario.ScenarioState.driver_angle``): frozen during the panic time,
   then a slow correction of the yaw rate;
3. the sensors measure the driver's angle, the speed and the yaw rate (``BatchSensors``);
4. the law computes the command (``BatchLaw``), which the actuator receives one step later;
5. the actuator's position follows the command received the step before, and the car advances
   with the driver's angle plus the position's mean over the step.

The rows are split into groups that run apart, so that none pays for another's arithmetic: the
yaw-moment step and the side wind (all wheels intact, speed constant); split-mu braking (speed
integrated, each axle's two wheels on their own mu with one shared tyre curve); the blow-out
(speed integrated, every wheel evaluated on its own).

``simulate`` returns, per row, the figures the criteria judge (``METRICS``).
"""

from __future__ import annotations

import math

import numpy as np

from firmware_py import authority as au
from firmware_py import model_regulator as mr
from sim_plant.campaign.batch_car import BASE, BatchCar, BatchPositionActuator, BatchSensors, Tyres
from sim_plant.campaign.batch_law import BatchLaw
from sim_plant.campaign.batch_monitor import BatchAuthority
from sim_plant.campaign.loads import BLOCK, EVENT_SLACK, SPLIT, BLOWOUT, GripLoads, IntactLoads
from sim_plant.campaign.params import NOISE_SEED, SampleSet

#: Per-row results: name -> unit, description.
METRICS = {
    "peak_yaw_rate": ("rad/s", "largest |r| of the run"),
    "peak_side_slip": ("deg", "largest |beta| of the run"),
    "time_at_limit": ("s", "time the command sat at the actuator's +-3 deg"),
    "fault_steps": ("", "steps the firmware reported a fault (no fault is injected: false alarms)"),
    "peak_command": ("deg", "largest |auxiliary command|"),
    "final_yaw_rate": ("rad/s", "r at the end"),
    "final_speed": ("m/s", "v at the end"),
}
DRIVER_LIMIT = 0.6  # ScenarioState.driver_angle's clamp, rad
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
    with ``record`` the traces ``r``, ``beta``, ``command`` (steps x rows) as well."""
    if config is not None and abs(config.ts - ts) > 1e-15:
        raise ValueError(f"the calibration's step {config.ts:g} s differs from the campaign's {ts:g} s")
    kind = samples["disturbance"]
    grip = (kind == SPLIT) | (kind == BLOWOUT)
    out: dict[str, np.ndarray] = {}
    for rows in (np.flatnonzero(~grip), np.flatnonzero(kind == SPLIT), np.flatnonzero(kind == BLOWOUT)):
        if rows.size == 0:
            continue
        part = _Group(samples.take(rows), config, ts, grip=bool(grip[rows[0]]), record=record)
        res = part.run(steps_of(duration, ts))
        for name, values in res.items():
            if name not in out:
                shape = (len(samples),) if values.ndim == 1 else (values.shape[0], len(samples))
                out[name] = np.empty(shape, dtype=values.dtype)
            out[name][..., rows] = values
    return out


class _Group:
    """Rows that share their tyre and speed treatment, run together."""

    def __init__(self, s: SampleSet, config: mr.ControllerConfig | None, ts: float, grip: bool,
                 record: bool) -> None:
        self.ts, self.grip, self.record = ts, grip, record
        self.mass = s["mass"]
        self.car = BatchCar(s["v"], s["mu"], s["mass"], ts)
        self.loads = GripLoads(s, self.car) if grip else IntactLoads(s)
        self.actuator = BatchPositionActuator(s["actuator_tau"], s["actuator_rate"], ACTUATOR_LIMIT_DEG, ts)
        # The actuator's own authority limit (actuator.Actuator): size and rate, the controller's
        # status saying every check runs (no monitor in the batch yet: docs/campaigns.md).
        self.authority = BatchAuthority(au.AuthorityConfig(ts=ts, u_max=math.radians(ACTUATOR_LIMIT_DEG)),
                                        self.mass.size)
        self.checked = np.zeros(self.mass.size, dtype=np.int64)
        self.sensors = BatchSensors(s["noise_density"], s["bias"], s[NOISE_SEED], ts)
        self.law = BatchLaw(config, len(s)) if config is not None else None
        self.panic_until = s["onset"] + s["reaction_time"]
        self.onset = s["onset"]
        self.gain_step = ts / s["driver_time_constant"]
        self.nominal = None if grip else nominal_gain(self.car.v, self.mass)

    def _command(self, steer: np.ndarray, yaw: np.ndarray, speed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The law's command and its status; zero and inactive without a controller."""
        if self.law is None:
            return np.zeros_like(steer), np.zeros(steer.size, dtype=np.int8)
        u = self.law.step(steer, yaw, speed)
        return u, self.law.status

    def run(self, n: int) -> dict[str, np.ndarray]:
        ts, car, rows = self.ts, self.car, self.mass.size
        correction = np.zeros(rows)
        pending = np.zeros(rows)  # the command in flight (one step of loop delay)
        limit = math.radians(ACTUATOR_LIMIT_DEG)
        peaks, magnitude = np.zeros((2, rows)), np.empty((2, rows))  # |beta|, |r|: car.x's first two rows
        peak_u = np.zeros(rows)
        at_limit, faults = np.zeros(rows, dtype=np.int64), np.zeros(rows, dtype=np.int64)
        traces = {k: np.empty((n, rows)) for k in ("r", "beta", "command")} if self.record else {}
        for k0 in range(0, n, BLOCK):
            t_block = np.arange(k0, min(n, k0 + BLOCK), dtype=float)[:, None] * ts
            block = self.loads.block(t_block)
            for j in range(t_block.shape[0]):
                k = k0 + j
                t = k * ts
                r = car.r  # (a view: read before the car advances)
                np.maximum(peaks, np.abs(car.x[:2], out=magnitude), out=peaks)
                # The driver: frozen until panic_until once the event has fired, else correcting.
                steering = (t >= self.panic_until) | (self.onset > t + EVENT_SLACK)
                nominal = self.nominal if self.nominal is not None else nominal_gain(car.v, self.mass)
                correction = np.where(steering, correction - self.gain_step * r / nominal, correction)
                driver = np.maximum(-DRIVER_LIMIT, np.minimum(DRIVER_LIMIT, 0.0 + correction))
                # actuator.Actuator.apply, fresh: its authority limit, then its range
                handled = np.minimum(limit, np.maximum(-limit, self.authority.step(pending, self.checked)))
                yaw = self.sensors.yaw_rate(r)
                u, status = self._command(self.sensors.steer(driver), yaw, self.sensors.speed(car.v))
                np.maximum(peak_u, np.abs(u), out=peak_u)
                at_limit += status == mr.STATUS_SATURATED
                faults += status == mr.STATUS_FAULT
                pending = u
                self.actuator.step(handled)
                applied = self.actuator.mean  # the car gets the position's mean over the step
                if self.record:
                    traces["r"][k], traces["beta"][k], traces["command"][k] = car.r, car.beta, u
                m_z = block["m_z"][j]
                f_y = block["f_y"][j] if block["f_y"] is not None else None
                if self.grip:
                    b = block["b"]
                    tyres = Tyres(b[j if b.shape[0] > 1 else 0], block["d"][j])
                    car.advance(driver + applied, m_z, f_y, block["a_x"][j], tyres, block["mu_max"][j])
                else:
                    car.advance(driver + applied, m_z, f_y, None, None, car.mu)
        return {"peak_yaw_rate": peaks[1], "peak_side_slip": np.degrees(peaks[0]), "time_at_limit": at_limit * ts,
                "fault_steps": faults, "peak_command": np.degrees(peak_u), "final_yaw_rate": car.r.copy(),
                "final_speed": car.v.copy(), **traces}
