"""The fallback bus's broker (``mrsteer bus``, or started by the first client): one process per
channel that fans every frame out to every client in one total order, applying their filters
(the semantics are in ``fallback_bus``)."""

from __future__ import annotations

import collections
import errno
import fcntl
import math
import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import can

from firmware_py.platform.cli import Parser, describe, fail
from firmware_py.platform.fallback_wire import DEFAULT_CHANNEL, FRAME, STAMP, FILTER, OPTIONS, MAX_PACKET, F_EXTENDED, F_OWN, socket_path, private_dir

_QUEUE_LIMIT = 100_000  # frames waiting for one client before it starts losing them


def start_broker(channel: str, idle_exit: float = 5.0) -> None:
    """Start a detached broker for ``channel`` unless one is already listening."""
    path = socket_path(channel)
    private_dir(path.parent)
    with open(path.parent / f"{channel}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if _listening(path):
            return
        log = open(path.parent / f"{channel}.log", "ab")
        subprocess.Popen([sys.executable, "-m", "firmware_py.platform.fallback_broker", "--channel", channel, "--idle-exit", str(idle_exit)],
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
        private_dir(self.path.parent)
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
                packet = client.sock.recv(MAX_PACKET)
            except BlockingIOError:
                return
            except OSError:
                packet = b""
            if not packet:
                self._drop(client)
                return
            kind = packet[:1]
            if kind == b"F" and len(packet) >= FRAME.size:
                self._fan_out(client, packet)
            elif kind == b"S":
                body = packet[1:]
                n = len(body) // FILTER.size
                client.filters = [FILTER.unpack_from(body, i * FILTER.size) for i in range(n)] or None
            elif kind == b"O" and len(packet) == OPTIONS.size:
                client.own = bool(OPTIONS.unpack(packet)[1])
                client.queue.append(b"A")  # the handshake's ack, in order with any frames queued
                self._flush(client)

    def _fan_out(self, sender: _Client, packet: bytes) -> None:
        self.frames += 1
        _, flags, _, arb, _, _ = FRAME.unpack_from(packet)
        packet = packet[:2] + STAMP.pack(time.time()) + packet[2 + STAMP.size:]  # on the bus now
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
    parser = Parser(prog=prog, description="Run the fallback CAN bus broker "
                                     "(a loopback-only stand-in for SocketCAN vcan).")
    parser.add_argument("--channel", default=DEFAULT_CHANNEL, help=f"bus name (default {DEFAULT_CHANNEL})")
    parser.add_argument("--idle-exit", type=float, default=None, metavar="S",
                        help="exit after S seconds without clients (default: run until SIGINT/SIGTERM)")
    args = parser.parse_args(argv)
    if args.idle_exit is not None and not (math.isfinite(args.idle_exit) and args.idle_exit > 0):
        parser.error(f"--idle-exit must be a positive number of seconds, got {args.idle_exit:g}")
    try:
        broker = Broker(args.channel, args.idle_exit)
        broker.bind()
    except (OSError, ValueError, can.CanError) as exc:
        return fail(prog, describe(exc))
    signal.signal(signal.SIGTERM, broker.stop)
    signal.signal(signal.SIGINT, broker.stop)
    print(f"{prog}: serving {args.channel} on {broker.path}", file=sys.stderr, flush=True)
    broker.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main())
