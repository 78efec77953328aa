"""The DBC bus contract and its E2E protection."""

from __future__ import annotations

import math

import random

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

import mrsteer_dbc
from firmware_py import model_regulator as mr
from mrsteer_dbc import E2EReceiver, E2EStatus


def _crc8_j1850_bitwise(data: bytes, init: int = 0xFF, xor_out: int = 0xFF) -> int:
    """Independent CRC-8 with poly 0x1D, no reflection; CRC-8/SAE-J1850 with the defaults."""
    crc = init
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ xor_out


@pytest.fixture(scope="module")
def contract() -> mrsteer_dbc.Contract:
    return mrsteer_dbc.load()


def test_dbc_loads_strictly_with_cantools() -> None:
    db = cantools.database.load_file(str(mrsteer_dbc.DBC_PATH), strict=True)
    names = {m.name for m in db.messages}
    assert {"MRS_DriverSteer", "MRS_YawRate", "MRS_VehicleSpeed", "MRS_AuxSteerCmd", "MRS_CtrlStatus",
            "MRS_BenchInject"} <= names
    assert {n.name for n in db.nodes} == {"VEHICLE", "MRCTRL", "BENCH"}
    for m in db.messages:
        assert m.cycle_time, f"{m.name} has no GenMsgCycleTime"
        for s in m.signals:
            assert s.minimum is not None and s.maximum is not None, f"{s.name} has no range"


def test_every_safety_relevant_message_is_e2e_protected(contract: mrsteer_dbc.Contract) -> None:
    for name in ("MRS_DriverSteer", "MRS_YawRate", "MRS_VehicleSpeed", "MRS_AuxSteerCmd", "MRS_BenchInject"):
        cfg = contract.e2e(name)
        assert cfg is not None and cfg.crc_byte == 0
    ids = [contract.e2e(n).data_id for n in ("MRS_DriverSteer", "MRS_YawRate", "MRS_VehicleSpeed",
                                            "MRS_AuxSteerCmd", "MRS_BenchInject")]
    assert len(set(ids)) == len(ids)  # a frame cannot masquerade as another


@pytest.mark.parametrize("data,expected", [(b"123456789", 0x4B), (b"\x00\x00\x00\x00", 0x59),
                                           (b"\xF2\x01\x83", 0x37), (b"\xFF\xFF\xFF\xFF", 0x74)])
def test_crc8_known_vectors(data: bytes, expected: int) -> None:
    # AUTOSAR CRC library check values for CRC-8/SAE-J1850.
    assert mrsteer_dbc.crc8_sae_j1850(data) == expected
    assert _crc8_j1850_bitwise(data) == expected


def test_e2e_crc_covers_data_id_and_payload(contract: mrsteer_dbc.Contract) -> None:
    data = contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.1234}, counter=7)
    did = contract.e2e("MRS_YawRate").data_id
    # AUTOSAR R4 profile 1: polynomial 0x1D from register 0x00, no final XOR, over
    # (data ID low, data ID high, bytes 1..n-1).
    assert data[0] == _crc8_j1850_bitwise(bytes((did & 0xFF, did >> 8)) + data[1:], init=0x00, xor_out=0x00)
    assert data[0] != _crc8_j1850_bitwise(bytes((did & 0xFF, did >> 8)) + data[1:])  # not the old single pass
    assert data[1] & 0x0F == 7


# E2E_P01 CRCs (data ID mode BOTH), each computed by the independent `autosar-e2e` package
# (e2e.p01.e2e_p01_protect(..., increment_counter=False)); the first is issue 17's demo frame.
P01_FRAMES = [
    ("MRS_YawRate", "DF00000000000000", 0xA3),
    ("MRS_YawRate", "0003313233343536", 0x9A),
    ("MRS_AuxSteerCmd", "0000000000000000", 0x99),
    ("MRS_DriverSteer", "0000000000", 0x84),
    ("MRS_VehicleSpeed", "00FFFFFFFF", 0x25),
    ("MRS_BenchInject", "0007D00700", 0x8F),
]


