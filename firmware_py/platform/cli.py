"""What every mrsteer command line shares: argument errors in one line with exit status 2, the
SecOC key options, and output paths refused before any work is done."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import NoReturn

EXIT_USAGE = 2


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def add_secoc_args(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--secoc", action="store_true",
                   help="authenticate MRS_AuxSteerCmd and the sensor frames (AUTOSAR SecOC style, AES-CMAC) with the "
                   "128-bit key in $MRSTEER_SECOC_KEY (32 hex digits); both controller and plant must have it")
    g.add_argument("--secoc-key", type=str, metavar="FILE",
                   help="as --secoc, with the key read from FILE (32 hex digits)")


def secoc_key(args: argparse.Namespace, parser: argparse.ArgumentParser | None = None) -> bytes | None:
    """The key the SecOC options ask for, or None.  A bad or missing key is a usage error of
    ``parser``; without one, the ``SecOCError`` (a ValueError) is raised."""
    if not (args.secoc or args.secoc_key):
        return None
    from mrsteer_dbc.secoc import SecOCError, load_key

    try:
        return load_key(args.secoc_key)
    except SecOCError as exc:
        if parser is None:
            raise
        parser.error(str(exc))


SLOW_MOTION_MAX = 100.0


def add_slow_motion_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--slow-motion", type=float, default=1.0, metavar="F",
                   help="run F times slower than real time, for machines too slow for the loop (QEMU without "
                   "KVM): each period lasts F times its step in wall time; the step, every count in cycles "
                   f"and every result are unchanged (default 1, at most {SLOW_MOTION_MAX:g})")


def slow_motion_problem(value: float) -> str | None:
    """What is wrong with a slow-motion factor, or None: the one range check behind every
    ``--slow-motion`` (the nodes' and the fault matrix's)."""
    if math.isfinite(value) and 1.0 <= value <= SLOW_MOTION_MAX:
        return None
    return f"--slow-motion must be in [1, {SLOW_MOTION_MAX:g}], got {value:g}"


def check_slow_motion(parser: argparse.ArgumentParser, value: float) -> None:
    problem = slow_motion_problem(value)
    if problem is not None:
        parser.error(problem)


def slow_motion_suffix(value: float) -> str:
    """The ready line's " in Fx slow motion", empty at real time (the C node prints the same)."""
    return f" in {value:g}x slow motion" if value != 1.0 else ""


def check_output_file(parser: argparse.ArgumentParser, flag: str, path: Path | None) -> None:
    """Refuse, before any work is done, an output file that could not be written."""
    if path is None:
        return
    if path.is_dir():
        parser.error(f"{flag} {path} is a directory")
    parent = path.parent
    if not parent.is_dir():
        parser.error(f"{flag} {path}: {parent} is not an existing directory")
    if not os.access(parent, os.W_OK):
        parser.error(f"{flag} {path}: directory {parent} is not writable")
