"""SecOC on the sensor frames (mrsteer_dbc.secoc.SensorSigner / SensorVerifier) and its use by
the controller: counter recovery from the two residues, replays of any age, loss, epochs,
forgery, and the aliased replays that E2E alone accepts (docs/faults.md)."""

from __future__ import annotations

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.controller import node as rt
from mrsteer_dbc import secoc
from mrsteer_dbc import names

C = mrsteer_dbc.load()
KEY = bytes(range(16))
EPOCH = 1_000_000
YAW = C.frame_id(names.MSG_YAW)


def yaw_values(i: int) -> dict[str, float]:
    # Below the plausibility monitor's model bound (0.15 rad/s with the wheel straight).
    return {"YawRate_YawRate": 1e-4 * (i % 1000)}


def yaw_stream(n: int, epoch: int | None = EPOCH, signer: secoc.SensorSigner | None = None,
               alive: mrsteer_dbc.AliveCounter | None = None) -> list[bytes]:
    signer = signer or secoc.SensorSigner(C, KEY)
    alive = alive or mrsteer_dbc.AliveCounter()
    return [signer.sign(names.MSG_YAW, yaw_values(i), alive.next(), epoch) for i in range(n)]


def verifier(*epochs: int) -> secoc.SensorVerifier:
    v = secoc.SensorVerifier(C, KEY)
    for e in epochs or (EPOCH,):
        v.adopt(e)
    return v


def accepts(v: secoc.SensorVerifier, data: bytes, frame_id: int = YAW) -> bool:
    decoded = C.decode(frame_id, data)
    assert decoded.status is mrsteer_dbc.E2EStatus.OK  # the E2E CRC covers the authenticator
    return v.verify(frame_id, data, decoded.signals)


# ---------------------------------------------------------------------- the layout and the counter


@pytest.mark.parametrize("name, mac_bits", [(names.MSG_STEER, 8), (names.MSG_YAW, 16), (names.MSG_SPEED, 8)])
def test_every_sensor_message_has_its_fields_in_the_dbc(name: str, mac_bits: int) -> None:
    f = secoc.SensorFields.of(C, name)
    assert f.mac_bits == mac_bits
    assert f.zero_mask[C.e2e(name).crc_byte] == 0
    assert sum(8 - bin(b).count("1") for b in f.zero_mask) == 8 + mac_bits  # the CRC and the MAC, no more


@given(st.integers(0, 14), st.integers(0, 7), st.integers(1, 120))
def test_the_advance_is_recovered_from_the_alive_and_low_bit_residues(alive0: int, low0: int, advance: int) -> None:
    alive1, low1 = (alive0 + advance) % 15, (low0 + advance) % 8
    assert secoc.counter_advance(alive1 - alive0, low1 - low0) == advance


# ---------------------------------------------------------------------- verification


def test_every_signed_frame_verifies_once_and_a_duplicate_does_not() -> None:
    v = verifier()
    frames = yaw_stream(40)
    assert all(accepts(v, d) for d in frames)
    assert not accepts(v, frames[-1])
    assert v.failed[names.MSG_YAW] == 1


def test_each_sensor_message_is_signed_and_checked_on_its_own() -> None:
    signer, v = secoc.SensorSigner(C, KEY), verifier()
    for name, values in ((names.MSG_STEER, {"DriverSteer_Angle": 0.1}), (names.MSG_SPEED, {"VehicleSpeed_Speed": 20.0}),
                         (names.MSG_YAW, yaw_values(3))):
        alive = mrsteer_dbc.AliveCounter()
        frames = [signer.sign(name, values, alive.next(), EPOCH) for _ in range(20)]
        assert all(accepts(v, d, C.frame_id(name)) for d in frames)
    other = secoc.SensorSigner(C, bytes(16))  # the freshness right, the key wrong
    assert not accepts(v, other.sign(names.MSG_YAW, yaw_values(0), 5, EPOCH))


def test_a_changed_bit_outside_the_crc_fails_the_mac() -> None:
    v = verifier()
    frames = yaw_stream(3)
    assert accepts(v, frames[0])
    for byte in range(1, len(frames[1])):
        for bit in range(8):
            bad = bytearray(frames[1])
            bad[byte] ^= 1 << bit
            bad[0] = C.e2e_crc(names.MSG_YAW, bytes(bad))  # a forger can always fix the CRC
            decoded = C.decode(YAW, bytes(bad))
            if decoded.status is mrsteer_dbc.E2EStatus.OK:
                assert not v.verify(YAW, bytes(bad), decoded.signals), (byte, bit)
    assert accepts(v, frames[1])


