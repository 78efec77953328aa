"""Golden test vectors for ports of the controller (``mrsteer vectors --out DIR``).

For each configuration: ``<config>.cfg``, the calibration and the coefficient table as
``key = value`` lines (trivial to read from C). For each configuration and scenario:
``<config>__<scenario>.csv``, one row per step with the inputs, the command and the whole
state after the step.  Numbers are written with 17 significant digits (``repr``), so a float64
port can compare exactly and a reader gets back the very doubles the Python firmware used;
non-finite inputs are written ``nan``/``inf``/``-inf``.

The inputs come from two kinds of scenario:

* closed loop: the firmware driving the exactly discretised single-track model (section 3
  vehicle) with one sample of loop delay, so the inputs are what a car would send;
* synthetic: hand-made input sequences for the fault, inactivity and recovery paths,
  including NaN, infinities, out-of-range values and speeds below activation.
"""

from __future__ import annotations

import csv
import math
from collections import deque
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Callable, Iterator

from firmware_py import model_regulator as mr
from sim_plant.vehicle import DiscretePlant, VehicleParams

Inputs = tuple[float, float, float]  # driver's front-wheel angle, yaw rate, speed


def _configs() -> dict[str, mr.ControllerConfig]:
    d = mr.ControllerConfig()
    paper = replace(d, k=mr.PAPER_K, tau=mr.PAPER_TAU, ts=0.001, model_delay_steps=0)
    return {
        "shipped_500hz": d,
        "paper_limited_1khz": paper,
        "paper_standard_1khz": replace(paper, q_form=mr.Q_STANDARD),
        "limited_zoh_200hz_m1": replace(d, k=8.0, tau=0.03, ts=0.005, method=mr.METHOD_ZOH, model_delay_steps=1),
        "limited_100hz_m2_ratelimit": replace(d, k=4.0, tau=0.02, ts=0.01, model_delay_steps=2,
                                              rate_limit=math.radians(20.0)),
    }


CONFIGS = _configs()


def _closed_loop(cfg: mr.ControllerConfig, params: VehicleParams, duration: float,
                 m_z: Callable[[float], float], driver: Callable[[float], float]) -> Iterator[Inputs]:
    """Inputs the firmware sees while it drives the car (one sample of loop delay)."""
    plant = DiscretePlant(params, cfg.ts)
    c = mr.configure(cfg)
    s = mr.State()
    pipe: deque[float] = deque([0.0])
    for k in range(int(round(duration / cfg.ts)) + 1):
        t = k * cfg.ts
        dd = driver(t)
        r = float(plant.x[1])
        yield dd, r, params.v
        pipe.append(mr.step(c, s, dd, r, params.v))
        plant.advance(dd + pipe.popleft(), m_z(t))


def _synthetic_faults(cfg: mr.ControllerConfig) -> Iterator[Inputs]:
    """Every fault and inactivity path, each followed by recovery."""
    n = max(1, int(round(0.05 / cfg.ts)))  # 50 ms per phase

    def phase(count: int, f: Callable[[int], Inputs]) -> Iterator[Inputs]:
        for i in range(count):
            yield f(i)

    yield from phase(n, lambda i: (0.0, 0.0, 20.0))  # power-on, then active at rest
    yield from phase(4 * n, lambda i: (0.01, 0.3 * math.sin(0.2 * i), 20.0))  # active, saturating
    yield from phase(n, lambda i: (0.01, math.nan, 20.0))  # yaw rate NaN: fault, fade
    yield from phase(4 * n, lambda i: (0.01, 0.05, 20.0))  # recovery, slewing back
    yield from phase(n, lambda i: (0.9, 0.05, 20.0))  # driver angle out of range
    yield from phase(2 * n, lambda i: (0.0, 0.05, 20.0))
    yield from phase(n, lambda i: (0.0, 0.05, math.inf))  # speed infinite
    yield from phase(2 * n, lambda i: (0.0, 0.05, 20.0))
    yield from phase(n, lambda i: (0.0, -math.inf, -1.0))  # two faults at once
    yield from phase(2 * n, lambda i: (0.0, -0.05, 20.0))
    yield from phase(2 * n, lambda i: (0.0, -0.05, 20.0 - 9.0 * i / n))  # decelerating to 2 m/s: inactive
    yield from phase(n, lambda i: (0.0, -0.05, 2.0))  # inactive
    yield from phase(4 * n, lambda i: (0.0, -0.05, 2.0 + 8.0 * i / (4 * n)))  # accelerating again
    yield from phase(n, lambda i: (-0.02, 3.5, 10.0))  # yaw rate beyond +-3 rad/s


