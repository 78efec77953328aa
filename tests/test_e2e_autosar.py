"""mrsteer's E2E against an independent AUTOSAR profile-1 implementation (issue 17).

The oracle is the `autosar-e2e` package (``e2e.p01``, a C extension written from the AUTOSAR
E2E specification): it must accept every frame mrsteer protects, and mrsteer must accept every
frame it protects.  Its API, as used here: ``e2e_p01_check(data, data_id, *, data_id_mode,
length, offset)`` and ``e2e_p01_protect(data, data_id, *, data_id_mode, length, offset,
increment_counter)``, both on a mutable buffer with the CRC in byte 0 and the counter in the
low nibble of byte 1 (variant 1A's offsets 0 and 8).  ``check`` is stateless: it checks the CRC
and rejects counter 15, nothing about the sequence.  ``protect`` with ``increment_counter``
first sets the counter to (counter + 1) mod 15, then writes the CRC.
"""

from __future__ import annotations

import can
import e2e.crc as e2e_crc
import e2e.p01 as e2e_p01
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.controller import node as rt
from mrsteer_dbc import E2EReceiver, E2EStatus
from mrsteer_dbc import names
from sim_plant.car import scenario as scn
from sim_plant.nodes.plant import PlantNode

C = mrsteer_dbc.load()
E2E_MESSAGES = [m.name for m in C.db.messages if C.e2e(m.name) is not None]
SENSORS = (names.MSG_STEER, names.MSG_YAW, names.MSG_SPEED)
MODES = {"LOW": e2e_p01.E2E_P01_DATAID_LOW, "ALT": e2e_p01.E2E_P01_DATAID_ALT,
         "NIBBLE": e2e_p01.E2E_P01_DATAID_NIBBLE}
KEY = bytes(range(16))


def _lib_check(name: str, frame: bytes, mode: int = e2e_p01.E2E_P01_DATAID_BOTH) -> bool:
    return e2e_p01.e2e_p01_check(bytearray(frame), C.e2e(name).data_id, data_id_mode=mode)


def _lib_protect(name: str, frame: bytes, *, increment: bool = False,
                 mode: int = e2e_p01.E2E_P01_DATAID_BOTH) -> bytes:
    buf = bytearray(frame)
    e2e_p01.e2e_p01_protect(buf, C.e2e(name).data_id, data_id_mode=mode, increment_counter=increment)
    return bytes(buf)


def _raw_frame(name: str, body: bytes, counter: int) -> bytearray:
    """Bytes 1..n-1 = body, with the alive counter in byte 1's low nibble; CRC byte 0 zero."""
    data = bytearray(b"\x00" + body)
    data[1] = (data[1] & 0xF0) | counter
    return data


def _mid_values(name: str) -> dict[str, float]:
    """Every data signal of the message at the middle of its DBC range (on its scale grid)."""
    msg, cfg = C.message(name), C.e2e(name)
    return {s.name: round(0.5 * (s.minimum + s.maximum) / s.scale) * s.scale for s in msg.signals
            if s.name not in (cfg.crc_signal, cfg.counter_signal)}


def _bodies(name: str) -> st.SearchStrategy[bytes]:
    n = C.message(name).length - 1
    return st.binary(min_size=n, max_size=n)


def test_the_setup_matches_variant_1a() -> None:
    assert E2E_MESSAGES == ["MRS_AuxSteerCmd", "MRS_DriverSteer", "MRS_YawRate", "MRS_VehicleSpeed",
                            "MRS_RedundantSensors", "MRS_BenchInject"]
    for name in E2E_MESSAGES:
        cfg = C.e2e(name)
        assert cfg.crc_byte == 0  # CRCOffset 0
        counter = C.message(name).get_signal_by_name(cfg.counter_signal)
        assert (counter.start, counter.length) == (8, 4)  # CounterOffset 8: byte 1's low nibble


def test_the_issue_17_demo_frame() -> None:
    assert C.e2e("MRS_YawRate").data_id == 4353
    assert _lib_protect("MRS_YawRate", bytes(8)) == bytes.fromhex("A300000000000000")
    assert C.encode("MRS_YawRate", {"YawRate_YawRate": 0.0, "YawRate_YawRate2": 0.0}, 0) == bytes.fromhex(
        "A300000000000000")
    assert not _lib_check("MRS_YawRate", bytes.fromhex("DF00000000000000"))  # the old single-pass CRC


@given(st.binary(max_size=24), st.integers(0, 255), st.booleans())
def test_crc8_primitive_equals_crc_calculate_crc8(data: bytes, start: int, first: bool) -> None:
    assert mrsteer_dbc.crc8_sae_j1850(data, start, first) == e2e_crc.calculate_crc8(data, start, first)