@pytest.mark.parametrize("back", [1, 2, 5, 10, 11, 12, 13, 14, 15, 16, 27, 28, 29, 30, 60, 104])
def test_a_replay_after_each_live_frame_is_refused_at_any_age(back: int) -> None:
    """The attack that E2E alone cannot see (12-14 back alias to 1-3 ahead of the alive counter):
    every replay is refused and every live frame kept."""
    frames = yaw_stream(400)
    v = verifier()
    assert all(accepts(v, d) for d in frames[:back])
    live = replays = 0
    for i in range(back, 400):
        live += accepts(v, frames[i])
        replays += accepts(v, frames[i - back])
    assert (replays, live) == (0, 400 - back)


def test_up_to_14_lost_frames_are_bridged_more_wait_for_the_next_epoch() -> None:
    signer, alive = secoc.SensorSigner(C, KEY), mrsteer_dbc.AliveCounter()
    v = verifier()
    frames = yaw_stream(60, signer=signer, alive=alive)
    assert accepts(v, frames[0])
    assert accepts(v, frames[15])  # 14 lost
    assert not accepts(v, frames[31])  # 15 lost: beyond the window
    assert not accepts(v, frames[32])
    v.adopt(EPOCH + 1)
    fresh = yaw_stream(2, epoch=EPOCH + 1, signer=signer, alive=alive)
    assert accepts(v, fresh[0]) and accepts(v, fresh[1])


def test_a_frame_of_the_previous_epoch_still_in_flight_verifies_older_ones_do_not() -> None:
    signer, alive = secoc.SensorSigner(C, KEY), mrsteer_dbc.AliveCounter()
    v = verifier()
    old = yaw_stream(3, signer=signer, alive=alive)
    assert accepts(v, old[0])
    v.adopt(EPOCH + 1)
    assert accepts(v, old[1])  # sent before the sync, received after it
    new = yaw_stream(2, epoch=EPOCH + 1, signer=signer, alive=alive)
    assert accepts(v, new[0])
    assert not accepts(v, old[2])  # the previous epoch, after a frame of the current one
    v.adopt(EPOCH + 2)
    assert not accepts(v, yaw_stream(1, epoch=EPOCH, signer=signer, alive=alive)[0])  # two old: its bit names EPOCH+2
    assert accepts(v, new[1])


def test_without_an_epoch_nothing_verifies() -> None:
    v = secoc.SensorVerifier(C, KEY)
    assert not accepts(v, yaw_stream(1)[0])
    assert not accepts(verifier(), yaw_stream(1, epoch=None)[0])  # unsigned: MAC and FV fields 0


@given(st.binary(min_size=8, max_size=8))
def test_random_frames_never_raise(data: bytes) -> None:
    decoded = C.decode(YAW, data)
    if decoded is not None and decoded.status is mrsteer_dbc.E2EStatus.OK:
        assert verifier().verify(YAW, data, decoded.signals) in (True, False)


# ---------------------------------------------------------------------- the controller


def _controller_run(secured: bool, frames: list[tuple[int, bytes]], channel: str
                    ) -> tuple[rt.ControllerNode, dict[str, float]]:
    """Feed driver/speed/yaw frames to a controller (SecOC on if ``secured``), one cycle per yaw
    frame; the node and the input values it holds at the end."""
    cfg = rt.RuntimeConfig(rate_hz=500.0, secoc_key=KEY if secured else None)
    with can.Bus(interface="virtual", channel=channel) as cb, can.Bus(interface="virtual", channel=channel) as vb:
        node = rt.ControllerNode(cb, cfg)
        for frame_id, data in frames:
            vb.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
            if frame_id == YAW:
                node.drain()
                node.control()
        return node, {i.name: i.value for i in node.inputs.values()}


