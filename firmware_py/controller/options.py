"""Controller options shared by every command that configures the firmware's law.

``--calibration FILE`` (a ``.cfg`` file, ``firmware_py.calibration_file``) replaces the shipped
calibration; ``--k``, ``--tau`` and ``--tau-n`` switch to the paper's plain law with constant
gains (no actuator or filter in the nominal model, and no modelled delay unless
``--model-delay`` says so): that is what gains given by hand, such as the paper's K = 10,
tau = 6 ms, were designed for.

``calibration_for_rate`` is the one check behind every ``--rate-hz`` that runs the firmware
(``mrsteer controller``, ``hil run|demo|evidence``, ``faults run``, ``replay``, ``bench``): a
rate runs only with a calibration made for it, and is refused in the same words everywhere.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import Callable

from firmware_py import calibration_file
from firmware_py.calibration import (DEFAULT_TAU_N, MAX_MODEL_DELAY, PAPER_K, PAPER_TAU, RATE_CALIBRATIONS,
                                     ControllerConfig, describe_gains, plain_law)

__all__ = ["RATES_HELP", "RateError", "add_calibration_args", "calibration_at_rate", "calibration_for_rate", "calibration_from_args",
           "describe_gains", "hand_gains", "model_delay_help"]


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


class RateError(ValueError):
    """A control rate without a calibration made for it."""


def _same_rate(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b))


def _rates(rates: object) -> str:
    text = [f"{r:g}" for r in sorted(rates)]  # type: ignore[call-overload]
    return ", ".join(text[:-1]) + " and " + text[-1] if len(text) > 1 else text[0]


#: What --rate-hz accepts without a calibration given, for the commands' --help.
RATES_HELP = f"{_rates(RATE_CALIBRATIONS)} Hz"


def _where(flag: str, rate_hz: float) -> str:
    return f"{flag} {rate_hz:g}" if flag.startswith("-") else f"{flag} ({rate_hz:g} Hz)"


def _make_one(rate_hz: float) -> str:
    return f"mrsteer design tune --schedule --ts {1.0 / rate_hz:g} --out FILE.cfg"


def calibration_for_rate(rate_hz: float | None, given: ControllerConfig | None = None, hand: bool = False, *,
                         flag: str = "--rate-hz", file_flag: str | None = "--calibration") -> ControllerConfig:
    """The calibration to run at ``rate_hz`` (None: the calibration's own rate), its ``ts`` the
    period; ``RateError`` if there is none for that rate:

    * ``hand``: gains given by hand (``--k/--tau/--tau-n``, the paper's plain law, continuous-time
      gains the user chose): at any rate;
    * ``given`` (a calibration file): at the rate it was made for, 1 / its ``ts``;
    * neither: at a rate of ``RATE_CALIBRATIONS`` (the shipped calibration at 500 Hz).

    ``flag`` names where the rate came from, ``file_flag`` the option that gives a calibration
    file (None: the command has none)."""
    if hand and given is not None:
        return given if rate_hz is None else replace(given, ts=1.0 / rate_hz)
    if given is not None:
        own = 1.0 / given.ts
        if rate_hz is None or _same_rate(rate_hz, own):
            return given
        raise RateError(f"{_where(flag, rate_hz)}: the {file_flag} file is made for {own:g} Hz (ts {given.ts:g} s), "
                        f"not {rate_hz:g} Hz; give one made for {rate_hz:g} Hz ({_make_one(rate_hz)})")
    if rate_hz is None:
        return ControllerConfig()
    for rate, cfg in RATE_CALIBRATIONS.items():
        if _same_rate(rate, rate_hz):
            return cfg
    alternative = f", or give {file_flag} FILE made for {rate_hz:g} Hz ({_make_one(rate_hz)})" if file_flag else ""
    raise RateError(f"{_where(flag, rate_hz)}: no calibration for {rate_hz:g} Hz; there is one for "
                    f"{_rates(RATE_CALIBRATIONS)} Hz{alternative}")


def calibration_at_rate(args: argparse.Namespace, rate_hz: float | None) -> ControllerConfig:
    """``calibration_from_args`` at ``rate_hz`` (``calibration_for_rate``; RateError): a command's
    calibration and, through its ``ts``, its rate."""
    hand = hand_gains(args)
    given = calibration_from_args(args) if hand or getattr(args, "calibration", None) is not None else None
    if given is None and getattr(args, "model_delay", None) is not None:
        # --model-delay alone changes the calibration of the rate, not the rate's choice
        return replace(calibration_for_rate(rate_hz), model_delay_steps=args.model_delay)
    return calibration_for_rate(rate_hz, given, hand)
