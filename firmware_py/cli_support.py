"""Argument parsing shared by every mrsteer command: one-line errors and exit status 2."""

from __future__ import annotations

import argparse
from typing import NoReturn

EXIT_USAGE = 2


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def model_delay_help(default_steps: int, max_steps: int) -> str:
    return (f"command delay modelled inside the controller, 0..{max_steps} (default: {default_steps} with the "
            "shipped K, tau and tau_n; 0, the paper's structure, when any of them is given)")


def resolve_model_delay(args: argparse.Namespace) -> None:
    """Fill ``args.model_delay`` when it was not given: the shipped calibration models one
    sample of loop delay, but gains given by hand (the paper's K = 10, tau = 6 ms, say) mean
    the plain law they were designed for."""
    if getattr(args, "model_delay", 0) is not None or not hasattr(args, "k"):
        return
    from firmware_py.model_regulator import ControllerConfig

    d = ControllerConfig()
    shipped = (args.k, args.tau, args.tau_n) == (d.k, d.tau, d.tau_n)
    args.model_delay = d.model_delay_steps if shipped else 0
