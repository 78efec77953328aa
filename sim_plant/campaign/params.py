"""The parameters a campaign sample draws, and the scenario one sample is.

A sample is one row of a ``SampleSet``: a value for every name of ``PARAMETERS`` (a column of
numpy arrays, one entry per sample).  ``scenario_for`` turns a row into the ``car.scenario``
``Scenario`` it stands for: the realistic car (nonlinear tyres, a first-order actuator with
range and rate limit, the yaw-rate sensor's noise, bias, 30 Hz filter and DBC quantisation, its
second element, the second speed), the
driver model with the sample's panic time, and one disturbance at the sample's onset.  That
scenario is what ``campaign export`` writes, what ``hil run --scenario`` plays on the bus, and
what the scalar reference (``reference``) runs; the batch engine (``engine``) runs the same
rows vectorised.

Disturbance kinds (``KINDS``, the codes stored in the ``disturbance`` column):

* ``yaw_moment``: the paper's M_z step of ``yaw_moment`` Nm at the onset;
* ``split_mu_braking``: braking at ``deceleration`` m/s^2 asked, the left wheels on the road's
  ``mu``, the right ones on ``mu_split`` (``disturbances.SplitMuBraking``);
* ``side_wind``: a gust of ``wind_force`` N peak (``disturbances.SideWindGust``);
* ``blowout``: the tyre ``blowout_wheel`` (0 fl, 1 fr, 2 rl, 3 rr) loses its grip
  (``disturbances.TyreBlowout``).

Every kind's own parameters are drawn for every sample (so the design stays one hypercube) and
ignored by the other kinds.

A sample may fault one sensor (issue 18): ``fault_sensor`` (``FAULT_CHANNELS``; ``none`` by
default), ``fault_kind`` (``FAULT_KINDS``: stuck at a value, an offset, a gain, a drift),
``fault_onset`` and ``fault_size``, which ``sensor_fault`` makes the scenario's
``sensor_faults.SensorFault`` (``batch_faults`` has them for the batch).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from sim_plant.car import disturbances as dist
from sim_plant.car.actuator_dynamics import ActuatorModelConfig
from sim_plant.car.scenario import DriverModel, Event, Scenario
from sim_plant.car.sensor_faults import FAULT_SENSORS, SensorFault
from sim_plant.car.sensors import MAX_SEED, SensorConfig, YawRateSensorConfig
from sim_plant.car.vehicle import MAX_MU, PAPER_MASS

KINDS = ("yaw_moment", "split_mu_braking", "side_wind", "blowout")
WHEELS = dist.WHEELS  # blowout_wheel codes 0..3
#: fault_sensor codes: none, then every sensor of sensor_faults.FAULT_SENSORS (the speed, the
#: yaw-rate sensor's second element and the second speed last, as they were added: stored codes
#: keep their meaning)
FAULT_CHANNELS = ("none", *FAULT_SENSORS)
#: fault_kind codes and the sensor_faults kind each one is
FAULT_KINDS = ("stuck", "offset", "gain", "drift")
SCALAR_FAULT_KINDS = ("stuck", "bias", "scale", "drift")
#: the channels whose fault_size is in degrees (the fault's value in rad)
_ANGLES = tuple(FAULT_CHANNELS.index(ch) for ch in ("yaw_rate", "steer", "steer_redundant", "yaw_rate_redundant"))


@dataclass(frozen=True)
class Parameter:
    """One sampled quantity: its unit, the range any distribution must stay in, its default."""

    unit: str
    lo: float
    hi: float
    default: float
    help: str
    choices: tuple[str, ...] = ()  # a categorical parameter: its values by name (stored as codes)


PARAMETERS: dict[str, Parameter] = {
    "v": Parameter("m/s", 5.0, 60.0, 25.0, "speed at the start"),
    "mu": Parameter("", 0.05, MAX_MU, 1.0, "road friction (the left wheels' under split-mu braking)"),
    "mass": Parameter("kg", 900.0, 2500.0, PAPER_MASS, "vehicle mass"),
    "disturbance": Parameter("", 0, len(KINDS) - 1, 0, "disturbance kind", KINDS),
    "onset": Parameter("s", 0.0, 5.0, 0.5, "when the disturbance starts"),
    "yaw_moment": Parameter("Nm", -20000.0, 20000.0, 4000.0, "M_z step (yaw_moment)"),
    "mu_split": Parameter("", 0.05, MAX_MU, 0.2, "friction under the right wheels (split_mu_braking)"),
    "deceleration": Parameter("m/s^2", 0.0, 15.0, 5.0, "deceleration asked (split_mu_braking)"),
    "wind_force": Parameter("N", -20000.0, 20000.0, 1500.0, "peak side force (side_wind)"),
    "blowout_wheel": Parameter("", 0, 3, 0, "the tyre that blows out (blowout)", WHEELS),
    "actuator_tau": Parameter("s", 0.001, 1.0, 0.020, "actuator time constant (first order)"),
    "actuator_rate": Parameter("deg/s", 1.0, math.inf, math.inf, "actuator rate limit (inf: none)"),
    "noise_density": Parameter("deg/s/sqrt(Hz)", 0.0, 10.0, 0.014, "yaw-rate sensor noise density"),
    "bias": Parameter("deg/s", -50.0, 50.0, 0.0, "yaw-rate sensor bias"),
    "reaction_time": Parameter("s", 0.5, 2.0, 1.0, "driver's panic reaction time"),
    "driver_time_constant": Parameter("s", 0.05, 10.0, 0.5, "how slowly the driver's correction converges"),
    "fault_sensor": Parameter("", 0, len(FAULT_CHANNELS) - 1, 0, "the faulted sensor (none: no fault)",
                              FAULT_CHANNELS),
    "fault_kind": Parameter("", 0, len(FAULT_KINDS) - 1, 1, "the sensor fault's kind", FAULT_KINDS),
    "fault_onset": Parameter("s", 0.0, 60.0, 1.0, "when the sensor fault starts"),
    "fault_size": Parameter("", -1000.0, 1000.0, 1.0, "stuck at, offset or drift per s in deg/s (either yaw-rate "
                            "element), m/s^2 (a_y), deg (steering angles) or m/s (either speed); gain: the factor"),
}
#: Columns every SampleSet has besides PARAMETERS: the sample's index and its sensors' noise seed.
INDEX, NOISE_SEED = "index", "noise_seed"


class SampleSet(dict):
    """Columns (name -> 1-D array) of equal length: PARAMETERS, ``index`` and ``noise_seed``."""

    def __len__(self) -> int:  # the number of samples, not of columns
        return int(self[INDEX].size)

    def take(self, rows: np.ndarray) -> "SampleSet":
        return SampleSet({k: v[rows] for k, v in self.items()})

    def row(self, i: int) -> dict[str, float]:
        return {k: v[i].item() for k, v in self.items()}


def noise_seed(campaign_seed: int, index: np.ndarray) -> np.ndarray:
    """The sensors' seed of each sample: from the campaign's seed and the sample's index only."""
    out = np.empty(index.size, dtype=np.int64)
    for j, i in enumerate(index.tolist()):
        out[j] = int(np.random.SeedSequence([campaign_seed, i]).generate_state(1, np.uint64)[0]) & MAX_SEED
    return out


