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
import errno
import fcntl
import os
import selectors
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import can
from can import BusABC, CanInitializationError, CanOperationError, Message

DEFAULT_CHANNEL = "mrsteer0"
INTERFACE_NAME = "mrsteer"
_FRAME = struct.Struct("<cBdIBB")  # type b"F", flags, timestamp, arbitration id, dlc, data length
_STAMP = struct.Struct("<d")  # the timestamp field of _FRAME, at offset 2
_FILTER = struct.Struct("<IIb")  # can_id, can_mask, extended (-1: either)
_OPTIONS = struct.Struct("<cB")  # type b"O", receive_own
_MAX_PACKET = _FRAME.size + 64
_QUEUE_LIMIT = 100_000  # frames waiting for one client before it starts losing them

F_EXTENDED, F_REMOTE, F_ERROR, F_FD, F_BRS, F_ESI, F_OWN = 1, 2, 4, 8, 16, 32, 64


def socket_dir() -> Path:
    return Path(os.environ.get("MRSTEER_BUS_DIR") or f"/tmp/mrsteer-bus-{os.getuid()}")


def socket_path(channel: str) -> Path:
    if not channel or "/" in channel or channel.startswith("."):
        raise ValueError(f"invalid fallback-bus channel name {channel!r}")
    return socket_dir() / f"{channel}.sock"


def _private_dir(path: Path) -> None:
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    st = path.stat()
    if st.st_uid != os.getuid() or st.st_mode & 0o077:
        raise CanInitializationError(f"{path} must be a directory owned by you with mode 0700")


def _pack_frame(msg: Message, flags_extra: int = 0) -> bytes:
    flags = flags_extra
    if msg.is_extended_id:
        flags |= F_EXTENDED
    if msg.is_remote_frame:
        flags |= F_REMOTE
    if msg.is_error_frame:
        flags |= F_ERROR
    if msg.is_fd:
        flags |= F_FD
    if msg.bitrate_switch:
        flags |= F_BRS
    if msg.error_state_indicator:
        flags |= F_ESI
    data = bytes(msg.data or b"")
    return _FRAME.pack(b"F", flags, msg.timestamp or 0.0, msg.arbitration_id, msg.dlc, len(data)) + data


def _unpack_frame(packet: bytes, channel: str) -> Message:
    _, flags, stamp, arb, dlc, n = _FRAME.unpack_from(packet)
    return Message(
        timestamp=stamp,
        arbitration_id=arb,
        is_extended_id=bool(flags & F_EXTENDED),
        is_remote_frame=bool(flags & F_REMOTE),
        is_error_frame=bool(flags & F_ERROR),
        is_fd=bool(flags & F_FD),
        bitrate_switch=bool(flags & F_BRS),
        error_state_indicator=bool(flags & F_ESI),
        dlc=dlc,
        data=packet[_FRAME.size:_FRAME.size + n],
        channel=channel,
        is_rx=not flags & F_OWN,
    )