@pytest.mark.parametrize("name,frame,expected", P01_FRAMES)
def test_e2e_crc_known_profile_1_values(contract: mrsteer_dbc.Contract, name: str, frame: str,
                                        expected: int) -> None:
    data = bytes.fromhex(frame)
    assert contract.e2e_crc(name, data) == expected
    fid = contract.frame_id(name)
    # The receiver takes that CRC (a frame may still fail later checks, e.g. counter 15) ...
    assert contract.decode(fid, bytes((expected,)) + data[1:]).status is not E2EStatus.BAD_CRC
    # ... and no other.
    assert contract.decode(fid, bytes((expected ^ 0x01,)) + data[1:]).status is E2EStatus.BAD_CRC


def test_crc8_chains_like_crc_calculate_crc8() -> None:
    """Crc_CalculateCRC8 semantics: a later call resumes from the previous result, and the
    profile-1 chain from start value 0xFF is the bare polynomial from register 0x00."""
    data = b"123456789"
    first = mrsteer_dbc.crc8_sae_j1850(data[:4])
    assert mrsteer_dbc.crc8_sae_j1850(data[4:], first, False) == 0x4B
    assert mrsteer_dbc.crc8_sae_j1850(data, 0x00, True) == 0x4B  # the start value is ignored on a first call
    assert mrsteer_dbc.crc8_sae_j1850(data, 0xFF, False) ^ 0xFF == _crc8_j1850_bitwise(data, 0x00, 0x00)


def test_round_trip_every_protected_message(contract: mrsteer_dbc.Contract) -> None:
    rng = random.Random(3)
    for name in ("MRS_DriverSteer", "MRS_YawRate", "MRS_VehicleSpeed", "MRS_AuxSteerCmd", "MRS_BenchInject"):
        msg = contract.message(name)
        for _ in range(50):
            values = {}
            for s in msg.signals:
                if s.name.endswith(("_CRC", "_Counter")):
                    continue
                lo, hi = s.minimum, s.maximum
                values[s.name] = round(rng.uniform(lo, hi) / s.scale) * s.scale if s.scale != 1 else rng.randint(
                    int(lo), int(hi))
                values[s.name] = min(max(values[s.name], lo), hi)
            counter = rng.randrange(15)
            d = contract.decode(msg.frame_id, contract.encode(name, values, counter))
            assert d.status is E2EStatus.OK and d.counter == counter
            for k, v in values.items():
                assert d.signals[k] == pytest.approx(v, abs=msg.get_signal_by_name(k).scale)


def test_corruption_is_detected(contract: mrsteer_dbc.Contract) -> None:
    fid = contract.frame_id("MRS_YawRate")
    good = contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.05}, counter=3)
    for byte in range(len(good)):
        for bit in range(8):
            bad = bytearray(good)
            bad[byte] ^= 1 << bit
            assert contract.decode(fid, bytes(bad)).status is E2EStatus.BAD_CRC  # every single-bit error
    assert contract.decode(fid, good[:-1]).status is E2EStatus.BAD_LENGTH
    assert contract.decode(fid, good + b"\x00").status is E2EStatus.BAD_LENGTH
    # A valid frame of another message cannot pass as this one: the data ID differs.
    other = contract.encode("MRS_DriverSteer", {"DriverSteer_Angle": 0.01}, counter=3)
    assert contract.decode(fid, other + b"\x00\x00\x00").status is E2EStatus.BAD_CRC
    assert contract.decode(0x7FF, good) is None


