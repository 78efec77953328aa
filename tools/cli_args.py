"""Argument types and option groups shared by the ``mrsteer`` subcommands."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Callable

from firmware_py.controller.options import add_calibration_args

MASS_RANGE = (300.0, 10000.0)  # kg accepted for the vehicle's mass


def number(kind: str, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            allow_zero: bool = False) -> Callable[[str], float]:
    """argparse type: a finite float within [lo, hi] (or (lo, hi] with lo_open)."""

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{kind} must be a number, got {text!r}") from None
        if not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"{kind} must be finite, got {text!r}")
        if allow_zero and x == 0.0:
            return x
        below = (x <= lo) if lo_open else (x < lo) if lo is not None else False
        if below or (hi is not None and x > hi):
            left = "(" if lo_open else "["
            raise argparse.ArgumentTypeError(f"{kind} must be in {left}{lo:g}, {hi:g}], got {text}")
        return x

    return parse


def count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
    if not 0 <= n <= 100:
        raise argparse.ArgumentTypeError(f"must be in [0, 100], got {n}")
    return n



def add_gains(p: argparse.ArgumentParser) -> None:
    """--calibration, --k, --tau, --tau-n and --model-delay (firmware_py.controller.options),
    range-checked; the shipped calibration by default."""
    add_calibration_args(p, number=lambda name, lo, hi: number(name, lo, hi, lo_open=True), count=count)


def _model_spec(kind: str, loader: Callable[[str], object]) -> Callable[[str], object]:
    """argparse type: ``ideal``, ``default`` or a TOML file, loaded (every key range-checked)."""

    def parse(text: str) -> object:
        try:
            return loader(text)
        except ValueError as exc:  # ModelFileError: one line naming the file and the key
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = kind  # argparse names the type in its own messages
    return parse


def add_models(p: argparse.ArgumentParser, seed: bool = False) -> None:
    """--actuator and --sensors (ideal by default: the paper's loop), and --seed with ``seed``."""
    from sim_plant.car.actuator_dynamics import ActuatorModelConfig
    from sim_plant.car.sensors import MAX_SEED, SensorConfig

    p.add_argument("--actuator", type=_model_spec("actuator", ActuatorModelConfig.load), default=None,
                   metavar="ideal|default|FILE",
                   help="actuator model in the loop: ideal (default; G_sa = 1 within +-3 deg), default (first "
                   "order, 20 ms, +-3 deg) or a TOML file (docs/realistic-car.md)")
    p.add_argument("--sensors", type=_model_spec("sensors", SensorConfig.load), default=None,
                   metavar="ideal|default|FILE",
                   help="sensor models: ideal (default; exact), default (30 Hz Butterworth on the yaw rate, "
                   "0.014 deg/s/sqrt(Hz) noise, DBC quantisation) or a TOML file")
    if seed:
        p.add_argument("--seed", type=int_in("seed", 0, MAX_SEED), default=None, metavar="N",
                       help="seed of the sensors' noise (default: the sensors config's, 0)")


def int_in(kind: str, lo: int, hi: int) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{kind} must be a whole number, got {text!r}") from None
        if not lo <= n <= hi:
            raise argparse.ArgumentTypeError(f"{kind} must be in [{lo}, {hi}], got {n}")
        return n

    return parse


def loop_models(args: argparse.Namespace) -> object:
    """The ``LoopModels`` the --actuator/--sensors(/--seed) options ask for."""
    from dataclasses import replace

    from sim_plant.car.actuator_dynamics import ActuatorModelConfig
    from sim_plant.car.sensors import SensorConfig
    from sim_plant.offline.loop_plant import LoopModels

    sensors = args.sensors or SensorConfig.ideal()
    if getattr(args, "seed", None) is not None:
        sensors = replace(sensors, seed=args.seed)
    return LoopModels(args.actuator or ActuatorModelConfig.ideal(), sensors)


def say(msg: str) -> None:
    """Progress and notices on stderr, so that stdout stays the command's result."""
    print(msg, file=sys.stderr, flush=True)
