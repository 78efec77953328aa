"""What every mrsteer command shares: argument errors in one line with exit status 2, the
SecOC key options, output files written whole or not at all, and the life of a bus process."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable, Mapping, NoReturn, Sequence

import can

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


_UMASK = os.umask(0)
os.umask(_UMASK)
_FILE_MODE = 0o666 & ~_UMASK  # mkstemp creates 0600; outputs get ordinary permissions


def write_files(directory: Path, files: Mapping[str, str | bytes]) -> list[Path]:
    """Write every file whole, or none of them: each goes to a temporary file in ``directory``
    first, and only when all are written are they renamed into place.  A failure (disk full,
    say) removes the temporary files and leaves the directory as it was."""
    staged: list[tuple[str, str]] = []
    try:
        for name, data in files.items():
            fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{name}.", suffix=".tmp")
            staged.append((name, tmp))
            with os.fdopen(fd, "wb") as f:
                os.fchmod(f.fileno(), _FILE_MODE)
                f.write(data.encode() if isinstance(data, str) else data)
        for name, tmp in staged:
            os.replace(tmp, directory / name)
    except BaseException:
        for _, tmp in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise
    return [directory / name for name in files]


def write_atomic(path: Path, data: str | bytes) -> None:
    """One file, whole or not at all (``write_files``)."""
    write_files(path.parent, {path.name: data})


Outputs = Sequence[tuple[Path | None, Callable[[], str | bytes]]]


def run_node(prog: str, bus: can.BusABC | Sequence[can.BusABC], run: Callable[[], Any], stop: Callable[..., Any],
             outputs: Outputs = (), ready: str | None = None) -> int:
    """The life of a bus process after its bus is open.

    SIGINT and SIGTERM call ``stop`` (the loop ends after its current cycle); ``ready`` is then
    printed on stderr (a supervisor may signal from that moment on); a bus failure is
    one line and exit status 1; the bus (or each of them) is always shut down; then each output whose path was
    given is written whole (``write_atomic``), and one that cannot be is one line and exit 1.
    """
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    if ready is not None:
        print(f"{prog}: {ready}", file=sys.stderr, flush=True)
    code = 0
    try:
        run()
    except can.CanError as exc:
        print(f"{prog}: error: bus failed: {exc}", file=sys.stderr)
        code = 1
    finally:
        for b in [bus] if isinstance(bus, can.BusABC) else bus:
            b.shutdown()
    for path, render in outputs:
        if path is None:
            continue
        try:
            write_atomic(path, render())
        except OSError as exc:
            print(f"{prog}: error: cannot write {path}: {exc.strerror or exc}", file=sys.stderr)
            code = 1
    return code