def test_out_of_range_and_bad_counter_are_rejected(contract: mrsteer_dbc.Contract) -> None:
    fid = contract.frame_id("MRS_YawRate")
    hot = contract.encode("MRS_YawRate", {"YawRate_YawRate": 3.2}, counter=1, strict=False)
    assert contract.decode(fid, hot).status is E2EStatus.OUT_OF_RANGE
    # Past what the signal's 16 bits carry it saturates there (+-3.2767/-3.2768 rad/s), not an
    # encoder's overflow; and short of an SNA raw value at the field's end (Speed2's 255).
    for value, carried in ((50.0, 3.2767), (-math.inf, -3.2768)):
        frame = contract.decode(fid, contract.encode("MRS_YawRate", {"YawRate_YawRate": value}, counter=1,
                                                     strict=False))
        assert frame.status is E2EStatus.OUT_OF_RANGE and frame.signals["YawRate_YawRate"] == carried
    red = contract.decode(contract.frame_id("MRS_RedundantSensors"), contract.encode(
        "MRS_RedundantSensors", {"RedundantSensors_LatAccel": 0.0, "RedundantSensors_SteerAngle": 0.0,
                                 "RedundantSensors_Speed2": 100.0}, counter=1, strict=False))
    assert red.signals["RedundantSensors_Speed2"] == pytest.approx(76.2)  # raw 254, not SNA's 255
    # Counter 15 is never sent in profile 1; forge one with a correct CRC.
    data = bytearray(contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.0}, counter=1))
    data[1] = (data[1] & 0xF0) | 0x0F
    data[0] = contract.e2e_crc("MRS_YawRate", bytes(data))
    assert contract.decode(fid, bytes(data)).status is E2EStatus.BAD_COUNTER


def test_receiver_counter_sequence() -> None:
    rx = E2EReceiver(max_delta=3)
    assert rx.check(5) is E2EStatus.INITIAL
    assert rx.check(6) is E2EStatus.OK
    assert rx.check(6) is E2EStatus.REPEATED
    assert rx.check(8) is E2EStatus.OK_SOME_LOST
    assert rx.check(14) is E2EStatus.WRONG_SEQUENCE  # jump of 6
    assert rx.check(0) is E2EStatus.OK  # wraps 14 -> 0 (modulo 15), re-synchronised
    assert rx.check(13) is E2EStatus.WRONG_SEQUENCE  # a replayed old frame
    assert all(s.accepted for s in (E2EStatus.OK, E2EStatus.OK_SOME_LOST, E2EStatus.INITIAL))
    assert not any(s.accepted for s in (E2EStatus.REPEATED, E2EStatus.WRONG_SEQUENCE, E2EStatus.BAD_CRC))


def test_alive_counter_wraps_at_fifteen() -> None:
    c = mrsteer_dbc.AliveCounter()
    assert [c.next() for _ in range(17)] == list(range(15)) + [0, 1]


def test_firmware_ranges_agree_with_the_dbc(contract: mrsteer_dbc.Contract) -> None:
    d = mr.ControllerConfig()
    assert contract.signal_range("MRS_DriverSteer", "DriverSteer_Angle") == (-d.driver_angle_max, d.driver_angle_max)
    assert contract.signal_range("MRS_YawRate", "YawRate_YawRate") == (-d.yaw_rate_max, d.yaw_rate_max)
    assert contract.signal_range("MRS_VehicleSpeed", "VehicleSpeed_Speed")[1] == d.speed_max
    lo, hi = contract.signal_range("MRS_AuxSteerCmd", "AuxSteerCmd_Angle")
    assert hi >= d.aux_limit and hi - d.aux_limit < 1e-3 and lo == -hi


STATES = {0: "INACTIVE", 1: "ACTIVE", 2: "SATURATED", 3: "FAULT", 4: "DEGRADED", 5: "STARTING"}


def test_both_state_signals_carry_the_six_states_of_the_firmware_and_the_c_port(contract: mrsteer_dbc.Contract) -> None:
    from pathlib import Path

    for msg, sig in (("MRS_AuxSteerCmd", "AuxSteerCmd_State"), ("MRS_CtrlStatus", "CtrlStatus_State")):
        s = contract.message(msg).get_signal_by_name(sig)
        assert {int(k): str(v) for k, v in s.choices.items()} == STATES, sig
        assert (s.length, s.is_signed, s.minimum, s.maximum) == (3, False, 0, 5), sig
    python = {name: getattr(mr, f"STATUS_{name}") for name in STATES.values()}
    assert python == {name: value for value, name in STATES.items()}
    header = (Path(__file__).resolve().parents[1] / "ports" / "c" / "mrs_controller.h").read_text()
    for name, value in python.items():
        assert f"#define MRS_STATUS_{name} {value}u\n" in header, name


