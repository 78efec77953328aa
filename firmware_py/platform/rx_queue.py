"""A deep kernel receive queue for the processes that must see every frame (bus logger,
fault bridge).

A SocketCAN raw socket holds about ``net.core.rmem_default`` bytes of received frames (212992:
some 300 frames of ~700 bytes each in the kernel) and silently drops the rest.  A stall of one
second at 400 frames/s overflows it, and a loaded or emulated machine stalls that long.  The
controller keeps the default on purpose: for it an old frame is worth nothing.
"""

from __future__ import annotations

import socket
from typing import Any

SO_RCVBUFFORCE = 33  # <asm-generic/socket.h>; Python's socket module does not name it
DEPTH_BYTES = 8 << 20  # about 12 000 frames: tens of seconds of this project's traffic


def deepen(bus: Any, size: int = DEPTH_BYTES) -> int | None:
    """Ask for a ``size``-byte receive queue on ``bus``'s socket, beyond ``rmem_max`` where
    privileged (SO_RCVBUFFORCE needs CAP_NET_ADMIN); returns the size the kernel granted, or
    None for a bus without a kernel socket (the fallback bus queues in its broker)."""
    sock = getattr(bus, "socket", None)
    if not isinstance(sock, socket.socket):
        return None
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, size)
    except OSError:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)  # capped at rmem_max
        except OSError:
            pass
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
