"""Scenarios: timed events for the plant, from TOML files or built in.

A scenario file::

    name = "split-mu-braking"
    description = "yaw moment while braking on a unilaterally icy road"
    duration = 4.0          # s
    v = 25.0                # m/s at the start
    mu = 1.0
    mass = 1296.0           # optional

    [driver]
    mode = "model"          # "hold": the wheel stays where the events put it;
                            # "model": panic reaction, then a slow closed-loop driver steers back
    reaction_time = 1.0     # s, 0.5 .. 2 (the paper's panic reaction time)
    time_constant = 0.5     # s, how slowly the driver's correction converges

    [[events]]
    t = 0.5
    yaw_moment = 4000.0     # Nm step (or: steer = rad of front-wheel angle,
                            # steer_norm = units of the dry-road steady yaw rate (Figure 8),
                            # mu = friction, speed = m/s: set at once, which the
                            # plausibility monitor takes for a speed sensor that jumped)

The realistic car (``docs/realistic-car.md``), every key optional; the defaults are the
paper's ideal plant, so a file without them runs as before::

    plant = "nonlinear"     # "linear" (default): the paper's exact ZOH model (``vehicle``);
                            # "nonlinear": magic-formula tyres, speed a state (``nonlinear``)
    [actuator]              # the keys of an --actuator file (``actuator_dynamics``); absent: ideal
    time_constant_s = 0.020
    [sensors]               # the keys of a --sensors file (``sensors``); absent: ideal
    seed = 1

    [[events]]              # a physical disturbance (``disturbances``) starting at t; its
    t = 0.5                 # parameters in a table, every one optional (the car's mass is the
    split_mu_braking = { mu_left = 1.0, mu_right = 0.2 }   # scenario's): split_mu_braking,
                                                           # side_wind or blowout

Sensor faults in well-formed frames (``sensor_faults``: sensor, kind, value in the signal's SI
unit, onset; optional ``stop``), on any car::

    [[sensor_fault]]
    sensor = "yaw_rate"     # yaw_rate, lat_accel, steer, steer_redundant, speed, yaw_rate_redundant, speed_redundant
    kind = "bias"           # stuck (value optional: the value at onset), bias, scale, drift, noise, frozen
    value = 0.05            # rad/s here
    start = 1.0             # s

The linear plant takes only yaw-moment loads: a physical disturbance (a lateral force, a
deceleration, a change of grip) needs ``plant = "nonlinear"``, and is refused otherwise.

Built-ins: ``paper-fig8`` (normalised driver steering step), ``paper-fig9`` (4000 Nm yaw
moment step, wheel held), ``handover`` (yaw moment with the driver model: the controller
acts during the panic reaction time, then the driver takes over), and on the realistic car
(nonlinear tyres, the default actuator and sensors, the driver model with a 1 s panic time):
``split-mu`` (a panic stop at 25 m/s on mu 1.0 left / 0.2 right), ``side-wind`` (a gust at
30 m/s) and ``blow-out`` (the front-left tyre at 30 m/s); their sizes are argued in
``docs/can-runtime.md``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from sim_plant.car import disturbances as dist
from sim_plant.car.actuator_dynamics import ActuatorModelConfig
from sim_plant.car.model_files import ModelFileError
from sim_plant.car.plants import LINEAR, PLANTS
from sim_plant.car.sensor_faults import SensorFault, faults_from_list
from sim_plant.car.sensors import MAX_SEED, SensorConfig
from sim_plant.car.vehicle import MAX_MU, PAPER_MASS

EVENT_KINDS = ("yaw_moment", "steer", "steer_norm", "mu", "speed")
#: Physical disturbances (``disturbances.KINDS``): an event whose value is a table of parameters.
LOAD_KINDS = tuple(dist.KINDS)
#: Their parameters a scenario may not set: the start is the event's t, the car's data the scenario's.
_FROM_SCENARIO = ("t_start", "mass", "l_f", "l_r")
DRIVER_MODES = ("hold", "model")
REACTION_RANGE = (0.5, 2.0)
SPEED_RANGE = (3.0, 70.0)  # m/s: from the firmware's activation speed to the DBC's speed range
MAX_DURATION = 600.0


class ScenarioError(ValueError):
    """A scenario that cannot be run; the message names the file and the problem."""


@dataclass(frozen=True)
class Event:
    t: float
    kind: str
    value: float
    load: Any = None  # a ``disturbances`` object for a LOAD_KINDS event (value then unused)


@dataclass(frozen=True)
class DriverModel:
    mode: str = "hold"
    reaction_time: float = 1.0
    time_constant: float = 0.5


@dataclass(frozen=True)
class Scenario:
    name: str
    duration: float
    v: float = 20.0
    mu: float = 1.0
    mass: float = PAPER_MASS
    events: tuple[Event, ...] = ()
    driver: DriverModel = field(default_factory=DriverModel)
    description: str = ""
    plant: str = LINEAR
    actuator: ActuatorModelConfig = field(default_factory=ActuatorModelConfig.ideal)
    sensors: SensorConfig = field(default_factory=SensorConfig.ideal)
    sensor_faults: tuple[SensorFault, ...] = ()

    @property
    def sensor_config(self) -> SensorConfig:
        """The sensors with this scenario's sensor faults: what the plant measures with."""
        return replace(self.sensors, faults=self.sensors.faults + self.sensor_faults)

    def with_sensor_faults(self, faults: tuple[SensorFault, ...]) -> "Scenario":
        """The same scenario with ``faults`` added to its own; ScenarioError for one that starts
        at or after the scenario's end (give the duration first), which would never act."""
        for f in faults:
            if f.start >= self.duration:
                raise ScenarioError(f"the sensor fault {f.sensor}:{f.kind}@{f.start:g} starts at or after the run's "
                                    f"end ({self.duration:g} s): it would never act (give --duration, or an "
                                    "earlier START)")
        return replace(self, sensor_faults=self.sensor_faults + tuple(faults))

    def without_sensor_faults(self) -> "Scenario":
        """The same scenario with every sensor healthy: its own faults and its sensor models'
        dropped (a fault-free twin of a run)."""
        return replace(self, sensor_faults=(), sensors=replace(self.sensors, faults=()))

    @property
    def ideal_car(self) -> bool:
        """The paper's car: linear plant, ideal actuator, exact sensors."""
        return self.plant == LINEAR and self.actuator == ActuatorModelConfig.ideal() and self.sensors.exact

    @property
    def disturbances(self) -> tuple[Any, ...]:
        """The physical disturbances of the LOAD_KINDS events, in time order."""
        return tuple(e.load for e in self.events if e.load is not None)

    def with_overrides(self, v: float | None = None, mu: float | None = None, mz: float | None = None,
                       mass: float | None = None, reaction_time: float | None = None,
                       duration: float | None = None) -> "Scenario":
        """The same scenario at another operating point; ``mz`` replaces every yaw-moment step."""
        sc = self
        if duration is not None:
            sc = replace(sc, duration=duration)
        if v is not None:
            sc = replace(sc, v=v)
        if mu is not None:
            sc = replace(sc, mu=mu)
        if mass is not None:
            sc = replace(sc, mass=mass, events=tuple(_with_car(e, mass) for e in sc.events))
        if mz is not None:
            sc = replace(sc, events=tuple(replace(e, value=mz) if e.kind == "yaw_moment" else e for e in sc.events))
        if reaction_time is not None:
            sc = replace(sc, driver=replace(sc.driver, reaction_time=reaction_time))
        _check(sc, sc.name)
        return sc

    def with_models(self, plant: str | None = None, actuator: str | None = None, sensors: str | None = None,
                    seed: int | None = None) -> "Scenario":
        """The same scenario on another car: ``plant`` one of PLANTS, ``actuator`` and ``sensors``
        specs (``ideal``, ``default`` or a TOML file), ``seed`` the sensors' noise seed; ``None``
        keeps the scenario's.  A bad choice is one ScenarioError line."""
        sc = self
        try:
            if plant is not None:
                sc = replace(sc, plant=plant)
            if actuator is not None:
                sc = replace(sc, actuator=ActuatorModelConfig.load(actuator))
            if sensors is not None:
                sc = replace(sc, sensors=SensorConfig.load(sensors))
            if seed is not None:
                if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
                    raise ScenarioError(f"seed must be an integer in [0, {MAX_SEED}], got {seed!r}")
                sc = replace(sc, sensors=replace(sc.sensors, seed=seed))
        except ModelFileError as exc:
            raise ScenarioError(str(exc)) from None
        _check(sc, sc.name)
        return sc

    @property
    def first_disturbance_time(self) -> float | None:
        times = [e.t for e in self.events if e.kind in ("yaw_moment", "mu", *LOAD_KINDS)]
        return min(times) if times else None


