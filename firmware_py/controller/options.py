"""Controller options shared by every command that configures the firmware's law.

``--calibration FILE`` (a ``.cfg`` file, ``firmware_py.calibration_file``) replaces the shipped
calibration; ``--k``, ``--tau`` and ``--tau-n`` switch to the paper's plain law with constant
gains (no actuator or filter in the nominal model, and no modelled delay unless
``--model-delay`` says so): that is what gains given by hand, such as the paper's K = 10,
tau = 6 ms, were designed for.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import Callable

from firmware_py import calibration_file
from firmware_py.calibration import (DEFAULT_TAU_N, MAX_MODEL_DELAY, PAPER_K, PAPER_TAU, ControllerConfig,
                                     describe_gains, plain_law)

__all__ = ["add_calibration_args", "calibration_from_args", "describe_gains", "hand_gains", "model_delay_help"]


def model_delay_help(default_steps: int, max_steps: int) -> str:
    return (f"command delay modelled inside the controller, 0..{max_steps} (default: {default_steps} with the "
            "shipped or a --calibration file's law; 0, the paper's structure, when --k, --tau or --tau-n is given)")


def _calibration_file(text: str) -> ControllerConfig:
    try:
        return calibration_file.load(Path(text))
    except calibration_file.CalibrationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_calibration_args(p: argparse.ArgumentParser, number: Callable[[str, float, float], Callable[[str], float]]
                         | None = None, count: Callable[[str], int] | None = None) -> None:
    """--calibration, --k, --tau, --tau-n and --model-delay.  ``number(name, lo, hi)`` and
    ``count`` are argparse types that range-check (plain float and int when not given)."""
    d = ControllerConfig()

    def num(name: str, hi: float) -> Callable[[str], float]:
        return number(name, 0.0, hi) if number is not None else float

    p.add_argument("--calibration", type=_calibration_file, default=None, metavar="FILE",
                   help="calibration file (key = value lines, docs/porting.md; default: the shipped "
                   "speed-scheduled calibration)")
    p.add_argument("--k", type=num("K", 1e6), default=None,
                   help=f"constant eq. (22) gain K of the paper's plain law (e.g. the paper's {PAPER_K:g})")
    p.add_argument("--tau", type=num("tau", 10.0), default=None,
                   help=f"constant eq. (22) time constant in s (with --k; default {PAPER_TAU:g})")
    p.add_argument("--tau-n", type=num("tau_n", 10.0), default=None,
                   help=f"constant eq. (18) desired-model time constant in s (with --k; default {DEFAULT_TAU_N:g})")
    p.add_argument("--model-delay", type=count or int, default=None, metavar="M",
                   help=model_delay_help(d.model_delay_steps, MAX_MODEL_DELAY))


def hand_gains(args: argparse.Namespace) -> bool:
    return any(getattr(args, name, None) is not None for name in ("k", "tau", "tau_n"))


def calibration_from_args(args: argparse.Namespace) -> ControllerConfig:
    """The calibration the options describe (not yet validated: ``configure()`` does that)."""
    cfg = getattr(args, "calibration", None) or ControllerConfig()
    m = getattr(args, "model_delay", None)
    if hand_gains(args):
        cfg = plain_law(cfg, args.k if args.k is not None else PAPER_K,
                        args.tau if args.tau is not None else PAPER_TAU,
                        args.tau_n if args.tau_n is not None else DEFAULT_TAU_N)
        cfg = replace(cfg, model_delay_steps=m if m is not None else 0)
    elif m is not None:
        cfg = replace(cfg, model_delay_steps=m)
    return cfg
