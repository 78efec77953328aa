"""The candump ``-L`` log format, written by the bus logger and read by the HIL report and the
fault matrix: one frame a line, ``(1700000000.123456) vcan0 101#0011AA``.

Reading goes through python-can's ``can.CanutilsLogReader``: it parses this format as written
(the timestamp from its own text, so to the microsecond; extended IDs by their 8 digits; CAN FD
``##``; remote ``#R``) and also what the real ``candump -L`` writes.  Every line either writes
ends with a newline: a last line without one was cut off (a logger killed mid-write, a copy cut
short), and is left out with one warning naming it; the frames before it are read.

Writing does not use ``can.CanutilsLogWriter``, which writes another file than ``candump -L``
and than ``traffic.log`` always was: it appends the direction (`` R``/`` T``) to every line,
writes a frame whose timestamp is older than the previous one with the previous one's (the
log would no longer show when a frame really came), and names the message's own channel
rather than the one the logger was told to write (``--iface-name``; the fault matrix names its
two buses ``vehicle`` and ``controller``).  ``cantools decode`` reads what ``format_line``
writes, byte for byte the same as the real ``candump -L``.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path
from typing import Callable, NamedTuple

import can

from firmware_py.platform.cli import error_line


class Frame(NamedTuple):
    """One logged frame: when it was on the bus (epoch s), its ID and its payload."""

    t: float
    frame_id: int
    data: bytes


def format_line(msg: can.Message, iface: str) -> str:
    """One line of ``candump -L``: extended IDs in 8 hex digits, standard in 3."""
    ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
    if msg.is_remote_frame:
        body = f"{ident}#R"
    elif msg.is_fd:
        flags = (1 if msg.bitrate_switch else 0) | (2 if msg.error_state_indicator else 0)
        body = f"{ident}##{flags:X}{bytes(msg.data).hex().upper()}"
    else:
        body = f"{ident}#{bytes(msg.data).hex().upper()}"
    return f"({msg.timestamp:.6f}) {iface} {body}\n"


Warn = Callable[[str], None]


def read_candump(path: Path, warn: Warn | None = None) -> list[Frame]:
    """Every frame of a candump ``-L`` log, in the order logged (a remote frame with no data);
    a cut-off last line is left out (``read_candump_messages``)."""
    return [Frame(msg.timestamp, msg.arbitration_id, bytes(msg.data)) for _, msg in read_candump_messages(path, warn)]


class LogError(ValueError):
    """A file that is not a candump ``-L`` log; the message names the line."""


def _warn(message: str) -> None:
    print(error_line("mrsteer", f"warning: {message}"), file=sys.stderr, flush=True)


def read_candump_messages(path: Path, warn: Warn | None = None) -> list[tuple[int, can.Message]]:
    """Every frame of a candump ``-L`` log with its line number (from 1), in the order logged.

    A last line without its newline was cut off: it is left out, and ``warn`` (default: one
    line on stderr) is told which.  The reader skips only blank lines and yields one message
    for every other line (or fails on it), so the n-th message is the n-th non-blank line:
    that is how a failure is named (LogError)."""
    with open(path, encoding="utf-8", errors="replace", newline="") as f:
        lines = f.readlines()
    numbers = [n for n, line in enumerate(lines, 1) if line.strip()]
    if numbers and not lines[numbers[-1] - 1].endswith("\n"):
        cut = numbers.pop()
        del lines[cut - 1:]
        n = len(numbers)
        (warn or _warn)(f"{path}: line {cut} is cut off (no end of line) and left out; the {n} "
                        f"{'frame' if n == 1 else 'frames'} before it {'is' if n == 1 else 'are'} read")
    out: list[tuple[int, can.Message]] = []
    try:
        with can.CanutilsLogReader(io.StringIO("".join(lines))) as reader:
            for msg in reader:
                out.append((numbers[len(out)], msg))
    except (ValueError, IndexError) as exc:
        line = numbers[len(out)] if len(out) < len(numbers) else len(numbers)
        raise LogError(f"{path}: line {line}: not a candump -L frame ({exc})") from None
    return out
