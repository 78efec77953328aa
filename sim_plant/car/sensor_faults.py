"""Sensor faults in well-formed frames: a sensor that lies while its frames stay valid (E2E,
SecOC, counters), the errors the plausibility monitor (``firmware_py.plausibility``) must find.

A fault (``SensorFault``) names a ``sensor`` (``yaw_rate``, ``lat_accel``, ``steer``,
``steer_redundant``, ``speed``, ``yaw_rate_redundant``: the yaw-rate sensor's second element,
``speed_redundant``: the second speed), a ``kind``, a ``value`` in the signal's SI unit (rad/s, m/s^2,
rad, m/s) and an onset ``start`` (s; ``stop`` optional, default never).  The kinds:

==========  ================================================================================
stuck       the sensing element is stuck: its input is ``value``, or without one the true
            quantity at onset; the channel's noise, filter and quantisation still act on it
bias        input + ``value``
scale       input * ``value``
drift       input + ``value`` * (t - start): ``value`` is the drift rate per second
noise       input + ``value`` * N(0, 1): ``value`` is an extra RMS, seeded per fault
frozen      the channel's *output* is held at its last value before onset, bit for bit: the
            frames stay well-formed, with advancing alive and freshness counters and valid
            CRC and MAC, and only the value is frozen.  (A replay of the whole frame, counter
            and all, is a bus fault, refused by E2E: the fault bridge's ``replay``.)
==========  ================================================================================

Faults act before the sensor model (``sensors``) so that the filter shapes a bias step as it
would a real one, and so that the values on the bus stay on the DBC's grid.  Parsing is here
too: a scenario's ``[[sensor_fault]]`` tables and the command line's ``--sensor-fault``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from sim_plant.car.model_files import ModelFileError, reject_unknown

FAULT_SENSORS = ("yaw_rate", "lat_accel", "steer", "steer_redundant", "speed", "yaw_rate_redundant",
                 "speed_redundant")
FAULT_KINDS = ("stuck", "bias", "scale", "drift", "noise", "frozen")
#: Kinds whose ``value`` is required (stuck's is optional, frozen has none).
NEEDS_VALUE = ("bias", "scale", "drift", "noise")
MAX_TIME = 600.0


@dataclass(frozen=True)
class SensorFault:
    sensor: str
    kind: str
    start: float = 0.0
    value: float | None = None
    stop: float = math.inf

    def __post_init__(self) -> None:
        where = f"sensor fault {self.sensor}/{self.kind}"
        if self.sensor not in FAULT_SENSORS:
            raise ModelFileError(f"sensor fault: sensor must be one of {', '.join(FAULT_SENSORS)}, got {self.sensor!r}")
        if self.kind not in FAULT_KINDS:
            raise ModelFileError(f"{where}: kind must be one of {', '.join(FAULT_KINDS)}")
        if self.kind in NEEDS_VALUE and self.value is None:
            raise ModelFileError(f"{where}: needs a value")
        if self.kind == "frozen" and self.value is not None:
            raise ModelFileError(f"{where}: takes no value (the output is held at its last value)")
        if self.value is not None and not math.isfinite(self.value):
            raise ModelFileError(f"{where}: value must be finite, got {self.value!r}")
        if self.kind == "noise" and self.value is not None and self.value < 0.0:
            raise ModelFileError(f"{where}: the noise RMS must be >= 0, got {self.value!r}")
        if not (math.isfinite(self.start) and 0.0 <= self.start <= MAX_TIME):
            raise ModelFileError(f"{where}: start must be in [0, {MAX_TIME:g}] s, got {self.start!r}")
        if not self.stop > self.start:
            raise ModelFileError(f"{where}: stop must be after start, got {self.stop!r}")

    def active(self, t: float) -> bool:
        return self.start <= t < self.stop


def _number(data: dict[str, Any], key: str, where: str) -> float | None:
    value = data.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ModelFileError(f"{where}: {key} must be a number, got {value!r}")
    return float(value)


def fault_from_mapping(data: Any, where: str) -> SensorFault:
    """One ``[[sensor_fault]]`` table: ``sensor``, ``kind``, ``start`` (s), optional ``value``
    and ``stop``."""
    if not isinstance(data, dict):
        raise ModelFileError(f"{where}: a sensor fault must be a table")
    reject_unknown(data, {"sensor", "kind", "value", "start", "stop"}, where)
    for key in ("sensor", "kind"):
        if not isinstance(data.get(key), str):
            raise ModelFileError(f"{where}: '{key}' is required (a string)")
    start = _number(data, "start", where)
    stop = _number(data, "stop", where)
    try:
        return SensorFault(data["sensor"], data["kind"], 0.0 if start is None else start, _number(data, "value", where),
                           math.inf if stop is None else stop)
    except ModelFileError as exc:
        raise ModelFileError(f"{where}: {exc}") from None


def faults_from_list(raw: Any, where: str) -> tuple[SensorFault, ...]:
    if not isinstance(raw, list):
        raise ModelFileError(f"{where}: 'sensor_fault' must be an array of tables ([[sensor_fault]])")
    return tuple(fault_from_mapping(item, f"{where} sensor_fault {i}") for i, item in enumerate(raw, 1))


def parse_spec(spec: str) -> SensorFault:
    """``SENSOR:KIND[:VALUE]@START`` (the command line's ``--sensor-fault``), e.g.
    ``yaw_rate:bias:0.05@1.0``, ``steer:frozen@2``, ``yaw_rate:stuck@1.5``."""
    body, at, start = spec.partition("@")
    parts = body.split(":")
    if not at or len(parts) not in (2, 3):
        raise ModelFileError(f"--sensor-fault {spec!r}: expected SENSOR:KIND[:VALUE]@START")
    try:
        value = float(parts[2]) if len(parts) == 3 else None
        onset = float(start)
    except ValueError:
        raise ModelFileError(f"--sensor-fault {spec!r}: VALUE and START must be numbers") from None
    try:
        return SensorFault(parts[0], parts[1], onset, value)
    except ModelFileError as exc:
        raise ModelFileError(f"--sensor-fault {spec!r}: {exc}") from None


class FaultedChannel:
    """The faults of one sensor channel, applied in their order: ``input`` before the sensor
    model, ``output`` after it.  ``rngs``: one Generator per fault (the noise faults use theirs)."""

    def __init__(self, faults: Sequence[SensorFault], rngs: Sequence[np.random.Generator]) -> None:
        self.faults = tuple(faults)
        self.rngs = tuple(rngs)
        self._held_input: list[float | None] = [None] * len(self.faults)
        self._held_output: list[float | None] = [None] * len(self.faults)
        self._last_output: float | None = None

    def input(self, t: float, x: float) -> float:
        for i, f in enumerate(self.faults):
            if f.kind == "frozen" or not f.active(t):
                continue
            if f.kind == "stuck":
                if f.value is not None:
                    x = f.value
                else:
                    if self._held_input[i] is None:
                        self._held_input[i] = x
                    x = self._held_input[i]  # type: ignore[assignment]
            elif f.kind == "bias":
                x = x + f.value  # type: ignore[operator]
            elif f.kind == "scale":
                x = x * f.value  # type: ignore[operator]
            elif f.kind == "drift":
                x = x + f.value * (t - f.start)  # type: ignore[operator]
            elif f.kind == "noise":
                x = x + f.value * float(self.rngs[i].standard_normal())  # type: ignore[operator]
        return x

    def output(self, t: float, y: float) -> float:
        for i, f in enumerate(self.faults):
            if f.kind != "frozen" or not f.active(t):
                continue
            if self._held_output[i] is None:
                # the last value before onset (the first reading if the fault starts at once)
                self._held_output[i] = self._last_output if self._last_output is not None else y
            y = self._held_output[i]  # type: ignore[assignment]
        self._last_output = y
        return y