def _with_car(e: Event, mass: float) -> Event:
    """A disturbance that depends on the car's mass, for a car of ``mass``."""
    if e.load is None or not hasattr(e.load, "mass"):
        return e
    return replace(e, load=replace(e.load, mass=mass))


def _realistic(name: str, v: float, load: Any, description: str) -> Scenario:
    """A built-in on the realistic car: nonlinear tyres, the default actuator and sensors, the
    driver model with a 1 s panic time, the disturbance at 0.5 s."""
    return Scenario(name, 4.0, v=v, mu=1.0, events=(Event(load.t_start, _KIND_OF[type(load)], 0.0, load=load),),
                    driver=DriverModel("model", 1.0, 0.5), description=description, plant="nonlinear",
                    actuator=ActuatorModelConfig.default(), sensors=SensorConfig.default())


_KIND_OF = {cls: kind for kind, cls in dist.KINDS.items()}
#: The realistic built-ins' sizes (docs/can-runtime.md, "Scenarios", gives the reasoning): a
#: firm stop rather than a panic one, because with the driver frozen for 1 s a full ABS stop on
#: mu 1.0 / 0.2 (3814 Nm) spins this car without the controller (no yaw-moment build-up delay of
#: a real ABS, no load transfer); the gust and the blow-out at their documented defaults.
_REALISTIC = (
    ("split-mu", 25.0, dist.SplitMuBraking(t_start=0.5, mu_left=1.0, mu_right=0.2, deceleration=5.0),
     "firm braking (5 m/s^2 asked) at 25 m/s with mu 1.0 left / 0.2 right; the driver panics for 1 s"),
    ("side-wind", 30.0, dist.SideWindGust(t_start=0.5),
     "a 1500 N side-wind gust (about 15 m/s of crosswind) at 30 m/s; the driver panics for 1 s"),
    ("blow-out", 30.0, dist.TyreBlowout(t_start=0.5),
     "the front-left tyre blows out at 30 m/s; the driver panics for 1 s"),
)

