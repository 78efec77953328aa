"""The frame path (mrsteer_dbc.link): each rejection and its cause, the order of the receive
checks (tested here once for both nodes), and the send side's counter, signing and CRC."""

from __future__ import annotations

from typing import Mapping

import can
import pytest

import mrsteer_dbc
from mrsteer_dbc import secoc
from mrsteer_dbc.e2e import E2EStatus
from mrsteer_dbc.link import Rejected, RxLink, TxLink
from mrsteer_dbc.names import CAUSE_AUTH, CAUSE_E2E, CAUSE_RANGE, MSG_CMD, MSG_STATUS, MSG_STEER, MSG_YAW, SENSORS

C = mrsteer_dbc.load()
KEY = bytes(range(16))
EPOCH = 1_000_000
YAW = C.frame_id(MSG_YAW)
STATUS = {s.name: 0 for s in C.message(MSG_STATUS).signals}


class Spy:
    """A verifier that records what it was asked and answers as told."""

    def __init__(self, answer: bool = True) -> None:
        self.answer = answer
        self.asked: list[bytes] = []

    def verify(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> bool:
        self.asked.append(data)
        return self.answer


def yaw(counter: int, value: float = 0.01, *, strict: bool = True) -> can.Message:
    data = C.encode(MSG_YAW, {"YawRate_YawRate": value}, counter, strict=strict)
    return can.Message(arbitration_id=YAW, data=data, is_extended_id=False)


def with_crc(data: bytearray) -> bytes:
    data[C.e2e(MSG_YAW).crc_byte] = C.e2e_crc(MSG_YAW, bytes(data))
    return bytes(data)


def link(verifier: object | None = None) -> RxLink:
    return RxLink(C, SENSORS, {MSG_YAW: verifier} if verifier is not None else None)


# ---------------------------------------------------------------------- each outcome


def test_an_accepted_frame_carries_its_name_signals_and_counter() -> None:
    rx = link()
    first, second, jumped = rx.accept(yaw(4, 0.25)), rx.accept(yaw(5)), rx.accept(yaw(8))
    assert first.name == MSG_YAW and first.counter == 4 and first.status is E2EStatus.INITIAL
    assert first.signals["YawRate_YawRate"] == pytest.approx(0.25, abs=1e-6)
    assert second.status is E2EStatus.OK
    assert jumped.status is E2EStatus.OK_SOME_LOST  # 2 frames lost: still within max_delta 3


@pytest.mark.parametrize("msg", [
    can.Message(arbitration_id=YAW, data=bytes(7), is_extended_id=True),
    can.Message(arbitration_id=YAW, is_error_frame=True, is_extended_id=False),
    can.Message(arbitration_id=YAW, is_remote_frame=True, dlc=7, is_extended_id=False),
    can.Message(arbitration_id=C.frame_id(MSG_CMD), data=bytes(8), is_extended_id=False),  # not this link's
    can.Message(arbitration_id=0x7FF, data=bytes(8), is_extended_id=False),  # not in the DBC
], ids=["extended", "error", "remote", "other message", "unknown id"])
def test_frames_that_are_not_the_links_are_ignored_with_no_cause(msg: can.Message) -> None:
    spy = Spy()
    assert link(spy).accept(msg) is Rejected.IGNORED and Rejected.IGNORED.cause == 0
    assert spy.asked == []


def test_each_rejection_names_its_check_and_cause() -> None:
    bad_crc = bytearray(yaw(0).data)
    bad_crc[3] ^= 0x10
    counter_15 = bytearray(C.encode(MSG_YAW, {"YawRate_YawRate": 0.0, "YawRate_Counter": 15}, 0, strict=False))
    counter_15[1] = (counter_15[1] & 0xF0) | 15
    cases = [
        (bytes(yaw(0).data)[:6], Rejected.LENGTH, CAUSE_E2E),
        (bytes(bad_crc), Rejected.CRC, CAUSE_E2E),
        (with_crc(counter_15), Rejected.COUNTER_VALUE, CAUSE_E2E),
        (bytes(yaw(0, 3.2, strict=False).data), Rejected.RANGE, CAUSE_RANGE),
    ]
    for data, reason, cause in cases:
        got = link().accept(can.Message(arbitration_id=YAW, data=data, is_extended_id=False))
        assert got is reason and got.cause == cause, reason
    assert link(Spy(False)).accept(yaw(0)) is Rejected.MAC and Rejected.MAC.cause == CAUSE_AUTH
    rx = link()
    rx.accept(yaw(3))
    assert rx.accept(yaw(3)) is Rejected.REPEATED and Rejected.REPEATED.cause == CAUSE_E2E
    assert rx.accept(yaw(8)) is Rejected.WRONG_SEQUENCE and Rejected.WRONG_SEQUENCE.cause == CAUSE_E2E


# ---------------------------------------------------------------------- the order of the checks


def test_length_then_crc_then_range() -> None:
    out_of_range = bytearray(yaw(0, 3.2, strict=False).data)
    out_of_range[2] ^= 0x01  # still out of range, and now its CRC is wrong too
    short = bytes(out_of_range[:6])
    assert link().accept(can.Message(arbitration_id=YAW, data=short, is_extended_id=False)) is Rejected.LENGTH
    assert link().accept(can.Message(arbitration_id=YAW, data=bytes(out_of_range), is_extended_id=False)) \
        is Rejected.CRC
    assert link().accept(can.Message(arbitration_id=YAW, data=with_crc(out_of_range), is_extended_id=False)) \
        is Rejected.RANGE


def test_the_verifier_is_asked_only_about_frames_that_passed_length_crc_and_range() -> None:
    spy = Spy()
    rx = link(spy)
    bad_crc = bytearray(yaw(0).data)
    bad_crc[0] ^= 0xFF
    for data in (bytes(yaw(0).data)[:3], bytes(bad_crc), bytes(yaw(0, -3.2, strict=False).data)):
        assert type(rx.accept(can.Message(arbitration_id=YAW, data=data, is_extended_id=False))) is Rejected
    assert spy.asked == []
    good = yaw(0)
    assert rx.accept(good).status is E2EStatus.INITIAL and spy.asked == [bytes(good.data)]


def test_the_mac_is_checked_before_the_counter_so_a_forgery_does_not_advance_the_sequence() -> None:
    signer, verifier = secoc.SensorSigner(C, KEY), secoc.SensorVerifier(C, KEY)
    verifier.adopt(EPOCH)
    forger = secoc.SensorSigner(C, bytes(16))  # right format and freshness, wrong key
    rx = link(verifier)

    def frame(by: secoc.SensorSigner, counter: int) -> can.Message:
        data = by.sign(MSG_YAW, {"YawRate_YawRate": 0.01}, counter, EPOCH)
        return can.Message(arbitration_id=YAW, data=data, is_extended_id=False)

    assert rx.accept(frame(signer, 0)).status is E2EStatus.INITIAL
    assert rx.accept(frame(forger, 1)) is Rejected.MAC  # takes the next alive counter, fails its MAC
    # Had the forgery advanced the sequence, counter 1 would now be REPEATED.
    assert rx.accept(frame(signer, 1)).status is E2EStatus.OK
    assert rx.accept(frame(signer, 1)) is Rejected.MAC  # the replay: its freshness is spent


def test_a_rejected_frame_leaves_the_sequence_where_it_was() -> None:
    rx = link(Spy(True))
    rx.accept(yaw(0))
    bad_crc = bytearray(yaw(1).data)
    bad_crc[4] ^= 0x01
    for msg in (can.Message(arbitration_id=YAW, data=bytes(bad_crc), is_extended_id=False),
                yaw(1, 3.2, strict=False)):
        assert type(rx.accept(msg)) is Rejected
    assert rx.accept(yaw(1)).status is E2EStatus.OK  # the next counter after 0, not a repeat or a gap


def test_every_message_keeps_its_own_sequence() -> None:
    rx = link()
    steer = C.encode(MSG_STEER, {"DriverSteer_Angle": 0.0}, 7)
    rx.accept(yaw(7))
    assert rx.accept(can.Message(arbitration_id=C.frame_id(MSG_STEER), data=steer,
                                 is_extended_id=False)).status is E2EStatus.INITIAL


def test_a_verifier_for_a_message_the_link_does_not_receive_is_refused() -> None:
    with pytest.raises(ValueError, match=MSG_CMD):
        RxLink(C, SENSORS, {MSG_CMD: Spy()})


def test_filters_name_exactly_the_links_frames() -> None:
    assert link().filters() == [{"can_id": C.frame_id(n), "can_mask": 0x7FF, "extended": False} for n in SENSORS]


# ---------------------------------------------------------------------- the send side


def test_tx_counts_each_e2e_message_on_its_own_and_seals_every_frame() -> None:
    tx = TxLink(C, (MSG_YAW, MSG_STEER, MSG_STATUS))
    counters = []
    for _ in range(17):
        m = tx.frame(MSG_YAW, {"YawRate_YawRate": 0.02})
        d = C.decode(m.arbitration_id, bytes(m.data))
        assert m.arbitration_id == YAW and not m.is_extended_id and d.status is E2EStatus.OK
        counters.append(d.counter)
        assert tx.counter(MSG_YAW) == d.counter
    assert counters == [k % 15 for k in range(17)]
    assert C.decode(C.frame_id(MSG_STEER), tx.payload(MSG_STEER, {"DriverSteer_Angle": 0.0})).counter == 0
    status = tx.frame(MSG_STATUS, dict(STATUS, CtrlStatus_Cause=8))  # no E2E: no counter
    assert C.decode(status.arbitration_id, bytes(status.data)).signals["CtrlStatus_Cause"] == 8


def test_tx_strict_false_sends_a_saturated_value_as_it_is() -> None:
    with pytest.raises(Exception):
        TxLink(C, (MSG_YAW,)).frame(MSG_YAW, {"YawRate_YawRate": 3.2})
    m = TxLink(C, (MSG_YAW,), strict=False).frame(MSG_YAW, {"YawRate_YawRate": 3.2})
    assert link().accept(m) is Rejected.RANGE  # the receiver range-checks


def test_signed_frames_from_tx_verify_at_rx_and_the_crc_covers_the_mac() -> None:
    signer, verifier = secoc.SensorSigner(C, KEY), secoc.SensorVerifier(C, KEY)
    signer.adopt(EPOCH)
    verifier.adopt(EPOCH)
    tx = TxLink(C, (*SENSORS, MSG_STATUS), signer)
    rx = RxLink(C, SENSORS, dict.fromkeys(SENSORS, verifier))
    stranger = secoc.SensorVerifier(C, bytes(16))
    stranger.adopt(EPOCH)
    other = RxLink(C, SENSORS, dict.fromkeys(SENSORS, stranger))
    for k in range(40):
        m = tx.frame(MSG_YAW, {"YawRate_YawRate": 0.001 * k})
        assert other.accept(m) is Rejected.MAC  # authenticated: another key refuses it
        assert rx.accept(m).signals["YawRate_YawRate"] == pytest.approx(0.001 * k, abs=1e-6)
        flipped = bytearray(m.data)
        flipped[6] ^= 0x01  # a MAC bit: the CRC, computed last, no longer matches
        assert rx.accept(can.Message(arbitration_id=YAW, data=bytes(flipped), is_extended_id=False)) is Rejected.CRC
    status = tx.payload(MSG_STATUS, dict(STATUS, CtrlStatus_Cause=8))
    assert status == C.encode(MSG_STATUS, dict(STATUS, CtrlStatus_Cause=8))  # not signed: as plain as ever


def test_the_signed_command_goes_from_tx_to_rx_and_an_unsynced_one_is_refused() -> None:
    master, signer = secoc.CommandVerifier(C, KEY, lambda: secoc.EPOCH_ORIGIN_S + 1000.0), secoc.CommandSigner(C, KEY)
    tx = TxLink(C, (MSG_CMD,), signer)
    rx = RxLink(C, (MSG_CMD,), {MSG_CMD: master})
    values = {"AuxSteerCmd_State": 1, "AuxSteerCmd_Angle": 0.01, "AuxSteerCmd_MeasCounter": 15}
    assert rx.accept(tx.frame(MSG_CMD, values)) is Rejected.MAC  # no sync yet: SecOC fields 0
    assert signer.accept_sync(master.next_sync())
    for _ in range(20):
        assert rx.accept(tx.frame(MSG_CMD, values)).signals["AuxSteerCmd_Angle"] == pytest.approx(0.01)
    assert master.stats.accepted == 20 and master.stats.failed == 1