@pytest.mark.parametrize("name", E2E_MESSAGES)
@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_the_library_accepts_every_frame_the_contract_protects(name: str, data: st.DataObject) -> None:
    frame = _raw_frame(name, data.draw(_bodies(name)), data.draw(st.integers(0, 14)))
    frame[0] = C.e2e_crc(name, bytes(frame))
    assert _lib_check(name, bytes(frame))
    assert _lib_protect(name, bytes(frame)) == bytes(frame)  # the library writes the same CRC


@pytest.mark.parametrize("name", E2E_MESSAGES)
@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_the_contract_accepts_every_frame_the_library_protects(name: str, data: st.DataObject) -> None:
    frame = _lib_protect(name, bytes(_raw_frame(name, data.draw(_bodies(name)), data.draw(st.integers(0, 14)))))
    assert C.e2e_crc(name, frame) == frame[0]
    assert C.decode(C.frame_id(name), frame).status is not E2EStatus.BAD_CRC


@pytest.mark.parametrize("name", E2E_MESSAGES)
def test_encoded_frames_at_every_counter_value_pass_the_library(name: str) -> None:
    values = _mid_values(name)
    for counter in range(15):
        frame = C.encode(name, values, counter)
        assert frame[1] & 0x0F == counter
        assert _lib_check(name, frame), counter


@pytest.mark.parametrize("name", E2E_MESSAGES)
def test_the_library_counter_runs_like_the_alive_counter_and_the_receiver_takes_it(name: str) -> None:
    """15 frames protected with the library's own increment, from counter 14: 0, 1, ..., 14,
    each decoded OK by the contract and in sequence for the receiver (INITIAL, then OK)."""
    msg = C.message(name)
    frame = C.encode(name, _mid_values(name), 14)
    alive, rx = mrsteer_dbc.AliveCounter(), E2EReceiver()
    verdicts = []
    for _ in range(16):
        frame = _lib_protect(name, frame, increment=True)
        d = C.decode(msg.frame_id, frame)
        assert d.status is E2EStatus.OK
        assert d.counter == alive.next()
        verdicts.append(rx.check(d.counter))
    assert verdicts == [E2EStatus.INITIAL] + [E2EStatus.OK] * 15


@pytest.mark.parametrize("name", E2E_MESSAGES)
def test_counter_15_is_refused_by_both_even_with_a_valid_crc(name: str) -> None:
    frame = _raw_frame(name, bytes(C.message(name).length - 1), 15)
    frame[0] = C.e2e_crc(name, bytes(frame))
    assert _lib_protect(name, bytes(frame)) == bytes(frame)  # the CRC is right ...
    assert not _lib_check(name, bytes(frame))  # ... yet the library refuses counter 15
    assert C.decode(C.frame_id(name), bytes(frame)).status is E2EStatus.BAD_COUNTER


@pytest.mark.parametrize("name", E2E_MESSAGES)
def test_every_single_bit_error_is_refused_by_both(name: str) -> None:
    msg = C.message(name)
    good = C.encode(name, _mid_values(name), 6)
    assert _lib_check(name, good)
    for bit in range(8 * len(good)):
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
        assert not _lib_check(name, bytes(bad)), bit
        assert C.decode(msg.frame_id, bytes(bad)).status is E2EStatus.BAD_CRC, bit


@pytest.mark.parametrize("mode", MODES, ids=str)
@pytest.mark.parametrize("name", E2E_MESSAGES)
@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_the_other_data_id_modes_give_other_crcs(name: str, mode: str, data: st.DataObject) -> None:
    """The contract selects E2E_P01_DATAID_BOTH only (variant 1A).  A receiver configured with
    LOW, ALT or NIBBLE computes a different CRC for mrsteer's frames, with one exception: the
    register starts at 0x00, so a data ID low byte of 0x00 adds nothing, and BOTH equals ALT's
    high-byte-only CRC on odd counters for MRS_AuxSteerCmd (0x1000), MRS_DriverSteer (0x1100)
    and MRS_BenchInject (0x1200).  An ALT receiver takes their odd-counter frames and refuses
    the even ones."""
    did = C.e2e(name).data_id
    counter = data.draw(st.integers(0, 14))
    frame = _raw_frame(name, data.draw(_bodies(name)), counter)
    if mode == "NIBBLE":  # variant 1C carries the data ID's high-byte low nibble in byte 1
        frame[1] = (frame[1] & 0x0F) | ((did >> 8) & 0x0F) << 4
    frame[0] = C.e2e_crc(name, bytes(frame))
    other = _lib_protect(name, bytes(frame), mode=MODES[mode])
    assert other[1:] == bytes(frame[1:])
    coincide = mode == "ALT" and counter % 2 == 1 and did & 0xFF == 0
    assert (other[0] == frame[0]) is coincide
    assert _lib_check(name, bytes(frame), MODES[mode]) is coincide