BUILTINS: dict[str, Scenario] = {
    "paper-fig8": Scenario("paper-fig8", 3.5, v=20.0, mu=1.0, events=(Event(0.5, "steer_norm", 1.0),),
                           description="driver steering step normalised to a unit dry-road yaw rate (Figure 8)"),
    "paper-fig9": Scenario("paper-fig9", 3.5, v=20.0, mu=1.0, events=(Event(0.5, "yaw_moment", 4000.0),),
                           description="4000 Nm yaw moment step, driver's wheel held (Figure 9)"),
    "handover": Scenario("handover", 5.0, v=25.0, mu=1.0, events=(Event(0.5, "yaw_moment", 4000.0),),
                         driver=DriverModel("model", 1.0, 0.5),
                         description="4000 Nm yaw moment; the driver panics for 1 s, then steers back"),
    **{sc.name: sc for sc in (_realistic(*spec) for spec in _REALISTIC)},
}


def load(spec: str) -> Scenario:
    """A built-in scenario by name, or a TOML file by path."""
    if spec in BUILTINS:
        return BUILTINS[spec]
    path = Path(spec)
    if not path.exists():
        raise ScenarioError(f"no built-in scenario or file named {spec!r} (built-ins: {', '.join(BUILTINS)})")
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    return parse(data, str(path))