def test_the_two_messages_that_carry_the_state_lose_no_signal(contract: mrsteer_dbc.Contract) -> None:
    """The command and the status: every signal of each in its own bits of the frame, the SecOC
    epoch bit moved next to the wider state, the status's overrun counter 13 bits (its comment
    says why), and the frames' lengths (so the bus load) as they were."""
    layout = {
        "MRS_AuxSteerCmd": {"AuxSteerCmd_CRC": (0, 8), "AuxSteerCmd_Counter": (8, 4), "AuxSteerCmd_State": (12, 3),
                            "AuxSteerCmd_FvEpoch": (15, 1), "AuxSteerCmd_Angle": (16, 24),
                            "AuxSteerCmd_MeasCounter": (40, 4), "AuxSteerCmd_FvCounter": (44, 4),
                            "AuxSteerCmd_MAC": (48, 16)},
        "MRS_CtrlStatus": {"CtrlStatus_State": (0, 3), "CtrlStatus_Plausibility": (3, 3), "CtrlStatus_Cause": (8, 8),
                           "CtrlStatus_Rejected": (16, 16), "CtrlStatus_InputFlags": (32, 3),
                           "CtrlStatus_Overruns": (35, 13), "CtrlStatus_MaxLateness": (48, 16)},
    }
    for name, signals in layout.items():
        m = contract.message(name)
        assert m.length == 8
        assert {s.name: (s.start, s.length) for s in m.signals} == signals
    overruns = contract.message("MRS_CtrlStatus").get_signal_by_name("CtrlStatus_Overruns")
    assert "13 bits" in overruns.comment and "50 between two status frames" in overruns.comment
    for m in contract.db.messages:  # no two signals share a bit, none leaves its frame
        bits = [b for s in m.signals for b in range(s.start, s.start + s.length)]
        assert len(bits) == len(set(bits)) and max(bits) < 8 * m.length, m.name
    from mrsteer_dbc.busload import bus_load

    assert bus_load(contract, 500e3).load_percent_worst < 40.0  # the budget (docs/can-runtime.md)


def test_every_state_round_trips_through_both_frames(contract: mrsteer_dbc.Contract) -> None:
    cmd, status = contract.frame_id("MRS_AuxSteerCmd"), contract.frame_id("MRS_CtrlStatus")
    for state in STATES:
        d = contract.decode(cmd, contract.encode("MRS_AuxSteerCmd", {"AuxSteerCmd_State": state,
                                                                     "AuxSteerCmd_Angle": -0.01,
                                                                     "AuxSteerCmd_MeasCounter": 7}, counter=3))
        assert d is not None and d.status is E2EStatus.OK and d.signals["AuxSteerCmd_State"] == state
        values = {"CtrlStatus_State": state, "CtrlStatus_InputFlags": 7, "CtrlStatus_Plausibility": 5,
                  "CtrlStatus_Cause": 0xA5, "CtrlStatus_Rejected": 65535, "CtrlStatus_Overruns": 8191,
                  "CtrlStatus_MaxLateness": 0.01}
        d = contract.decode(status, contract.encode("MRS_CtrlStatus", values))
        assert d is not None and d.status is E2EStatus.OK
        assert d.signals == pytest.approx(values)


