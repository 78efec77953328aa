"""What every mrsteer command line shares: every error in one line, ``mrsteer: COMMAND: what``,
with exit status 2 (``error_line``, ``fail``: the one place an error is formatted); an interrupted
command's one line and exit status 130; the SecOC key options; and output paths refused before
any work is done."""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import NoReturn

EXIT_ERROR = 2  # every error: bad input, a bus that cannot be opened, an output that cannot be written
EXIT_USAGE = EXIT_ERROR
EXIT_INTERRUPTED = 130  # Ctrl-C (SIGINT), as a shell reports it: 128 + 2
PREFIX = "mrsteer"


class CommandError(Exception):
    """An error a command reports in one line (``fail``), exit status 2; the message says what
    and, where it helps, what to do instead."""


def command_of(prog: str) -> str:
    """The command a program name stands for, without the leading ``mrsteer``: ``hil run`` for
    ``mrsteer hil run``, ``python -m firmware_py`` as it is, empty for ``mrsteer`` itself."""
    words = prog.split()
    return " ".join(words[1:]) if words[:1] == [PREFIX] else prog


def error_line(prog: str, message: str) -> str:
    """The one line of an error (or a warning: ``message`` starting ``warning:``) of ``prog``:
    ``mrsteer: hil run: --rate-hz 250: ...``."""
    command = command_of(prog)
    return f"{PREFIX}: {command}: {message}" if command else f"{PREFIX}: {message}"


def fail(prog: str, message: str, code: int = EXIT_ERROR) -> int:
    """Print ``error_line`` on stderr and return the exit status (2 unless told)."""
    print(error_line(prog, message), file=sys.stderr, flush=True)
    return code


def warn(prog: str, message: str) -> None:
    """A warning, one line on stderr: the command goes on."""
    print(error_line(prog, f"warning: {message}"), file=sys.stderr, flush=True)


def describe(exc: BaseException) -> str:
    """An exception as the rest of an error line: an OS error as its reason and file name (no
    errno), anything else as its message."""
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    text = str(exc).strip()
    if isinstance(exc, KeyError):  # str() of a KeyError is the repr of its key
        text = f"missing {text}"
    return " ".join(text.split()) or type(exc).__name__  # one line, whatever the message held


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, error_line(self.prog, message) + "\n")


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


#: Set to 1, every long command makes the short run of its ``--quick`` (the test suite runs the
#: README's and the docs' commands so, exactly as they are written: tests/doc_commands.py).
QUICK_ENV = "MRSTEER_QUICK"


def add_quick_arg(p: argparse.ArgumentParser, what: str) -> None:
    """``--quick``: ``what`` the short run does; on by default when ``$MRSTEER_QUICK`` is 1."""
    p.add_argument("--quick", action=argparse.BooleanOptionalAction, default=os.environ.get(QUICK_ENV, "") == "1",
                   help=f"{what} (the default when ${QUICK_ENV} is 1; --no-quick: the full run)")


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


def output_file_problem(flag: str, path: Path) -> str | None:
    """What keeps ``path`` from being written as an output file, or None."""
    if path.is_dir():
        return f"{flag} {path} is a directory"
    parent = path.parent
    if not parent.is_dir():
        return f"{flag} {path}: {parent} is not an existing directory"
    if not os.access(parent, os.W_OK):
        return f"{flag} {path}: directory {parent} is not writable"
    return None


def check_output_file(parser: argparse.ArgumentParser, flag: str, path: Path | None) -> None:
    """Refuse, before any work is done, an output file that could not be written."""
    problem = None if path is None else output_file_problem(flag, path)
    if problem is not None:
        parser.error(problem)


def output_dir_problem(flag: str, path: Path) -> str | None:
    """What keeps ``path`` from being an output directory (made if missing), or None: checked
    before any work, so that a run is not done for nothing."""
    if path.exists():
        if not path.is_dir():
            return f"{flag} {path} exists and is not a directory"
        if not os.access(path, os.W_OK | os.X_OK):
            return f"{flag} {path}: directory is not writable"
        return None
    ancestor = path.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"{flag} {path}: {ancestor} is not a directory"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"{flag} {path}: cannot be created, directory {ancestor} is not writable"
    return None


def check_output_dir(flag: str, path: Path | None) -> None:
    """``output_dir_problem`` as a CommandError (one line, exit 2)."""
    problem = None if path is None else output_dir_problem(flag, path)
    if problem is not None:
        raise CommandError(problem)