SCENARIOS: dict[str, Callable[[mr.ControllerConfig], Iterator[Inputs]]] = {
    "yaw_moment_step": lambda cfg: _closed_loop(cfg, VehicleParams(v=20.0, mu=1.0), 1.0,
                                                lambda t: 4000.0 if t >= 0.1 else 0.0, lambda t: 0.0),
    "saturating_low_mu": lambda cfg: _closed_loop(cfg, VehicleParams(v=30.0, mu=0.3, mass=1700.0), 1.0,
                                                  lambda t: 6000.0 if 0.1 <= t < 0.6 else 0.0, lambda t: 0.0),
    "driver_steer": lambda cfg: _closed_loop(cfg, VehicleParams(v=15.0, mu=0.8), 1.0, lambda t: 0.0,
                                             lambda t: 0.02 * min(1.0, max(0.0, (t - 0.1) / 0.2))),
    "faults_and_recovery": _synthetic_faults,
}

STATE_COLUMNS = ("z", "u_prev", *(f"u_hist{i}" for i in range(mr.MAX_MODEL_DELAY)), "hist_idx", "needs_init",
                 "recovering", "status", "fault_flags")
COLUMNS = ("k", "delta_driver", "yaw_rate", "speed", "u", *STATE_COLUMNS)


def _num(x: float) -> str:
    return repr(float(x))  # 17 significant digits; 'nan', 'inf', '-inf'


def state_row(s: mr.State) -> list[str]:
    return [_num(s.z), _num(s.u_prev), *(_num(x) for x in s.u_hist), str(s.hist_idx), str(int(s.needs_init)),
            str(int(s.recovering)), str(s.status), str(s.fault_flags)]


def _val(x: object) -> str:
    if isinstance(x, bool):
        return str(int(x))
    if isinstance(x, float):
        return _num(x)
    return str(x)


def config_lines(cfg: mr.ControllerConfig) -> list[str]:
    c = mr.configure(cfg)
    return ["# calibration (ControllerConfig)", *(f"{f.name} = {_val(getattr(cfg, f.name))}" for f in fields(cfg)),
            "# coefficients (configure())", *(f"c.{f.name} = {_val(getattr(c, f.name))}" for f in fields(c))]


@dataclass(frozen=True)
class VectorSet:
    config: str
    scenario: str
    rows: int


def write_all(out: Path, progress: Callable[[str], None] | None = None) -> list[VectorSet]:
    """Write every configuration's .cfg and every (configuration, scenario) .csv into ``out``."""
    say = progress or (lambda m: None)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, cfg in CONFIGS.items():
        _atomic_write(out / f"{name}.cfg", "\n".join(config_lines(cfg)) + "\n")
        for scen, make in SCENARIOS.items():
            c, s = mr.configure(cfg), mr.State()
            rows = []
            for k, (dd, r, v) in enumerate(make(cfg)):
                u = mr.step(c, s, dd, r, v)
                rows.append([str(k), _num(dd), _num(r), _num(v), _num(u), *state_row(s)])
            path = out / f"{name}__{scen}.csv"
            tmp = path.with_suffix(".csv.tmp")
            with tmp.open("w", newline="") as f:
                w = csv.writer(f, lineterminator="\n")
                w.writerow(COLUMNS)
                w.writerows(rows)
            tmp.replace(path)
            written.append(VectorSet(name, scen, len(rows)))
            say(f"{path.name}: {len(rows)} steps")
    return written


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)


def read_config(path: Path) -> mr.ControllerConfig:
    """The calibration back from a .cfg file (the coefficient lines are ignored)."""
    values: dict[str, object] = {}
    types = {f.name: f.type for f in fields(mr.ControllerConfig)}
    for line in path.read_text().splitlines():
        if not line or line.startswith("#") or line.startswith("c."):
            continue
        key, _, text = (p.strip() for p in line.partition("="))
        kind = types[key]
        values[key] = text if kind == "str" else int(text) if kind == "int" else float(text)
    return mr.ControllerConfig(**values)  # type: ignore[arg-type]