def test_a_command_is_never_sent_beyond_the_value_computed(contract: mrsteer_dbc.Contract) -> None:
    """AuxSteerCmd_Angle rounds toward zero (MRS_RoundTowardZero): the 3 deg limit, which the
    nearest raw value would send as 3.00001 deg, reads 2.99995 deg; a value on the 1e-6 rad grid
    (a decoded command re-encoded) keeps its raw value; other signals still round to nearest."""
    fid = contract.frame_id("MRS_AuxSteerCmd")
    assert mrsteer_dbc.contract.rounds_toward_zero(
        contract.message("MRS_AuxSteerCmd").get_signal_by_name("AuxSteerCmd_Angle"))

    def sent(angle: float) -> float:
        d = contract.decode(fid, contract.encode("MRS_AuxSteerCmd", {"AuxSteerCmd_State": 2, "AuxSteerCmd_Angle": angle,
                                                                     "AuxSteerCmd_MeasCounter": 0}, counter=0))
        assert d is not None and d.status is E2EStatus.OK
        return d.signals["AuxSteerCmd_Angle"]

    limit = math.radians(3.0)
    assert sent(limit) == pytest.approx(0.052359, abs=1e-12) and sent(-limit) == -sent(limit)
    assert round(math.degrees(sent(limit)), 5) == 2.99995 and math.degrees(sent(limit)) <= 3.0
    rng = random.Random(5)
    for _ in range(2000):
        x = rng.uniform(-0.0524, 0.0524)
        y = sent(x)
        assert abs(y) <= abs(x) and abs(x - y) < 1e-6 and y * x >= 0.0
    for k in (-52359, -123, -1, 0, 1, 123, 246, 253, 52359):  # 246e-6 / 1e-6 = 245.99999999999997
        assert sent(k * 1e-6) == k * 1e-6
    # the status's lateness at its maximum (the node's clamp) decodes inside its range: 65534, not 65535
    status = {"CtrlStatus_State": 1, "CtrlStatus_InputFlags": 0, "CtrlStatus_Plausibility": 0, "CtrlStatus_Cause": 0,
              "CtrlStatus_Rejected": 0, "CtrlStatus_Overruns": 0, "CtrlStatus_MaxLateness": 0.65535}
    d = contract.decode(contract.frame_id("MRS_CtrlStatus"), contract.encode("MRS_CtrlStatus", status))
    assert d is not None and d.status is E2EStatus.OK and d.signals["CtrlStatus_MaxLateness"] == pytest.approx(0.65534)
    # a sensor still rounds to the nearest raw value: 0.0001 + 0.6 LSB reads one LSB up
    yaw = contract.decode(contract.frame_id("MRS_YawRate"),
                          contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.00016}, counter=1))
    assert yaw is not None and yaw.signals["YawRate_YawRate"] == pytest.approx(0.0002)


def test_a_broken_dbc_is_a_clear_error(tmp_path) -> None:
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ this is not a dbc")
    with pytest.raises(mrsteer_dbc.ContractError, match="cannot load DBC"):
        mrsteer_dbc.Contract(bad)
    with pytest.raises(mrsteer_dbc.ContractError, match="not found"):
        mrsteer_dbc.Contract(tmp_path / "missing.dbc")


@given(st.binary(max_size=16))
def test_table_crc_equals_crccheck(data: bytes) -> None:
    from crccheck.crc import Crc8SaeJ1850

    assert mrsteer_dbc.crc8_sae_j1850(data) == Crc8SaeJ1850.calc(data)


@given(st.binary(max_size=16), st.integers(0, 255))
def test_chained_crc_equals_the_bitwise_reference(data: bytes, start: int) -> None:
    assert mrsteer_dbc.crc8_sae_j1850(data, start, False) == _crc8_j1850_bitwise(data, init=start ^ 0xFF)


def test_every_name_in_names_is_in_the_dbc(contract: mrsteer_dbc.Contract) -> None:
    from mrsteer_dbc import names

    messages = {v for k, v in vars(names).items() if k.startswith("MSG_")}
    assert messages == {m.name for m in contract.db.messages}  # every message named, none invented
    assert set(names.VEHICLE_SENSORS) == {m.name for m in contract.db.messages if m.senders == ["VEHICLE"]} - {names.MSG_SYNC}
    assert set(names.SENSORS).isdisjoint(names.REDUNDANT_SENSORS)
    signals = {v for k, v in vars(names).items() if k.startswith("SIG_")}
    in_dbc = {s.name: m.name for m in contract.db.messages for s in m.signals}
    assert signals <= set(in_dbc)
    for message, signal in names.SENSOR_SIGNAL.items():
        assert in_dbc[signal] == message