def test_which_data_ids_have_a_zero_low_byte() -> None:
    assert [n for n in E2E_MESSAGES if C.e2e(n).data_id & 0xFF == 0] == ["MRS_AuxSteerCmd", "MRS_DriverSteer",
                                                                          "MRS_BenchInject"]


@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=4, max_size=7))
def test_no_frame_passes_as_another_message(body: bytes) -> None:
    """The same bytes 1..n-1 under the six data IDs: six different library CRCs."""
    ids = [C.e2e(n).data_id for n in E2E_MESSAGES]
    crcs = set()
    for did in ids:
        buf = bytearray(b"\x00" + body)
        e2e_p01.e2e_p01_protect(buf, did, increment_counter=False)
        crcs.add(buf[0])
    assert len(crcs) == len(ids)


@pytest.mark.parametrize("variant", ["P01B", "P01C"])
def test_the_contract_selects_no_other_variant(tmp_path, variant: str) -> None:
    path = tmp_path / "bus.dbc"
    path.write_text(mrsteer_dbc.DBC_PATH.read_text().replace('"E2E_Profile" BO_ 257 "P01A"',
                                                              f'"E2E_Profile" BO_ 257 "{variant}"'))
    with pytest.raises(mrsteer_dbc.ContractError, match=f"unsupported E2E profile '{variant}'"):
        mrsteer_dbc.Contract(path)


# ------------------------------------------------------------------ recorded lockstep runs


class _LockstepBus:
    """The plant's end of an in-process lockstep run: after each yaw-rate frame it sends, the
    controller runs its cycle (drain, control) in this thread, as the controller process does
    on its own when the frame arrives; the command is then waiting in the plant's queue."""

    def __init__(self, inner: can.BusABC, node: rt.ControllerNode) -> None:
        self.inner, self.node, self.yaw_id = inner, node, C.frame_id(names.MSG_YAW)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg)
        if msg.arbitration_id == self.yaw_id:
            self.node.drain()
            self.node.control()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self.inner.recv(0.0)

    def set_filters(self, filters) -> None:
        # Not passed on: with timeout 0, python-can's recv returns None for a frame its software
        # filter drops (the status frame queued after the command) instead of trying the next.
        # The plant ignores frames of other IDs itself.
        pass


class _NoFilters:
    """A bus whose set_filters does nothing (the node's RxLink ignores other IDs itself)."""

    def __init__(self, inner: can.BusABC) -> None:
        self.inner = inner

    def set_filters(self, filters) -> None:
        pass

    def __getattr__(self, name: str):
        return getattr(self.inner, name)


def _record_lockstep(channel: str, scenario: str, secoc: bool) -> tuple[list[can.Message], PlantNode,
                                                                         rt.ControllerNode]:
    key = KEY if secoc else None
    buses = [can.Bus(interface="virtual", channel=channel) for _ in range(3)]
    plant_bus, ctl_bus, log_bus = buses
    try:
        # The controller's filters unset too: python-can's recv(0.0) returns None at a frame its
        # software filter drops (MRS_RedundantSensors, which the controller does not take yet),
        # and the drain would stop before the yaw-rate frame behind it.
        node = rt.ControllerNode(_NoFilters(ctl_bus), rt.RuntimeConfig(secoc_key=key))
        plant = PlantNode(_LockstepBus(plant_bus, node), scn.load(scenario), mode="lockstep", ts=node.period,
                          secoc_key=key)
        plant.run()
        frames = []
        while (m := log_bus.recv(0.0)) is not None:
            frames.append(m)
        return frames, plant, node
    finally:
        for b in buses:
            b.shutdown()


@pytest.mark.parametrize("secoc", [False, True], ids=["e2e", "secoc"])
@pytest.mark.parametrize("scenario", sorted(scn.BUILTINS))
def test_every_frame_of_the_built_in_lockstep_scenarios_passes_the_library(channel: str, scenario: str,
                                                                           secoc: bool) -> None:
    frames, plant, node = _record_lockstep(channel, scenario, secoc)
    assert plant.stats.lockstep_timeouts == 0 and node.stats.rx_rejected == 0
    last: dict[str, int] = {}
    counts = dict.fromkeys(E2E_MESSAGES, 0)
    for m in frames:
        name = C.name_of(m.arbitration_id)
        if name is None or C.e2e(name) is None:
            continue
        data = bytes(m.data)
        assert _lib_check(name, data), (name, data.hex())
        counter = data[1] & 0x0F
        if name in last:  # what E2E_P01Protect sends: one more per frame, modulo 15
            assert counter == (last[name] + 1) % 15, name
        last[name] = counter
        counts[name] += 1
    steps = plant.stats.steps
    assert counts["MRS_YawRate"] == counts["MRS_DriverSteer"] == counts["MRS_AuxSteerCmd"] == steps
    every = round(C.cycle_time_s("MRS_VehicleSpeed") / node.period)  # 20 ms: every 10th step
    assert counts["MRS_VehicleSpeed"] == (steps + every - 1) // every
    assert node.state.status in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED)


