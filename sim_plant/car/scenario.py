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
                            # mu = friction, speed = m/s)

Built-ins: ``paper-fig8`` (normalised driver steering step), ``paper-fig9`` (4000 Nm yaw
moment step, wheel held), ``handover`` (yaw moment with the driver model: the controller
acts during the panic reaction time, then the driver takes over).
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

from sim_plant.car.vehicle import MAX_MU, PAPER_MASS, VehicleParams, steering_tf

EVENT_KINDS = ("yaw_moment", "steer", "steer_norm", "mu", "speed")
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
            sc = replace(sc, mass=mass)
        if mz is not None:
            sc = replace(sc, events=tuple(replace(e, value=mz) if e.kind == "yaw_moment" else e for e in sc.events))
        if reaction_time is not None:
            sc = replace(sc, driver=replace(sc.driver, reaction_time=reaction_time))
        _check(sc, sc.name)
        return sc

    @property
    def first_disturbance_time(self) -> float | None:
        times = [e.t for e in self.events if e.kind in ("yaw_moment", "mu")]
        return min(times) if times else None


BUILTINS: dict[str, Scenario] = {
    "paper-fig8": Scenario("paper-fig8", 3.5, v=20.0, mu=1.0, events=(Event(0.5, "steer_norm", 1.0),),
                           description="driver steering step normalised to a unit dry-road yaw rate (Figure 8)"),
    "paper-fig9": Scenario("paper-fig9", 3.5, v=20.0, mu=1.0, events=(Event(0.5, "yaw_moment", 4000.0),),
                           description="4000 Nm yaw moment step, driver's wheel held (Figure 9)"),
    "handover": Scenario("handover", 5.0, v=25.0, mu=1.0, events=(Event(0.5, "yaw_moment", 4000.0),),
                         driver=DriverModel("model", 1.0, 0.5),
                         description="4000 Nm yaw moment; the driver panics for 1 s, then steers back"),
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
        raise ScenarioError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    return parse(data, str(path))


def parse(data: dict[str, Any], where: str) -> Scenario:
    allowed = {"name", "description", "duration", "v", "mu", "mass", "driver", "events"}
    _no_unknown(data, allowed, where)
    if "duration" not in data:
        raise ScenarioError(f"{where}: 'duration' is required")
    driver_data = data.get("driver", {})
    if not isinstance(driver_data, dict):
        raise ScenarioError(f"{where}: [driver] must be a table")
    _no_unknown(driver_data, {"mode", "reaction_time", "time_constant"}, f"{where} [driver]")
    driver = DriverModel(
        mode=str(driver_data.get("mode", "hold")),
        reaction_time=_num(driver_data, "reaction_time", 1.0, f"{where} [driver]"),
        time_constant=_num(driver_data, "time_constant", 0.5, f"{where} [driver]"),
    )
    events = []
    raw_events = data.get("events", [])
    if not isinstance(raw_events, list):
        raise ScenarioError(f"{where}: 'events' must be an array of tables ([[events]])")
    for i, ev in enumerate(raw_events, 1):
        here = f"{where} event {i}"
        if not isinstance(ev, dict):
            raise ScenarioError(f"{here}: must be a table")
        _no_unknown(ev, {"t", *EVENT_KINDS}, here)
        kinds = [k for k in EVENT_KINDS if k in ev]
        if len(kinds) != 1:
            raise ScenarioError(f"{here}: needs 't' and exactly one of {', '.join(EVENT_KINDS)}")
        if "t" not in ev:
            raise ScenarioError(f"{here}: 't' is required")
        events.append(Event(_num(ev, "t", 0.0, here), kinds[0], _num(ev, kinds[0], 0.0, here)))
    sc = Scenario(
        name=str(data.get("name", Path(where).stem)),
        description=str(data.get("description", "")),
        duration=_num(data, "duration", 0.0, where),
        v=_num(data, "v", 20.0, where),
        mu=_num(data, "mu", 1.0, where),
        mass=_num(data, "mass", PAPER_MASS, where),
        events=tuple(sorted(events, key=lambda e: e.t)),
        driver=driver,
    )
    _check(sc, where)
    return sc


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
        return changed

    def driver_angle(self, t: float, yaw_rate: float, dt: float) -> float:
        """The driver's front-wheel angle: the scripted intent plus, in ``model`` mode, a slow
        integrating correction that drives the yaw rate back to what the intent asks for on a
        dry road, frozen during the panic reaction time after each disturbance."""
        if self.sc.driver.mode == "model" and t >= self.panic_until:
            nominal = steering_tf(VehicleParams(v=self.v, mu=1.0, mass=self.sc.mass)).dc_gain()
            error = yaw_rate - nominal * self.steer_intent
            self.correction -= dt / self.sc.driver.time_constant * error / nominal
        angle = self.steer_intent + self.correction
        return max(-0.6, min(0.6, angle))