def test_cause_bits_and_meas_none_are_what_the_dbc_says(contract: mrsteer_dbc.Contract) -> None:
    from mrsteer_dbc import names

    comment = contract.message(names.MSG_STATUS).get_signal_by_name(names.SIG_STATUS_CAUSE).comment
    said = {names.CAUSE_STEER_MISSING: "1 driver angle missing", names.CAUSE_YAW_MISSING: "2 yaw rate missing",
            names.CAUSE_SPEED_MISSING: "4 speed missing", names.CAUSE_E2E: "8 E2E errors",
            names.CAUSE_RANGE: "16 input out of range", names.CAUSE_LOW_SPEED: "32 below activation speed",
            names.CAUSE_AUTH: "64 (SecOC on)", names.CAUSE_PLAUSIBILITY: "128 plausibility fault"}
    for bit, words in said.items():
        assert words in comment and int(words.split()[0]) == bit
    causes = [v for k, v in vars(names).items() if k.startswith("CAUSE_")]
    assert sorted(causes) == sorted(said) and sum(causes) == 0xFF  # distinct single bits
    plaus = contract.message(names.MSG_STATUS).get_signal_by_name(names.SIG_STATUS_PLAUS).comment
    for bit, words in {names.PLAUS_YAW: "1 yaw rate implausible", names.PLAUS_STEER: "2 steering angle implausible",
                       names.PLAUS_DEGRADED: "4 degraded"}.items():
        assert words in plaus and int(words.split()[0]) == bit
    meas = contract.message(names.MSG_CMD).get_signal_by_name(names.SIG_CMD_MEAS)
    assert {int(k): str(v) for k, v in meas.choices.items()} == {names.MEAS_NONE: "NONE"}


def test_the_second_yaw_rate_element_left_out_or_nan_is_sent_as_sna_and_read_as_nan(
        contract: mrsteer_dbc.Contract) -> None:
    fid = contract.frame_id("MRS_YawRate")
    sig = contract.message("MRS_YawRate").get_signal_by_name("YawRate_YawRate2")
    assert contract.has_sna("MRS_YawRate", "YawRate_YawRate2")
    assert not contract.has_sna("MRS_YawRate", "YawRate_YawRate")
    left_out = contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.1}, counter=2)
    as_nan = contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.1, "YawRate_YawRate2": float("nan")}, counter=2)
    assert left_out == as_nan
    # Raw -32768 (bytes 4-5, little endian: 00 80), the DBC's SNA
    assert left_out[sig.start // 8:sig.start // 8 + 2] == bytes.fromhex("0080")
    d = contract.decode(fid, left_out)
    assert d.status is E2EStatus.OK and d.signals["YawRate_YawRate2"] != d.signals["YawRate_YawRate2"]
    both = contract.decode(fid, contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.1, "YawRate_YawRate2": -0.25}, 3))
    assert both.status is E2EStatus.OK and both.signals["YawRate_YawRate2"] == pytest.approx(-0.25, abs=5e-5)
    # The raw value next to SNA is an ordinary value, out of range as before.
    near = contract.encode("MRS_YawRate", {"YawRate_YawRate": 0.1, "YawRate_YawRate2": -3.2767}, 4, strict=False)
    assert contract.decode(fid, near).status is E2EStatus.OUT_OF_RANGE
    # The first element has no SNA: its out-of-range values stay out of range.
    assert contract.decode(fid, contract.encode("MRS_YawRate", {"YawRate_YawRate": -3.2768}, 5,
                                                strict=False)).status is E2EStatus.OUT_OF_RANGE


@pytest.mark.parametrize("v", [10.0, 20.0, 40.0])
def test_the_lateral_acceleration_carries_the_paper_s_figure_8_at_each_of_its_speeds(
        contract: mrsteer_dbc.Contract, v: float) -> None:
    # Figure 8's step is normalised to a unit yaw rate, so its linear car's a_y is v m/s^2 (and
    # its overshoot a little more): valid and unsaturated in the frame, to its LSB.
    a_y = 1.2 * v
    frame = contract.decode(contract.frame_id("MRS_RedundantSensors"), contract.encode(
        "MRS_RedundantSensors", {"RedundantSensors_LatAccel": -a_y, "RedundantSensors_SteerAngle": 0.0}, counter=1))
    assert frame.status is E2EStatus.OK
    assert frame.signals["RedundantSensors_LatAccel"] == pytest.approx(-a_y, abs=0.002)