# ------------------------------------------------------------------ the controller takes library frames


class _LibrarySensors:
    """Sensor frames as another AUTOSAR ECU sends them: the payload encoded from the DBC with
    CRC 0 and the previous counter, then e2e_p01_protect increments the counter and writes the CRC."""

    def __init__(self, channel: str) -> None:
        self.ctl_bus = can.Bus(interface="virtual", channel=channel)
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.node = rt.ControllerNode(self.ctl_bus, rt.RuntimeConfig(rate_hz=1000.0))
        self.counter = dict.fromkeys((*SENSORS, names.MSG_REDUNDANT), 14)  # the library's first increment sends 0
        self.k = 0

    def frame(self, name: str, value: float) -> bytes:
        msg, cfg = C.message(name), C.e2e(name)
        signal = next(s.name for s in msg.signals if s.name not in (cfg.crc_signal, cfg.counter_signal)
                      and s.initial is None)
        sna = {s.name: "SNA" for s in msg.signals if C.has_sna(name, s.name)}  # no second speed or yaw element
        data = bytearray(msg.encode({**{s.name: 0 for s in msg.signals}, **sna, signal: value,
                                     cfg.counter_signal: self.counter[name]}, strict=True))
        e2e_p01.e2e_p01_protect(data, cfg.data_id, increment_counter=True)
        self.counter[name] = data[1] & 0x0F
        return bytes(data)

    def cycle(self, yaw: float, *, flip: int | None = None) -> dict:
        sends = [(names.MSG_STEER, 0.0)] + ([(names.MSG_SPEED, 20.0)] if self.k % 10 == 0 else []) + (
            [(names.MSG_REDUNDANT, 20.0 * yaw)] if self.k % 50 == 0 else []) + [(names.MSG_YAW, yaw)]
        for name, value in sends:
            data = bytearray(self.frame(name, value))
            if flip is not None and name == names.MSG_YAW:
                data[flip // 8] ^= 1 << (flip % 8)
            self.bus.send(can.Message(arbitration_id=C.frame_id(name), data=bytes(data), is_extended_id=False))
        self.k += 1
        self.node.drain()
        self.node.control()
        cmd = None
        while (m := self.bus.recv(0.0)) is not None:
            if m.arbitration_id == C.frame_id(names.MSG_CMD):
                cmd = C.decode(m.arbitration_id, bytes(m.data))
        assert cmd is not None and cmd.status is E2EStatus.OK
        return cmd.signals

    def close(self) -> None:
        self.ctl_bus.shutdown()
        self.bus.shutdown()


@pytest.fixture
def lib_rig(channel: str):
    r = _LibrarySensors(channel)
    yield r
    r.close()


def test_the_controller_accepts_library_protected_sensor_frames(lib_rig: _LibrarySensors) -> None:
    for _ in range(40):  # 40 yaw-rate frames: the library's counter wraps twice
        sig = lib_rig.cycle(0.02)
    st_ = lib_rig.node.stats
    assert st_.rx_rejected == 0 and st_.rx_frames == 40 + 40 + 4 + 1
    assert lib_rig.node.cause == 0
    assert sig["AuxSteerCmd_State"] == mr.STATUS_ACTIVE
    assert sig["AuxSteerCmd_MeasCounter"] == lib_rig.counter[names.MSG_YAW]  # it answers the library's frame
    assert sig["AuxSteerCmd_Angle"] < 0  # counter-steers the positive yaw rate


def test_a_single_flipped_bit_in_a_library_frame_is_rejected(lib_rig: _LibrarySensors) -> None:
    for _ in range(20):
        lib_rig.cycle(0.02)
    assert lib_rig.node.stats.rx_rejected == 0
    n_bits = 8 * C.message(names.MSG_YAW).length
    for bit in range(n_bits):  # each flip alone, between good frames: rejected, no fault
        before = lib_rig.node.stats.rx_rejected
        lib_rig.cycle(0.02, flip=bit)
        assert lib_rig.node.stats.rx_rejected == before + 1, bit
        sig = lib_rig.cycle(0.02)
        assert lib_rig.node.stats.rx_rejected == before + 1, bit
    assert sig["AuxSteerCmd_State"] == mr.STATUS_ACTIVE and lib_rig.node.cause == 0
    for _ in range(rt.RuntimeConfig().e2e_fail_max):  # three in a row: the yaw rate faults on E2E
        lib_rig.cycle(0.02, flip=13)
    assert lib_rig.node.cause & names.CAUSE_E2E