def parse(data: dict[str, Any], where: str) -> Scenario:
    allowed = {"name", "description", "duration", "v", "mu", "mass", "driver", "events", "plant", "actuator",
               "sensors", "sensor_fault"}
    _no_unknown(data, allowed, where)
    if "duration" not in data:
        raise ScenarioError(f"{where}: 'duration' is required")
    driver_data = _table(data, "driver", where)
    _no_unknown(driver_data, {"mode", "reaction_time", "time_constant"}, f"{where} [driver]")
    driver = DriverModel(
        mode=str(driver_data.get("mode", "hold")),
        reaction_time=_num(driver_data, "reaction_time", 1.0, f"{where} [driver]"),
        time_constant=_num(driver_data, "time_constant", 0.5, f"{where} [driver]"),
    )
    mass = _num(data, "mass", PAPER_MASS, where)
    raw_events = data.get("events", [])
    if not isinstance(raw_events, list):
        raise ScenarioError(f"{where}: 'events' must be an array of tables ([[events]])")
    events = [_event(ev, f"{where} event {i}", mass) for i, ev in enumerate(raw_events, 1)]
    plant = data.get("plant", LINEAR)
    if plant not in PLANTS:
        raise ScenarioError(f"{where}: plant must be one of {', '.join(PLANTS)}, got {plant!r}")
    try:
        actuator = (ActuatorModelConfig.from_mapping(_table(data, "actuator", where), f"{where} [actuator]")
                    if "actuator" in data else ActuatorModelConfig.ideal())
        sensors = (SensorConfig.from_mapping(_table(data, "sensors", where), f"{where} [sensors]")
                   if "sensors" in data else SensorConfig.ideal())
        sensor_faults = faults_from_list(data.get("sensor_fault", []), where)
    except ModelFileError as exc:
        raise ScenarioError(str(exc)) from None
    sc = Scenario(
        name=str(data.get("name", Path(where).stem)),
        description=str(data.get("description", "")),
        duration=_num(data, "duration", 0.0, where),
        v=_num(data, "v", 20.0, where),
        mu=_num(data, "mu", 1.0, where),
        mass=mass,
        events=tuple(sorted(events, key=lambda e: e.t)),
        driver=driver,
        plant=plant,
        actuator=actuator,
        sensors=sensors,
        sensor_faults=sensor_faults,
    )
    _check(sc, where)
    return sc


def _event(ev: Any, here: str, mass: float) -> Event:
    """One ``[[events]]`` table: ``t`` and exactly one kind."""
    if not isinstance(ev, dict):
        raise ScenarioError(f"{here}: must be a table")
    _no_unknown(ev, {"t", *EVENT_KINDS, *LOAD_KINDS}, here)
    kinds = [k for k in (*EVENT_KINDS, *LOAD_KINDS) if k in ev]
    if len(kinds) != 1:
        raise ScenarioError(f"{here}: needs 't' and exactly one of {', '.join((*EVENT_KINDS, *LOAD_KINDS))}")
    if "t" not in ev:
        raise ScenarioError(f"{here}: 't' is required")
    t, kind = _num(ev, "t", 0.0, here), kinds[0]
    if kind in EVENT_KINDS:
        return Event(t, kind, _num(ev, kind, 0.0, here))
    return Event(t, kind, 0.0, load=_load(kind, _table(ev, kind, here), t, mass, f"{here} {kind}"))