def _stream_with_yaw_replays(secured: bool, back: int, n: int = 200) -> list[tuple[int, bytes]]:
    """The plant's traffic at 500 Hz (with SecOC: a sync every 100 ms and signed sensor frames),
    each live yaw-rate frame from frame 40 on followed by the one ``back`` frames older."""
    signer = secoc.SensorSigner(C, KEY)
    master = secoc.CommandVerifier(C, KEY, lambda: secoc.EPOCH_ORIGIN_S + EPOCH / 1000.0)
    counters = {name: mrsteer_dbc.AliveCounter() for name in secoc.SENSORS}
    yaw, out, epoch = [], [], None
    for i in range(n):
        if secured and i % 50 == 0:
            out.append((C.frame_id(secoc.SYNC), master.next_sync()))
            epoch = master.current
        for name, values in ((names.MSG_STEER, {"DriverSteer_Angle": 0.0}), (names.MSG_SPEED, {"VehicleSpeed_Speed": 20.0})):
            if name == names.MSG_STEER or i % 5 == 0:
                out.append((C.frame_id(name), signer.sign(name, values, counters[name].next(), epoch)))
        yaw.append(signer.sign(names.MSG_YAW, yaw_values(i), counters[names.MSG_YAW].next(), epoch))
        if back and i >= 40 and i >= back:
            out.append((YAW, yaw[-1]))
            out.append((YAW, yaw[i - back]))  # the replay right after the live frame
        else:
            out.append((YAW, yaw[-1]))
    return out


@pytest.mark.parametrize("back", [12, 13, 14])
def test_controller_with_secoc_refuses_the_aliased_replays_that_e2e_takes(back: int, channel: str) -> None:
    _, plain = _controller_run(False, _stream_with_yaw_replays(False, back), channel + "p")
    # E2E alone: the controller ends on the replayed (stale) value, the documented limit.
    assert plain[names.MSG_YAW] == pytest.approx(yaw_values(199 - back)["YawRate_YawRate"], abs=1e-6)
    secured, values = _controller_run(True, _stream_with_yaw_replays(True, back), channel + "s")
    assert values[names.MSG_YAW] == pytest.approx(yaw_values(199)["YawRate_YawRate"], abs=1e-6)
    assert secured.stats.rx_auth_failed == 200 - 40
    assert secured.stats.rx_rejected == 200 - 40
    assert secured.state.status != mr.STATUS_FAULT and secured.cause == 0


def test_controller_with_secoc_faults_on_forged_sensor_frames_with_cause_auth(channel: str) -> None:
    frames = _stream_with_yaw_replays(True, 0, n=60)
    forger = secoc.SensorSigner(C, bytes(16))  # right freshness and format, wrong key
    alive = mrsteer_dbc.AliveCounter()
    # From frame 30 on, every yaw frame is replaced by a forgery carrying the live alive counter.
    forged, n_yaw = [], 0
    for frame_id, data in frames:
        if frame_id == YAW:
            n_yaw += 1
            counter = alive.next()
            if n_yaw > 30:
                data = forger.sign(names.MSG_YAW, yaw_values(0), counter, EPOCH)
        forged.append((frame_id, data))
    node, values = _controller_run(True, forged, channel)
    assert node.stats.rx_auth_failed == 30
    assert node.cause & names.CAUSE_AUTH and node.state.status == mr.STATUS_FAULT
    assert values[names.MSG_YAW] == pytest.approx(yaw_values(29)["YawRate_YawRate"], abs=1e-6)


def test_sensor_frames_before_the_first_sync_are_unverifiable_not_failed(channel: str) -> None:
    """A controller that starts after the actuator's sync cannot verify what comes before the
    next one: counted apart (``rx_unsynced``), so that ``rx_auth_failed`` stays an alarm."""
    stream = _stream_with_yaw_replays(True, 0)
    first_sync = next(i for i, (fid, _) in enumerate(stream) if fid == C.frame_id(secoc.SYNC))
    second_sync = next(i for i, (fid, _) in enumerate(stream) if fid == C.frame_id(secoc.SYNC) and i > first_sync)
    node, values = _controller_run(True, stream[first_sync + 1:], channel)
    before = second_sync - first_sync - 1  # sensor frames between the missed sync and the next
    assert node.stats.rx_unsynced == before > 0
    assert node.stats.rx_auth_failed == 0 and node.stats.rx_rejected == before
    assert values[names.MSG_YAW] == pytest.approx(yaw_values(199)["YawRate_YawRate"], abs=1e-6)
