"""The fallback bus: SocketCAN-like semantics over the loopback-only broker."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time

import can
import pytest

from firmware_py.platform import fallback_wire


@pytest.fixture
def broker(channel: str):
    proc = subprocess.Popen([sys.executable, "-m", "firmware_py.platform.fallback_broker", "--channel", channel],
                            stderr=subprocess.PIPE, env=os.environ.copy())
    path = fallback_wire.socket_path(channel)
    deadline = time.monotonic() + 10
    while not path.exists():
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    yield proc
    if proc.poll() is None:
        proc.terminate()
        proc.wait(10)


def _bus(channel: str, **kw) -> can.BusABC:
    return can.Bus(interface="mrsteer", channel=channel, autostart=False, **kw)


def _drain(bus: can.BusABC, timeout: float = 0.3) -> list[can.Message]:
    out = []
    while (m := bus.recv(timeout)) is not None:
        out.append(m)
    return out


def test_registered_as_a_python_can_interface() -> None:
    assert "mrsteer" in can.interfaces.VALID_INTERFACES


def test_every_client_sees_one_total_order(broker, channel: str) -> None:
    senders = [_bus(channel) for _ in range(3)]
    listeners = [_bus(channel) for _ in range(2)]

    def blast(i: int, b: can.BusABC) -> None:
        for n in range(300):
            b.send(can.Message(arbitration_id=0x100 + i, data=n.to_bytes(2, "little"), is_extended_id=False))

    threads = [threading.Thread(target=blast, args=(i, b)) for i, b in enumerate(senders)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    seqs = [[(m.arbitration_id, bytes(m.data)) for m in _drain(b)] for b in listeners]
    assert len(seqs[0]) == 900 and seqs[0] == seqs[1]
    for i in range(3):  # each sender's own frames keep their order
        mine = [int.from_bytes(d, "little") for a, d in seqs[0] if a == 0x100 + i]
        assert mine == list(range(300))
    for b in senders + listeners:
        b.shutdown()


def test_own_messages_only_when_asked_and_in_order(broker, channel: str) -> None:
    plain, own, other = _bus(channel), _bus(channel, receive_own_messages=True), _bus(channel)
    plain.send(can.Message(arbitration_id=1, data=b"a", is_extended_id=False))
    own.send(can.Message(arbitration_id=2, data=b"b", is_extended_id=False))
    plain.send(can.Message(arbitration_id=3, data=b"c", is_extended_id=False))
    got_own = _drain(own)
    seen_by_other = [m.arbitration_id for m in _drain(other)]
    # The echo sits at the same place in the total order as everyone else sees the frame.
    assert [m.arbitration_id for m in got_own] == seen_by_other and sorted(seen_by_other) == [1, 2, 3]
    assert [m.is_rx for m in got_own] == [m != 2 for m in seen_by_other]
    assert [m.arbitration_id for m in _drain(plain)] == [2]
    for b in (plain, own, other):
        b.shutdown()


def test_filters_at_open_and_set_filters_later(broker, channel: str) -> None:
    tx = _bus(channel)
    rx = _bus(channel, can_filters=[{"can_id": 0x100, "can_mask": 0x7F0, "extended": False}])
    for fid in (0x100, 0x10F, 0x200, 0x101):
        tx.send(can.Message(arbitration_id=fid, data=b"x", is_extended_id=False))
    tx.send(can.Message(arbitration_id=0x100, data=b"e", is_extended_id=True))  # extended: filtered out
    assert [m.arbitration_id for m in _drain(rx)] == [0x100, 0x10F, 0x101]
    rx.set_filters([{"can_id": 0x200, "can_mask": 0x7FF}])
    time.sleep(0.05)
    for fid in (0x100, 0x200):
        tx.send(can.Message(arbitration_id=fid, data=b"y", is_extended_id=False))
    assert [m.arbitration_id for m in _drain(rx)] == [0x200]
    rx.set_filters(None)
    time.sleep(0.05)
    tx.send(can.Message(arbitration_id=0x333, data=b"z", is_extended_id=False))
    assert [m.arbitration_id for m in _drain(rx)] == [0x333]
    tx.shutdown()
    rx.shutdown()


def test_frames_carry_receive_timestamps_and_payloads(broker, channel: str) -> None:
    tx, rx = _bus(channel), _bus(channel)
    before = time.time()
    tx.send(can.Message(arbitration_id=0x1ABCDEF, data=bytes(range(8)), is_extended_id=True))
    tx.send(can.Message(arbitration_id=0x12, data=bytes(range(64)), is_fd=True, bitrate_switch=True,
                        is_extended_id=False))
    a, b = _drain(rx)
    assert before <= a.timestamp <= time.time()
    assert a.arbitration_id == 0x1ABCDEF and a.is_extended_id and bytes(a.data) == bytes(range(8))
    assert b.is_fd and b.bitrate_switch and len(b.data) == 64
    # The stamp is when the frame was on the bus, not when the receiver got round to reading it.
    sent = time.time()
    tx.send(can.Message(arbitration_id=0x13, data=b"\x01", is_extended_id=False))
    time.sleep(0.3)
    late = rx.recv(5.0)
    assert late is not None and sent <= late.timestamp <= sent + 0.2 < time.time()
    tx.shutdown()
    rx.shutdown()


def test_a_dead_peer_does_not_disturb_the_others(broker, channel: str) -> None:
    code = (f"import can; b = can.Bus(interface='mrsteer', channel='{channel}', autostart=False); "
            "b.send(can.Message(arbitration_id=7, data=b'x', is_extended_id=False)); import os; os._exit(9)")
    rx = _bus(channel)
    subprocess.run([sys.executable, "-c", code], check=False, env=os.environ.copy(), timeout=30)
    tx = _bus(channel)
    tx.send(can.Message(arbitration_id=8, data=b"y", is_extended_id=False))
    assert [m.arbitration_id for m in _drain(rx)] == [7, 8]
    assert broker.poll() is None
    tx.shutdown()
    rx.shutdown()


def test_broker_death_raises_can_errors(broker, channel: str) -> None:
    bus = _bus(channel)
    broker.send_signal(signal.SIGKILL)
    broker.wait(10)
    with pytest.raises(can.CanOperationError):
        bus.recv(2.0)
    with pytest.raises(can.CanError):
        for _ in range(100):  # the first sends may still land in the socket buffer
            bus.send(can.Message(arbitration_id=1, data=b"x", is_extended_id=False))
    bus.shutdown()


def test_no_broker_and_no_autostart_is_an_initialisation_error(channel: str) -> None:
    with pytest.raises(can.CanInitializationError, match="mrsteer bus"):
        _bus(channel)


def test_autostart_brings_up_a_broker_that_leaves_when_idle(channel: str) -> None:
    a = can.Bus(interface="mrsteer", channel=channel)
    b = can.Bus(interface="mrsteer", channel=channel)
    a.send(can.Message(arbitration_id=5, data=b"q", is_extended_id=False))
    assert b.recv(2.0).arbitration_id == 5
    a.shutdown()
    b.shutdown()
    path = fallback_wire.socket_path(channel)
    deadline = time.monotonic() + 15
    while path.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not path.exists(), "an autostarted broker must exit once idle"


def test_socket_is_private_to_this_user(broker, channel: str) -> None:
    path = fallback_wire.socket_path(channel)
    assert path.stat().st_mode & 0o077 == 0
    assert path.parent.stat().st_mode & 0o077 == 0
    s = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    s.connect(str(path))  # reachable only through the file system: no network address at all
    s.close()


def test_a_client_gets_every_frame_sent_after_it_opened(broker, channel: str) -> None:
    # As with a bound SocketCAN socket: once the constructor returns, nothing is missed, even
    # when several clients join at once and a frame follows immediately.
    tx = _bus(channel)
    for round_ in range(10):
        rxs = [_bus(channel) for _ in range(8)]
        tx.send(can.Message(arbitration_id=round_, data=b"n", is_extended_id=False))
        for rx in rxs:
            m = rx.recv(2.0)
            assert m is not None and m.arbitration_id == round_
            rx.shutdown()
    tx.shutdown()


def test_frames_sent_just_before_shutdown_are_not_lost(broker, channel: str) -> None:
    # A client that exits right after sending, with frames of others still unread in its own
    # queue: the kernel used to reset the connection and the broker lost its last frames.
    rx, noisy = _bus(channel), _bus(channel)
    for round_ in range(20):
        tx = _bus(channel)
        for i in range(50):
            noisy.send(can.Message(arbitration_id=0x200, data=bytes([i]), is_extended_id=False))
        for i in range(3):
            tx.send(can.Message(arbitration_id=0x300 + i, data=bytes([round_]), is_extended_id=False))
        tx.shutdown()
    got = []
    while (m := rx.recv(0.5)) is not None:
        if m.arbitration_id >= 0x300:
            got.append(m.arbitration_id)
    assert len(got) == 60
    rx.shutdown()
    noisy.shutdown()


def test_a_receive_timeout_holds_while_another_thread_sends(broker, channel: str) -> None:
    """The fault bridge receives on a bus in one thread while another sends on it: a send must
    not turn the receiver's timed wait into one that never returns (it hung a matrix row)."""
    bus = _bus(channel)
    sending = threading.Event()
    sending.set()
    returned = 0

    def receive() -> None:  # nobody else is on the channel: every wait ends by its timeout
        nonlocal returned
        while returned < 200:
            assert bus.recv(0.005) is None
            returned += 1

    def send() -> None:
        msg = can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False)
        while sending.is_set():
            bus.send(msg)  # no timeout: a blocking send

    sender, receiver = threading.Thread(target=send, daemon=True), threading.Thread(target=receive, daemon=True)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads between any two calls: the race, every few frames
    try:
        sender.start()
        receiver.start()
        time.sleep(0.5)
        sending.clear()
        sender.join(10)
        receiver.join(30)
        assert not receiver.is_alive(), f"a receive with a 5 ms timeout still waiting after {returned} returned"
        assert returned == 200
    finally:
        sys.setswitchinterval(interval)
        sending.clear()
        bus.shutdown()