def fault_value(sensor: np.ndarray, kind: np.ndarray, size: np.ndarray) -> np.ndarray:
    """The ``SensorFault.value`` (SI) of each row's fault: ``fault_size`` in rad for an angle's
    stuck value, offset or drift, the factor itself for a gain."""
    angle = np.isin(sensor, _ANGLES) & (kind != FAULT_KINDS.index("gain"))
    return np.where(angle, np.radians(size), size)


def sensor_fault(row: dict[str, float]) -> SensorFault | None:
    """The ``SensorFault`` of one sample (None: ``fault_sensor`` none)."""
    sensor, kind = int(row["fault_sensor"]), int(row["fault_kind"])
    if FAULT_CHANNELS[sensor] == "none":
        return None
    value = float(fault_value(np.array([sensor]), np.array([kind]), np.array([float(row["fault_size"])]))[0])
    return SensorFault(FAULT_CHANNELS[sensor], SCALAR_FAULT_KINDS[kind], float(row["fault_onset"]), value)


def scenario_for(row: dict[str, float], duration: float) -> Scenario:
    """The scenario of one sample (a ``SampleSet.row``) lasting ``duration`` s."""
    kind = KINDS[int(row["disturbance"])]
    onset, mass = float(row["onset"]), float(row["mass"])
    if kind == "yaw_moment":
        event = Event(onset, "yaw_moment", float(row["yaw_moment"]))
    else:
        event = Event(onset, kind, 0.0, load=disturbance_for(row, kind))
    actuator = ActuatorModelConfig(order=1, time_constant_s=float(row["actuator_tau"]),
                                   rate_limit_deg_s=float(row["actuator_rate"]))
    # The yaw-rate sensor's second element: what a scenario file's [yaw_rate_redundant] defaults
    # to (the first's noise and filter, no bias), so that an exported sample reads back equal.
    # The second speed: SensorConfig's default (present, 0.02 m/s of noise), as the bus's car has it.
    yaw = YawRateSensorConfig(noise_density=float(row["noise_density"]), bias_deg_s=float(row["bias"]))
    sensors = SensorConfig(yaw, seed=int(row[NOISE_SEED]), yaw_rate_redundant=replace(yaw, bias_deg_s=0.0))
    return Scenario(name=f"campaign-sample-{int(row[INDEX])}", duration=duration, v=float(row["v"]),
                    mu=float(row["mu"]), mass=mass, events=(event,),
                    driver=DriverModel("model", float(row["reaction_time"]), float(row["driver_time_constant"])),
                    description=f"{kind} at {onset:g} s", plant="nonlinear", actuator=actuator, sensors=sensors,
                    sensor_faults=() if (fault := sensor_fault(row)) is None else (fault,))


def disturbance_for(row: dict[str, float], kind: str) -> object:
    """The ``disturbances`` object of a sample whose kind is a physical disturbance."""
    onset, mass = float(row["onset"]), float(row["mass"])
    if kind == "split_mu_braking":
        return dist.SplitMuBraking(t_start=onset, mu_left=float(row["mu"]), mu_right=float(row["mu_split"]),
                                   deceleration=float(row["deceleration"]), mass=mass)
    if kind == "side_wind":
        return dist.SideWindGust(t_start=onset, peak_force=float(row["wind_force"]))
    return dist.TyreBlowout(t_start=onset, wheel=WHEELS[int(row["blowout_wheel"])], mass=mass)
