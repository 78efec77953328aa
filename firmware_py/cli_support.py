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


def add_secoc_args(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--secoc", action="store_true",
                   help="authenticate MRS_AuxSteerCmd (AUTOSAR SecOC style, AES-CMAC) with the 128-bit key in "
                   "$MRSTEER_SECOC_KEY (32 hex digits); both controller and plant must have it")
    g.add_argument("--secoc-key", type=str, metavar="FILE",
                   help="as --secoc, with the key read from FILE (32 hex digits)")


def secoc_key(args: argparse.Namespace, parser: argparse.ArgumentParser) -> bytes | None:
    """The key the SecOC options ask for, or None; a bad or missing key is a usage error."""
    if not (args.secoc or args.secoc_key):
        return None
    from mrsteer_dbc.secoc import SecOCError, load_key

    try:
        return load_key(args.secoc_key)
    except SecOCError as exc:
        parser.error(str(exc))
