"""Fallback CAN bus for machines without SocketCAN: a broker and a python-can interface.

The broker (``mrsteer bus``, or started automatically by the first client) listens on a Unix
``SOCK_SEQPACKET`` socket in a private directory (mode 0700), so it is reachable from this
machine only.  Semantics follow SocketCAN:

* one total order: the broker is single-threaded and appends every frame to every client's
  queue in the order it received them, so all clients see the same sequence;
* a sender does not get its own frames unless it opened the bus with
  ``receive_own_messages=True``; then it gets them at their place in the total order;
* receive filters (``can_filters``/``set_filters``) are applied in the broker like kernel
  filters, so filtered-out traffic never reaches the client process;
* every received ``can.Message`` carries the time the broker put it on the bus
  (``time.time()``), as SocketCAN stamps a frame when the kernel receives it;
* a slow client's queue is bounded (like a socket receive buffer): when it overflows the
  broker drops that client's frames and counts them, it never stalls the others;
* every failure reaches the user as a ``can.CanError`` subclass; when the broker dies the next
  ``send``/``recv`` raises ``can.CanOperationError``; when a client dies the broker forgets it.

Use it as ``can.Bus(interface="mrsteer", channel="mrsteer0")`` (registered through the
``can.interface`` entry point).
"""

from __future__ import annotations

import collections
import select
import socket
import time
from typing import Any

from can import BusABC, CanInitializationError, CanOperationError, Message

from firmware_py.platform.fallback_broker import start_broker
from firmware_py.platform.fallback_wire import DEFAULT_CHANNEL, INTERFACE_NAME, FILTER, OPTIONS, MAX_PACKET, socket_dir, socket_path, pack_frame, unpack_frame


class FallbackBus(BusABC):
    """python-can interface ``mrsteer``: a client of the fallback-bus broker."""

    def __init__(self, channel: Any = DEFAULT_CHANNEL, can_filters: Any = None, receive_own_messages: bool = False,
                 autostart: bool = True, connect_timeout: float = 5.0, **kwargs: Any) -> None:
        self.channel = str(channel if channel is not None else DEFAULT_CHANNEL)
        try:
            self._path = socket_path(self.channel)
        except ValueError as exc:
            raise CanInitializationError(str(exc)) from None
        self.channel_info = f"mrsteer fallback bus {self.channel} ({self._path})"
        self._early: collections.deque[bytes] = collections.deque()
        self._sock = self._connect(autostart, connect_timeout)
        self._handshake(receive_own_messages, connect_timeout)
        super().__init__(channel=self.channel, can_filters=can_filters, **kwargs)

    def _handshake(self, receive_own: bool, timeout: float) -> None:
        """Send our options and wait for the broker's ack: once it arrives the broker has us on
        its list, so every frame anyone sends from now on reaches us (as with a bound socket)."""
        self._send_raw(OPTIONS.pack(b"O", int(bool(receive_own))))
        self._sock.settimeout(timeout)
        try:
            while True:
                packet = self._sock.recv(MAX_PACKET)
                if not packet:
                    raise CanInitializationError("fallback bus: the broker closed the connection")
                if packet == b"A":
                    break
                self._early.append(packet)  # a frame fanned out to us before the ack
        except socket.timeout:
            self._sock.close()
            raise CanInitializationError(f"fallback bus: no answer from the broker on {self._path}") from None
        # Blocking from here on, for good: every wait is per call (``poll``), because one thread
        # may receive while another sends (the fault bridge), and a timeout set on the socket by
        # one would change the other's wait (a receive that never returned).
        self._sock.settimeout(None)
        self._readable, self._writable = select.poll(), select.poll()  # one per direction: one thread each
        self._readable.register(self._sock, select.POLLIN)
        self._writable.register(self._sock, select.POLLOUT)

    def _connect(self, autostart: bool, timeout: float) -> socket.socket:
        deadline = time.monotonic() + timeout
        started = False
        while True:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            try:
                sock.connect(str(self._path))
                return sock
            except (FileNotFoundError, ConnectionRefusedError):
                sock.close()
            if autostart and not started:
                start_broker(self.channel)
                started = True
            elif not autostart:
                raise CanInitializationError(f"no fallback-bus broker on {self._path} (start one with `mrsteer bus`)")
            if time.monotonic() > deadline:
                raise CanInitializationError(f"fallback-bus broker did not come up on {self._path}")
            time.sleep(0.02)

    def _send_raw(self, packet: bytes, timeout: float | None = None) -> None:
        deadline = None if timeout is None else time.monotonic() + timeout
        try:
            while True:
                try:
                    self._sock.send(packet, 0 if deadline is None else socket.MSG_DONTWAIT)
                    return
                except BlockingIOError:
                    assert deadline is not None
                    left = deadline - time.monotonic()
                    if left <= 0.0 or not self._writable.poll(left * 1e3):
                        raise CanOperationError("fallback bus: send timed out") from None
        except OSError as exc:
            raise CanOperationError(f"fallback bus: broker connection lost ({exc.strerror or exc})") from None

    def send(self, msg: Message, timeout: float | None = None) -> None:
        if self._is_shutdown:
            raise CanOperationError("fallback bus: send on a closed bus")
        if len(msg.data or b"") > 64:
            raise CanOperationError("fallback bus: more than 64 data bytes")
        self._send_raw(pack_frame(msg), timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[Message | None, bool]:
        if self._is_shutdown:
            raise CanOperationError("fallback bus: receive on a closed bus")
        if self._early:
            return unpack_frame(self._early.popleft(), self.channel), False
        try:
            if timeout is not None and not self._readable.poll(max(timeout, 0.0) * 1e3):
                return None, False
            packet = self._sock.recv(MAX_PACKET)
        except OSError as exc:
            raise CanOperationError(f"fallback bus: broker connection lost ({exc.strerror or exc})") from None
        if not packet:
            raise CanOperationError("fallback bus: the broker closed the connection")
        # The broker already applied our filters; BusABC checks again in case they changed in flight.
        return unpack_frame(packet, self.channel), False

    def _apply_filters(self, filters: Any) -> None:
        if not getattr(self, "_sock", None):
            return
        rows = b"".join(FILTER.pack(int(f["can_id"]) & 0x1FFFFFFF, int(f["can_mask"]) & 0x1FFFFFFF,
                                     -1 if "extended" not in f else int(bool(f["extended"])))
                        for f in (filters or []))
        self._send_raw(b"S" + rows)

    def fileno(self) -> int:
        return self._sock.fileno()

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        super().shutdown()
        # Closing a Unix socket with frames still unread in our own receive queue makes the
        # kernel reset the connection, and the broker would lose the frames we sent last.  So:
        # end our side, let the broker read everything and hang up, then close.
        try:
            self._sock.shutdown(socket.SHUT_WR)
            self._sock.settimeout(0.2)
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline and self._sock.recv(MAX_PACKET):
                pass
        except OSError:
            pass
        self._sock.close()

    @staticmethod
    def _detect_available_configs() -> list[dict[str, Any]]:
        d = socket_dir()
        if not d.is_dir():
            return []
        return [{"interface": INTERFACE_NAME, "channel": p.stem} for p in sorted(d.glob("*.sock"))]
