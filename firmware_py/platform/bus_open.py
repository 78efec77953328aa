"""Opening the CAN bus every process uses: real SocketCAN where it exists, else the fallback.

Order of precedence: explicit ``--interface/--channel``; python-can's own configuration
(``CAN_INTERFACE``/``CAN_CHANNEL`` environment variables or a ``can.ini``/``.canrc`` file);
SocketCAN ``vcan0`` if this kernel has it; otherwise the ``mrsteer`` fallback bus.  Every
automatic choice is announced in one line on stderr.
"""

from __future__ import annotations

import socket
import sys
from pathlib import Path
from typing import Any, Callable

import can

FALLBACK = ("mrsteer", "mrsteer0")
VCAN = ("socketcan", "vcan0")


class BusOpenError(RuntimeError):
    """The requested bus could not be opened; the message says which and why."""


def vcan_available(name: str = "vcan0") -> bool:
    return hasattr(socket, "AF_CAN") and Path(f"/sys/class/net/{name}").exists()


def resolve(interface: str | None, channel: str | None,
            notice: Callable[[str], None] | None = None) -> tuple[str, str | None]:
    """(interface, channel) to open, announcing automatic choices."""
    say = notice or (lambda msg: print(msg, file=sys.stderr, flush=True))
    if interface is not None:
        if channel is None and interface == FALLBACK[0]:
            channel = FALLBACK[1]
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
    try:
        return can.Bus(interface=iface, channel=chan, **kwargs)
    except (can.CanError, ValueError, OSError, ImportError) as exc:
        raise BusOpenError(f"cannot open CAN bus {iface}:{chan}: {exc}") from None
