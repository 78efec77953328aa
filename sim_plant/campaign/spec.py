"""A campaign file (TOML): what to sample, how many, which calibrations, and what passes.

::

    name = "example"
    samples = 100000           # scenarios per calibration
    seed = 2026                # the design and every sample's sensor noise follow from it
    sampling = "lhs"           # "lhs" (Latin hypercube, scipy.stats.qmc) or "random"
    duration = 5.0             # s of each scenario
    chunk = 16384              # samples per task and per Parquet file
    calibrations = ["shipped", "paper"]   # shipped, paper, previous, none, or a .cfg file

    [parameters]               # every key of params.PARAMETERS; an absent one keeps its default
    v = { uniform = [5.0, 40.0] }
    noise_density = { loguniform = [0.005, 0.05] }
    disturbance = { choice = ["yaw_moment", "side_wind"] }
    mass = 1296.0              # a number: fixed
    fault_sensor = { choice = ["none", "yaw_rate", "lat_accel"] }   # sensor faults (issue 18)
    fault_kind = { choice = ["offset", "drift"] }
    fault_onset = { uniform = [1.0, 3.0] }
    fault_size = { uniform = [-3.0, 3.0] }   # deg/s, m/s^2, deg/s per s ...

    [criteria]                 # a sample passes when every figure is at or below its bound
    peak_yaw_rate = 0.5        # rad/s
    peak_side_slip = 6.0       # deg
    time_at_limit = 1.0        # s
    false_alarms = 0           # steps the monitor alarmed before any sensor fault
    detection_time = 0.3       # s from the fault's error leaving its bound to the report

Every error is one ``SpecError`` line naming the file and the key.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from firmware_py import calibration_file
from firmware_py import model_regulator as mr
from sim_plant.campaign.engine import METRICS
from sim_plant.campaign.params import PARAMETERS, Parameter

SAMPLINGS = ("lhs", "random")
DISTRIBUTIONS = ("uniform", "loguniform", "choice")
NAMED_CALIBRATIONS = ("shipped", "paper", "previous", "none")
CRITERIA = ("peak_yaw_rate", "peak_side_slip", "time_at_limit", "fault_steps", "false_alarms", "detection_time",
            "fault_yaw_rate", "twin_yaw_rate")
#: the parameters of a sensor fault besides fault_sensor (meaningless while it is always none)
FAULT_PARAMETERS = ("fault_kind", "fault_onset", "fault_size")
MAX_SAMPLES = 10**8
TS = 0.002  # the firmware's step; a campaign runs at its calibrations' step


class SpecError(ValueError):
    """A campaign file that cannot be run; one line naming the file and the key."""


@dataclass(frozen=True)
class Distribution:
    """How one parameter is drawn: ``fixed`` (``values[0]``), uniform, loguniform or choice."""

    kind: str
    values: tuple[float, ...]


@dataclass(frozen=True)
class Campaign:
    name: str
    samples: int
    seed: int
    sampling: str
    duration: float
    chunk: int
    calibrations: tuple[str, ...]
    parameters: dict[str, Distribution]
    criteria: dict[str, float]
    text: str  # the file as read: kept beside the results, and its hash names the campaign

    @property
    def digest(self) -> str:
        return hashlib.sha256(self.text.encode()).hexdigest()[:16]

    @property
    def sampled(self) -> tuple[str, ...]:
        """The parameters drawn (not fixed), in PARAMETERS order: the design's dimensions."""
        return tuple(k for k, d in self.parameters.items() if d.kind != "fixed")

    @property
    def chunks(self) -> int:
        return -(-self.samples // self.chunk)


def load(path: Path) -> Campaign:
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    return parse(text, str(path))


def parse(text: str, where: str) -> Campaign:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{where}: not valid TOML: {str(exc).splitlines()[0]}") from None
    allowed = {"name", "samples", "seed", "sampling", "duration", "chunk", "calibrations", "parameters", "criteria"}
    _no_unknown(data, allowed, where)
    samples = _int(data, "samples", None, 1, MAX_SAMPLES, where)
    sampling = data.get("sampling", "lhs")
    if sampling not in SAMPLINGS:
        raise SpecError(f"{where}: 'sampling' must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")
    duration = data.get("duration", 5.0)
    if isinstance(duration, bool) or not isinstance(duration, int | float) or not 0.0 < duration <= 60.0:
        raise SpecError(f"{where}: 'duration' must be a number of seconds in (0, 60], got {duration!r}")
    cals = data.get("calibrations", ["shipped"])
    if not (isinstance(cals, list) and cals and all(isinstance(c, str) for c in cals)) or len(set(cals)) != len(cals):
        raise SpecError(f"{where}: 'calibrations' must be a list of distinct names ({', '.join(NAMED_CALIBRATIONS)}) "
                        f"or .cfg files, got {cals!r}")
    base = Path(where).parent
    for c in cals:
        calibration(c, base, where)  # each one must load
    params = _table(data, "parameters", where)
    _no_unknown(params, set(PARAMETERS), f"{where} [parameters]")
    dists = {k: _distribution(params[k], k, p, f"{where} [parameters]") if k in params
             else Distribution("fixed", (p.default,)) for k, p in PARAMETERS.items()}
    no_faults = dists["fault_sensor"].kind == "fixed" and dists["fault_sensor"].values[0] == 0.0
    for key in ("onset",) if no_faults else ("onset", "fault_onset"):
        onset = dists[key].values[-1]
        if onset > duration:
            raise SpecError(f"{where} [parameters]: {key!r} reaches {onset:g} s, after the end of the run "
                            f"({duration:g} s)")
    _check_faults(params, dists, f"{where} [parameters]")
    crit = _table(data, "criteria", where)
    _no_unknown(crit, set(CRITERIA), f"{where} [criteria]")
    criteria = {}
    for k, v in crit.items():
        if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and v >= 0):
            raise SpecError(f"{where} [criteria]: {k!r} must be a number >= 0 ({METRICS[k][0] or 'steps'}), got {v!r}")
        criteria[k] = float(v)
    name = data.get("name", Path(where).stem)
    if not isinstance(name, str) or not name:
        raise SpecError(f"{where}: 'name' must be a non-empty string")
    return Campaign(name, samples, _int(data, "seed", 0, 0, 2**63 - 1, where), sampling, float(duration),
                    _int(data, "chunk", 16384, 1, 10**6, where), tuple(cals), dists, criteria, text)