# --------------------------------------------------------------------------- client


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
        self._send_raw(_OPTIONS.pack(b"O", int(bool(receive_own))))
        self._sock.settimeout(timeout)
        try:
            while True:
                packet = self._sock.recv(_MAX_PACKET)
                if not packet:
                    raise CanInitializationError("fallback bus: the broker closed the connection")
                if packet == b"A":
                    return
                self._early.append(packet)  # a frame fanned out to us before the ack
        except socket.timeout:
            self._sock.close()
            raise CanInitializationError(f"fallback bus: no answer from the broker on {self._path}") from None

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

    def _send_raw(self, packet: bytes) -> None:
        try:
            self._sock.send(packet)
        except socket.timeout:
            raise CanOperationError("fallback bus: send timed out") from None
        except OSError as exc:
            raise CanOperationError(f"fallback bus: broker connection lost ({exc.strerror or exc})") from None

    def send(self, msg: Message, timeout: float | None = None) -> None:
        if self._is_shutdown:
            raise CanOperationError("fallback bus: send on a closed bus")
        if len(msg.data or b"") > 64:
            raise CanOperationError("fallback bus: more than 64 data bytes")
        self._sock.settimeout(timeout)
        self._send_raw(_pack_frame(msg))

    def _recv_internal(self, timeout: float | None) -> tuple[Message | None, bool]:
        if self._is_shutdown:
            raise CanOperationError("fallback bus: receive on a closed bus")
        if self._early:
            return _unpack_frame(self._early.popleft(), self.channel), False
        self._sock.settimeout(timeout)
        try:
            packet = self._sock.recv(_MAX_PACKET)
        except socket.timeout:
            return None, False
        except BlockingIOError:
            return None, False
        except OSError as exc:
            raise CanOperationError(f"fallback bus: broker connection lost ({exc.strerror or exc})") from None
        if not packet:
            raise CanOperationError("fallback bus: the broker closed the connection")
        # The broker already applied our filters; BusABC checks again in case they changed in flight.
        return _unpack_frame(packet, self.channel), False

    def _apply_filters(self, filters: Any) -> None:
        if not getattr(self, "_sock", None):
            return
        rows = b"".join(_FILTER.pack(int(f["can_id"]) & 0x1FFFFFFF, int(f["can_mask"]) & 0x1FFFFFFF,
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
            while time.monotonic() < deadline and self._sock.recv(_MAX_PACKET):
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


# --------------------------------------------------------------------------- broker


def start_broker(channel: str, idle_exit: float = 5.0) -> None:
    """Start a detached broker for ``channel`` unless one is already listening."""
    path = socket_path(channel)
    _private_dir(path.parent)
    with open(path.parent / f"{channel}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if _listening(path):
            return
        log = open(path.parent / f"{channel}.log", "ab")
        subprocess.Popen([sys.executable, "-m", "sim_plant.vbus", "--channel", channel, "--idle-exit", str(idle_exit)],
                         stdin=subprocess.DEVNULL, stdout=log, stderr=log, start_new_session=True, close_fds=True)
        log.close()
        deadline = time.monotonic() + 5.0
        while not _listening(path) and time.monotonic() < deadline:
            time.sleep(0.01)


def _listening(path: Path) -> bool:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    try:
        s.connect(str(path))
        return True
    except OSError:
        return False
    finally:
        s.close()


class _Client:
    __slots__ = ("sock", "own", "filters", "queue", "dropped", "want_write")

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.own = False
        self.filters: list[tuple[int, int, int]] | None = None
        self.queue: collections.deque[bytes] = collections.deque()
        self.dropped = 0
        self.want_write = False

    def accepts(self, arb: int, extended: bool) -> bool:
        if self.filters is None:
            return True
        for can_id, mask, ext in self.filters:
            if ext != -1 and ext != extended:
                continue
            if (can_id ^ arb) & mask == 0:
                return True
        return False


class Broker:
    """Single-threaded fan-out of frames among the clients of one channel."""

    def __init__(self, channel: str, idle_exit: float | None = None) -> None:
        self.channel = channel
        self.path = socket_path(channel)
        self.idle_exit = idle_exit
        self.frames = 0
        self._clients: dict[int, _Client] = {}
        self._sel = selectors.DefaultSelector()
        self._running = True

    def bind(self) -> None:
        _private_dir(self.path.parent)
        self._listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            self._listener.bind(str(self.path))
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE or _listening(self.path):
                raise
            self.path.unlink()  # a stale socket file from a broker that died
            self._listener.bind(str(self.path))
        os.chmod(self.path, 0o600)
        self._listener.listen(64)
        self._listener.setblocking(False)
        self._sel.register(self._listener, selectors.EVENT_READ, None)

    def stop(self, *_: Any) -> None:
        self._running = False

    def serve(self) -> None:
        idle_since = time.monotonic()
        try:
            while self._running:
                for key, events in self._sel.select(timeout=0.5):
                    if key.data is None:
                        self._accept()
                        continue
                    client: _Client = key.data
                    if events & selectors.EVENT_READ:
                        self._read(client)
                    if events & selectors.EVENT_WRITE and client.sock.fileno() in self._clients:
                        self._flush(client)
                if self._clients:
                    idle_since = time.monotonic()
                elif self.idle_exit is not None and time.monotonic() - idle_since > self.idle_exit:
                    break
        finally:
            self.close()

    def close(self) -> None:
        for client in list(self._clients.values()):
            self._drop(client)
        try:
            self._sel.unregister(self._listener)
        except (KeyError, ValueError, AttributeError):
            pass
        if hasattr(self, "_listener"):
            self._listener.close()
            try:
                self.path.unlink()
            except FileNotFoundError:
                pass

    def _accept(self) -> None:
        try:
            sock, _ = self._listener.accept()
        except BlockingIOError:
            return
        sock.setblocking(False)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        client = _Client(sock)
        self._clients[sock.fileno()] = client
        self._sel.register(sock, selectors.EVENT_READ, client)

    def _drop(self, client: _Client) -> None:
        self._clients.pop(client.sock.fileno(), None)
        try:
            self._sel.unregister(client.sock)
        except (KeyError, ValueError):
            pass
        client.sock.close()

    def _read(self, client: _Client) -> None:
        for _ in range(256):  # bounded, so one chatty client cannot starve the rest
            try:
                packet = client.sock.recv(_MAX_PACKET)
            except BlockingIOError:
                return
            except OSError:
                packet = b""
            if not packet:
                self._drop(client)
                return
            kind = packet[:1]
            if kind == b"F" and len(packet) >= _FRAME.size:
                self._fan_out(client, packet)
            elif kind == b"S":
                body = packet[1:]
                n = len(body) // _FILTER.size
                client.filters = [_FILTER.unpack_from(body, i * _FILTER.size) for i in range(n)] or None
            elif kind == b"O" and len(packet) == _OPTIONS.size:
                client.own = bool(_OPTIONS.unpack(packet)[1])
                client.queue.append(b"A")  # the handshake's ack, in order with any frames queued
                self._flush(client)

    def _fan_out(self, sender: _Client, packet: bytes) -> None:
        self.frames += 1
        _, flags, _, arb, _, _ = _FRAME.unpack_from(packet)
        packet = packet[:2] + _STAMP.pack(time.time()) + packet[2 + _STAMP.size:]  # on the bus now
        extended = bool(flags & F_EXTENDED)
        own_packet = None
        for client in list(self._clients.values()):
            if client is sender:
                if not client.own:
                    continue
                if own_packet is None:
                    own_packet = packet[:1] + bytes((flags | F_OWN,)) + packet[2:]
                out = own_packet
            else:
                out = packet
            if not client.accepts(arb, extended):
                continue
            if len(client.queue) >= _QUEUE_LIMIT:
                client.dropped += 1
                continue
            client.queue.append(out)
            if not client.want_write:
                self._flush(client)

    def _flush(self, client: _Client) -> None:
        q = client.queue
        while q:
            try:
                client.sock.send(q[0])
            except BlockingIOError:
                break
            except OSError:
                self._drop(client)
                return
            q.popleft()
        want = bool(q)
        if want != client.want_write:
            client.want_write = want
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if want else 0)
            self._sel.modify(client.sock, events, client)


def main(argv: list[str] | None = None, prog: str = "mrsteer bus") -> int:
    from firmware_py.cli_support import Parser

    parser = Parser(prog=prog, description="Run the fallback CAN bus broker "
                                     "(a loopback-only stand-in for SocketCAN vcan).")
    parser.add_argument("--channel", default=DEFAULT_CHANNEL, help=f"bus name (default {DEFAULT_CHANNEL})")
    parser.add_argument("--idle-exit", type=float, default=None, metavar="S",
                        help="exit after S seconds without clients (default: run until SIGINT/SIGTERM)")
    args = parser.parse_args(argv)
    try:
        broker = Broker(args.channel, args.idle_exit)
        broker.bind()
    except (OSError, ValueError, can.CanError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    signal.signal(signal.SIGTERM, broker.stop)
    signal.signal(signal.SIGINT, broker.stop)
    print(f"{prog}: serving {args.channel} on {broker.path}", file=sys.stderr, flush=True)
    broker.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main())
