"""Argument types and option groups shared by the ``mrsteer`` subcommands."""

from __future__ import annotations

import argparse
import math
from typing import Callable

from firmware_py import model_regulator as mr
from firmware_py.controller.options import model_delay_help


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
    """--k, --tau, --tau-n and --model-delay, defaulting to the shipped calibration."""
    d = mr.ControllerConfig()
    p.add_argument("--k", type=number("K", 0.0, 1e6, lo_open=True), default=d.k,
                   help=f"eq. (22) gain K (default {d.k:g})")
    p.add_argument("--tau", type=number("tau", 0.0, 10.0, lo_open=True), default=d.tau,
                   help=f"eq. (22) time constant in s (default {d.tau:g})")
    p.add_argument("--tau-n", type=number("tau_n", 0.0, 10.0, lo_open=True), default=d.tau_n,
                   help=f"eq. (18) desired-model time constant in s (default {d.tau_n:g})")
    p.add_argument("--model-delay", type=count, default=None, metavar="M",
                   help=model_delay_help(d.model_delay_steps, mr.MAX_MODEL_DELAY))
