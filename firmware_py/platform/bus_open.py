"""Opening the CAN bus every process uses: real SocketCAN where it exists, else the fallback.

Order of precedence: explicit ``--interface/--channel``; python-can's own configuration
(``CAN_INTERFACE``/``CAN_CHANNEL`` environment variables or a ``can.ini``/``.canrc`` file);
SocketCAN ``vcan0`` if this kernel has it; otherwise the ``mrsteer`` fallback bus.  Every
automatic choice is announced in one line on stderr.

``check`` refuses, before anything starts, a bus that cannot be had: an interface python-can
does not know (the line names those it knows and those usable here), SocketCAN on a kernel
without CAN or on a channel that does not exist, a fallback-bus channel name that cannot be;
``open_bus`` goes through it, and so does a runner before it starts its processes.
"""

from __future__ import annotations

import socket
import sys
from pathlib import Path
from typing import Any, Callable

import can
import can.interfaces

from firmware_py.platform.fallback_wire import socket_path

FALLBACK = ("mrsteer", "mrsteer0")
VCAN = ("socketcan", "vcan0")


class BusOpenError(RuntimeError):
    """The requested bus could not be opened; the message says which and why."""


def vcan_available(name: str = "vcan0") -> bool:
    return hasattr(socket, "AF_CAN") and Path(f"/sys/class/net/{name}").exists()


def socketcan_problem() -> str | None:
    """Why SocketCAN cannot be used here, or None."""
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no SocketCAN (no socket.AF_CAN)"
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError as exc:
        return f"this kernel has no SocketCAN ({exc.strerror or exc})"
    return None


def usable_here() -> str:
    """The interfaces processes on this machine can share a bus on without hardware, in words."""
    return f"{FALLBACK[0]} (the fallback bus)" + (f" or {VCAN[0]}" if socketcan_problem() is None else "")


def check(interface: str, channel: str | None, between_processes: bool = False) -> None:
    """BusOpenError, in one line that says what to use instead, for a bus that cannot be had
    here; ``between_processes``: a run's processes must share it (python-can's ``virtual`` bus
    lives inside one process)."""
    known = can.interfaces.VALID_INTERFACES
    usable = usable_here()
    if interface not in known:
        raise BusOpenError(f"--interface {interface}: python-can has no such interface; usable here: {usable} "
                           f"(python-can knows {', '.join(sorted(known))})")
    if interface == VCAN[0]:
        problem = socketcan_problem()
        if problem is not None:
            raise BusOpenError(f"--interface socketcan: {problem}; use --interface {FALLBACK[0]} (the fallback "
                               "bus), or leave --interface out")
        if channel is not None and not Path(f"/sys/class/net/{channel}").exists():
            raise BusOpenError(f"--channel {channel}: no such network interface here (tools/vcan.sh up creates "
                               f"vcan0; or: ip link add dev {channel} type vcan && ip link set up {channel})")
    elif interface == FALLBACK[0] and channel is not None:
        try:
            socket_path(channel)
        except ValueError as exc:
            raise BusOpenError(f"--channel {channel}: {exc}") from None
    elif interface == "virtual" and between_processes:
        raise BusOpenError(f"--interface virtual: python-can's virtual bus lives inside one process, and this "
                           f"run's processes must share their bus; usable here: {usable}")


def resolve(interface: str | None, channel: str | None,
            notice: Callable[[str], None] | None = None) -> tuple[str, str | None]:
    """(interface, channel) to open, announcing automatic choices."""
    say = notice or (lambda msg: print(msg, file=sys.stderr, flush=True))
    if interface is not None:
        if channel is None and interface in (FALLBACK[0], VCAN[0]):
            channel = FALLBACK[1] if interface == FALLBACK[0] else VCAN[1]
        return interface, channel
    try:
        cfg = can.util.load_config()
    except can.CanInterfaceNotImplementedError:
        cfg = {}
    if cfg.get("interface"):
        chosen = (str(cfg["interface"]), channel if channel is not None else cfg.get("channel"))
        say(f"bus: {chosen[0]} {chosen[1]} (from python-can configuration)")
        return chosen
    if vcan_available(channel or VCAN[1]) and (channel is None or channel.startswith("vcan")):
        chosen = (VCAN[0], channel or VCAN[1])
        say(f"bus: SocketCAN {chosen[1]}")
        return chosen
    chosen = (FALLBACK[0], channel or FALLBACK[1])
    say(f"bus: no SocketCAN vcan0 here; using the mrsteer fallback bus {chosen[1]}")
    return chosen


def open_bus(interface: str | None = None, channel: str | None = None,
             notice: Callable[[str], None] | None = None, **kwargs: Any) -> can.BusABC:
    iface, chan = resolve(interface, channel, notice)
    check(iface, chan)
    try:
        return can.Bus(interface=iface, channel=chan, **kwargs)
    except (can.CanError, ValueError, OSError, ImportError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__  # one line, whatever the driver said
        raise BusOpenError(f"cannot open CAN bus {iface} {chan or ''}".rstrip() + f": {reason}") from None
