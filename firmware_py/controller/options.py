"""Controller options shared by every command that configures the firmware's law."""

from __future__ import annotations

import argparse

from firmware_py.model_regulator import ControllerConfig


def model_delay_help(default_steps: int, max_steps: int) -> str:
    return (f"command delay modelled inside the controller, 0..{max_steps} (default: {default_steps} with the "
            "shipped K, tau and tau_n; 0, the paper's structure, when any of them is given)")


def resolve_model_delay(args: argparse.Namespace) -> None:
    """Fill ``args.model_delay`` when it was not given: the shipped calibration models one
    sample of loop delay, but gains given by hand (the paper's K = 10, tau = 6 ms, say) mean
    the plain law they were designed for."""
    if getattr(args, "model_delay", 0) is not None or not hasattr(args, "k"):
        return
    d = ControllerConfig()
    shipped = (args.k, args.tau, args.tau_n) == (d.k, d.tau, d.tau_n)
    args.model_delay = d.model_delay_steps if shipped else 0