def _check_faults(given: dict[str, Any], dists: dict[str, Distribution], where: str) -> None:
    """A fault's kind, onset or size given while no sample can have a fault is a mistake."""
    sensor = dists["fault_sensor"]
    if sensor.kind == "fixed" and sensor.values[0] == 0.0:  # (the code of "none")
        named = [k for k in FAULT_PARAMETERS if k in given]
        if named:
            raise SpecError(f"{where}: {named[0]!r} is given but 'fault_sensor' is none: no sample has a sensor "
                            f"fault (give fault_sensor a sensor or a choice)")


def calibration(name: str, base: Path = Path("."), where: str = "campaign") -> mr.ControllerConfig | None:
    """The controller configuration a calibration name stands for (None: no controller).

    ``paper`` is the paper's K = 10, tau = 6 ms as a plain law (no nominal actuator or filter)
    at the firmware's 500 Hz with one modelled sample; ``previous`` the calibration shipped
    before issue 15's scheduled law."""
    if name == "none":
        return None
    if name == "shipped":
        return mr.ControllerConfig()
    if name == "paper":
        return mr.plain_law(mr.ControllerConfig(), mr.PAPER_K, mr.PAPER_TAU, mr.DEFAULT_TAU_N)
    if name == "previous":
        return mr.PREVIOUS_CONFIG
    path = Path(name) if Path(name).is_absolute() else base / name
    if path.suffix != ".cfg" or not path.is_file():
        raise SpecError(f"{where}: calibration {name!r} is none of {', '.join(NAMED_CALIBRATIONS)} nor a .cfg file")
    try:
        cfg = calibration_file.load(path)
        mr.configure(cfg)
    except (KeyError, ValueError, OSError) as exc:
        raise SpecError(f"{where}: calibration {name!r}: {str(exc).splitlines()[0]}") from None
    if abs(cfg.ts - TS) > 1e-15:
        raise SpecError(f"{where}: calibration {name!r} runs at ts {cfg.ts:g} s; campaigns run at {TS:g} s")
    return cfg


def _distribution(value: Any, key: str, p: Parameter, where: str) -> Distribution:
    if p.choices:
        return _categorical(value, key, p, where)
    if isinstance(value, int | float) and not isinstance(value, bool):
        _within(float(value), key, p, where)
        return Distribution("fixed", (float(value),))
    if not (isinstance(value, dict) and len(value) == 1 and next(iter(value)) in ("uniform", "loguniform")):
        raise SpecError(f"{where}: {key!r} must be a number, {{ uniform = [lo, hi] }} or {{ loguniform = [lo, hi] }}")
    kind, bounds = next(iter(value.items()))
    if not (isinstance(bounds, list) and len(bounds) == 2 and all(
            isinstance(b, int | float) and not isinstance(b, bool) and math.isfinite(b) for b in bounds)
            and bounds[0] < bounds[1]):
        raise SpecError(f"{where}: {key!r}: {kind} needs [lo, hi] with lo < hi, got {bounds!r}")
    lo, hi = float(bounds[0]), float(bounds[1])
    _within(lo, key, p, where)
    _within(hi, key, p, where)
    if kind == "loguniform" and lo <= 0.0:
        raise SpecError(f"{where}: {key!r}: loguniform needs lo > 0, got {lo:g}")
    return Distribution(kind, (lo, hi))


def _categorical(value: Any, key: str, p: Parameter, where: str) -> Distribution:
    names = list(value["choice"]) if isinstance(value, dict) and list(value) == ["choice"] and isinstance(
        value["choice"], list) else [value] if isinstance(value, str) else None
    if not names or any(n not in p.choices for n in names) or len(set(names)) != len(names):
        raise SpecError(f"{where}: {key!r} must be one of {', '.join(p.choices)} or {{ choice = [...] }} of "
                        f"distinct ones, got {value!r}")
    codes = tuple(float(p.choices.index(n)) for n in names)
    return Distribution("fixed", codes) if len(codes) == 1 else Distribution("choice", codes)


def _within(x: float, key: str, p: Parameter, where: str) -> None:
    if not (p.lo <= x <= p.hi) or math.isnan(x):
        raise SpecError(f"{where}: {key!r} must lie in [{p.lo:g}, {p.hi:g}] {p.unit}".rstrip() + f", got {x:g}")


def _int(data: dict[str, Any], key: str, default: int | None, lo: int, hi: int, where: str) -> int:
    if key not in data and default is None:
        raise SpecError(f"{where}: {key!r} is required")
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise SpecError(f"{where}: {key!r} must be a whole number in [{lo}, {hi}], got {value!r}")
    return value


def _table(data: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise SpecError(f"{where}: [{key}] must be a table")
    return value


def _no_unknown(data: dict[str, Any], allowed: set[str], where: str) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise SpecError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")
