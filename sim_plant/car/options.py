"""The command-line options that choose the car a plant plays (``mrsteer plant``, ``hil run``,
``faults run``) and the sensor faults it carries (``plant``, ``hil run``): one definition, so
that every command names and checks them alike."""

from __future__ import annotations

import argparse

from sim_plant.car.plants import PLANTS
from sim_plant.car.sensors import MAX_SEED


def seed(text: str) -> int:
    """A noise seed: an integer in [0, MAX_SEED]."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if not 0 <= n <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be in [0, {MAX_SEED}], got {n}")
    return n


def add_car_args(p: argparse.ArgumentParser, default: str = "the scenario's", with_seed: bool = True) -> None:
    """``--plant``, ``--actuator``, ``--sensors`` (and ``--seed``); each overrides what the
    scenario names, and ``default`` says what applies when neither names one."""
    p.add_argument("--plant", choices=PLANTS,
                   help=f"the car: linear (the paper's exact model) or nonlinear (magic-formula tyres); "
                   f"default: {default}")
    p.add_argument("--actuator", metavar="ideal|default|FILE",
                   help="the actuator's position model: ideal (applies the command at once), default (first order, "
                   f"20 ms, +-3 deg) or a TOML file (docs/realistic-car.md); default: {default}")
    p.add_argument("--sensors", metavar="ideal|default|FILE",
                   help="the sensor models: ideal (exact), default (yaw-rate noise, 30 Hz low-pass, DBC quantisation) "
                   f"or a TOML file (docs/realistic-car.md); default: {default}")
    if with_seed:
        p.add_argument("--seed", type=seed, metavar="N", help=f"the sensors' noise seed; default: {default}")


def add_sensor_fault_arg(p: argparse.ArgumentParser) -> None:
    """``--sensor-fault SPEC`` (repeatable; ``sim_plant.car.sensor_faults.parse_spec``)."""
    p.add_argument("--sensor-fault", action="append", default=[], metavar="SENSOR:KIND[:VALUE]@START",
                   help="a sensor fault in well-formed frames, added to the scenario's [[sensor_fault]] tables "
                   "(repeatable): SENSOR yaw_rate, lat_accel, steer, steer_redundant, speed, "
                   "yaw_rate_redundant (the yaw-rate sensor's second element) or speed_redundant (the "
                   "second speed); KIND stuck (VALUE "
                   "optional: else the value at onset), bias, scale, drift (VALUE per s), noise (VALUE RMS) or "
                   "frozen (no VALUE); VALUE in the signal's SI unit; START in s, e.g. yaw_rate:bias:0.05@1.0")