def _load(kind: str, params: dict[str, Any], t: float, mass: float, where: str) -> Any:
    """The disturbance of ``kind`` starting at t on a car of ``mass``; its own checks, one line."""
    allowed = set(dist.parameter_names(kind)) - set(_FROM_SCENARIO)
    _no_unknown(params, allowed, where)
    for key, value in params.items():
        if key != "wheel" and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise ScenarioError(f"{where}: {key!r} must be a number, got {value!r}")
    car = {"mass": mass} if "mass" in dist.parameter_names(kind) else {}
    try:
        return dist.KINDS[kind](t_start=t, **car, **{k: (v if k == "wheel" else float(v)) for k, v in params.items()})
    except ValueError as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def _table(data: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise ScenarioError(f"{where}: [{key}] must be a table")
    return value


def _no_unknown(data: dict[str, Any], allowed: set[str], where: str) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ScenarioError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")


def _num(data: dict[str, Any], key: str, default: float, where: str) -> float:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"{where}: {key!r} must be a finite number, got {value!r}")
    return float(value)


def _check(sc: Scenario, where: str) -> None:
    if not 0.0 < sc.duration <= MAX_DURATION:
        raise ScenarioError(f"{where}: duration must be in (0, {MAX_DURATION:g}] s, got {sc.duration}")
    for name, value, lo, hi in (("v", sc.v, *SPEED_RANGE), ("mu", sc.mu, 1e-9, MAX_MU), ("mass", sc.mass, 300.0, 1e4)):
        if not lo <= value <= hi:
            raise ScenarioError(f"{where}: {name} must be in [{lo:g}, {hi:g}], got {value}")
    if sc.plant not in PLANTS:
        raise ScenarioError(f"{where}: plant must be one of {', '.join(PLANTS)}, got {sc.plant!r}")
    loads = sorted({e.kind for e in sc.events if e.load is not None})
    if sc.plant == LINEAR and loads:
        raise ScenarioError(f"{where}: the linear plant takes only yaw-moment loads; {', '.join(loads)} "
                            f"needs the nonlinear plant (plant = \"nonlinear\", or --plant nonlinear)")
    if sc.driver.mode not in DRIVER_MODES:
        raise ScenarioError(f"{where}: driver mode must be one of {', '.join(DRIVER_MODES)}, got {sc.driver.mode!r}")
    if not REACTION_RANGE[0] <= sc.driver.reaction_time <= REACTION_RANGE[1]:
        raise ScenarioError(f"{where}: driver reaction_time must be in [0.5, 2] s (the panic reaction time), "
                            f"got {sc.driver.reaction_time}")
    if not 0.05 <= sc.driver.time_constant <= 10.0:
        raise ScenarioError(f"{where}: driver time_constant must be in [0.05, 10] s, got {sc.driver.time_constant}")
    for e in sc.events:
        if not 0.0 <= e.t <= sc.duration:
            raise ScenarioError(f"{where}: event at t={e.t} lies outside [0, duration]")
        if e.kind == "mu" and not 0.0 < e.value <= MAX_MU:
            raise ScenarioError(f"{where}: mu event must be in (0, {MAX_MU:g}], got {e.value}")
        if e.kind == "speed" and not SPEED_RANGE[0] <= e.value <= SPEED_RANGE[1]:
            raise ScenarioError(f"{where}: speed event must be in [{SPEED_RANGE[0]:g}, {SPEED_RANGE[1]:g}] m/s")
        if e.kind == "yaw_moment" and abs(e.value) > 20000.0:
            raise ScenarioError(f"{where}: yaw moment must be within +-20000 Nm, got {e.value}")
        if e.kind in ("steer", "steer_norm") and abs(e.value) > 5.0:
            raise ScenarioError(f"{where}: steer value {e.value} is implausibly large")
