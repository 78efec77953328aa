"""SecOC-style authentication of the steering command (mrsteer_dbc.secoc) and its use by the
controller and the plant: RFC 4493 vectors, freshness, forgery, replay, loss, restarts, keys."""

from __future__ import annotations

import dataclasses

import os
import subprocess
import sys
from pathlib import Path

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import mrsteer_dbc
from firmware_py.controller import node as rt
from mrsteer_dbc import secoc
from mrsteer_dbc import names
from sim_plant.car import scenario as scn
from sim_plant.nodes.plant import PlantNode

C = mrsteer_dbc.load()
CMD = C.frame_id(secoc.COMMAND)
SYNC_ID = C.frame_id(secoc.SYNC)
KEY = bytes(range(16))
T0 = secoc.EPOCH_ORIGIN_S + 1000.0
VALUES = {"AuxSteerCmd_State": 1, "AuxSteerCmd_Angle": 0.01, "AuxSteerCmd_MeasCounter": 15}


class Clock:
    def __init__(self, t: float = T0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def pair(clock: Clock | None = None) -> tuple[secoc.CommandSigner, secoc.CommandVerifier, mrsteer_dbc.AliveCounter]:
    verifier = secoc.CommandVerifier(C, KEY, clock or Clock())
    signer = secoc.CommandSigner(C, KEY)
    assert signer.accept_sync(verifier.next_sync())
    return signer, verifier, mrsteer_dbc.AliveCounter()


def accepts(verifier: secoc.CommandVerifier, data: bytes) -> bool:
    """The actuator's verdict on a command, asked the way the link asks it: only of a frame that
    passed length, CRC and range."""
    decoded = C.decode(CMD, data)
    return decoded.status is mrsteer_dbc.E2EStatus.OK and verifier.verify(CMD, data, decoded.signals)


def signed(signer: secoc.CommandSigner, counter: mrsteer_dbc.AliveCounter, angle: float = 0.01) -> bytes:
    data = signer.sign(dict(VALUES, AuxSteerCmd_Angle=angle), counter.next())
    assert C.decode(CMD, data).status is mrsteer_dbc.E2EStatus.OK  # the CRC covers the MAC
    return data


# ---------------------------------------------------------------------- primitives


@pytest.mark.parametrize("message, mac", [  # RFC 4493 section 4, AES-128 key 2b7e1516...
    ("", "bb1d6929e95937287fa37d129b756746"),
    ("6bc1bee22e409f96e93d7e117393172a", "070a16b46b4d4144f79bdd9dd04a287c"),
    ("6bc1bee22e409f96e93d7e117393172aae2d8a571e03ac9c9eb76fac45af8e5130c81c46a35ce411",
     "dfa66747de9ae63030ca32611497c827"),
])
def test_cmac_matches_rfc4493_and_truncates_to_the_leading_bits(message: str, mac: str) -> None:
    cmac = secoc.TruncatedCmac(bytes.fromhex("2b7e151628aed2a6abf7158809cf4f3c"))
    data = bytes.fromhex(message)
    assert cmac(data, 128) == int(mac, 16)
    assert cmac(data, 16) == int(mac[:4], 16)
    assert cmac(data, 24) == int(mac[:6], 16)


def test_layout_comes_from_the_dbc() -> None:
    lay = secoc.Layout.of(C)
    assert (lay.mac_bits, lay.counter_low_bits, lay.sync_mac_bits, lay.sync_epoch_bits) == (16, 4, 24, 40)
    cmd = C.message(secoc.COMMAND)
    assert cmd.length == 8
    used = sum(s.length for s in cmd.signals)
    assert used == 64  # 43 bits of E2E and data (the state 3 bits), 21 of SecOC: none spare


def test_a_dbc_without_the_secoc_fields_is_refused(tmp_path: Path) -> None:
    text = mrsteer_dbc.DBC_PATH.read_text().replace("AuxSteerCmd_MAC", "AuxSteerCmd_Spare")
    path = tmp_path / "old.dbc"
    path.write_text(text)
    with pytest.raises(secoc.SecOCError, match="AuxSteerCmd_MAC"):
        secoc.CommandSigner(mrsteer_dbc.Contract(path), KEY)


# ---------------------------------------------------------------------- keys


def test_key_from_file_and_from_environment(tmp_path: Path) -> None:
    f = tmp_path / "k.hex"
    f.write_text(KEY.hex().upper() + "\n")
    assert secoc.load_key(f) == KEY
    assert secoc.load_key(None, {secoc.KEY_ENV: KEY.hex()}) == KEY


@pytest.mark.parametrize("content, message", [
    ("zz" * 16, "not hexadecimal"),
    ("00" * 15, "must be 16 bytes"),
    ("00" * 17, "must be 16 bytes"),
])
def test_bad_keys_are_named(tmp_path: Path, content: str, message: str) -> None:
    f = tmp_path / "k.hex"
    f.write_text(content)
    with pytest.raises(secoc.SecOCError, match=message):
        secoc.load_key(f)
    with pytest.raises(secoc.SecOCError, match=message):
        secoc.load_key(None, {secoc.KEY_ENV: content})


def test_missing_keys_are_named(tmp_path: Path) -> None:
    with pytest.raises(secoc.SecOCError, match=secoc.KEY_ENV):
        secoc.load_key(None, {})
    with pytest.raises(secoc.SecOCError, match="cannot read the SecOC key file"):
        secoc.load_key(tmp_path / "absent")


# ---------------------------------------------------------------------- freshness


def test_every_signed_command_verifies_once() -> None:
    signer, verifier, ctr = pair()
    for _ in range(40):  # beyond the 4-bit window and the E2E counter's wrap
        data = signed(signer, ctr)
        assert accepts(verifier, data)
        assert not accepts(verifier, data)  # the same frame again: replay
    assert verifier.stats.accepted == 40 and verifier.stats.failed == 40


def test_a_changed_bit_anywhere_fails() -> None:
    signer, verifier, ctr = pair()
    data = signed(signer, ctr)
    # Every bit but the CRC's and the MAC's own, the spare bit 15 included, with the CRC made
    # valid again: only the MAC can tell.
    for bit in range(8, 48):
        forged = bytearray(data)
        forged[bit // 8] ^= 1 << (bit % 8)
        forged[0] = C.e2e_crc(secoc.COMMAND, bytes(forged))
        decoded = C.decode(CMD, bytes(forged))
        assert decoded.status in (mrsteer_dbc.E2EStatus.OK, mrsteer_dbc.E2EStatus.OUT_OF_RANGE)
        # Asked even where the range check would refuse the frame first: the MAC alone must tell.
        assert not verifier.verify(CMD, bytes(forged), decoded.signals)
    assert accepts(verifier, data)  # the forgeries did not move the freshness on


def test_a_different_key_fails() -> None:
    signer, verifier, ctr = pair()
    other = secoc.CommandSigner(C, bytes(16))
    other.epoch = signer.epoch  # knows the freshness, not the key
    assert not accepts(verifier, other.sign(VALUES, ctr.next()))


def test_up_to_15_lost_commands_are_bridged_more_resync_at_the_next_epoch() -> None:
    clock = Clock()
    signer, verifier, ctr = pair(clock)
    assert accepts(verifier, signed(signer, ctr))
    for _ in range(15):
        signed(signer, ctr)  # lost
    assert accepts(verifier, signed(signer, ctr))
    for _ in range(16):
        signed(signer, ctr)
    assert not accepts(verifier, signed(signer, ctr))  # low bits now ambiguous
    clock.t += 0.1
    assert signer.accept_sync(verifier.next_sync())
    assert accepts(verifier, signed(signer, ctr))


def test_a_command_of_the_previous_epoch_still_in_flight_verifies_older_ones_do_not() -> None:
    clock = Clock()
    signer, verifier, ctr = pair(clock)
    in_flight = signed(signer, ctr)
    clock.t += 0.1
    verifier.next_sync()  # the signer has not received it yet
    assert accepts(verifier, in_flight)
    two_old = signed(signer, ctr)
    clock.t += 0.1
    verifier.next_sync()
    assert not accepts(verifier, two_old)  # its low epoch bit now names the current epoch


def test_recorded_commands_are_refused_after_newer_ones() -> None:
    clock = Clock()
    signer, verifier, ctr = pair(clock)
    recorded = [signed(signer, ctr) for _ in range(150)]  # 0.3 s at 500 Hz: counter-aligned (150 = 10 * 15)
    for data in recorded[:10]:
        assert accepts(verifier, data)
    clock.t += 0.1
    signer.accept_sync(verifier.next_sync())
    assert accepts(verifier, signed(signer, ctr))
    assert not any(accepts(verifier, data) for data in recorded)


def test_epochs_increase_alternate_and_survive_a_restart() -> None:
    clock = Clock()
    v = secoc.CommandVerifier(C, KEY, clock)
    epochs = []
    for _ in range(5):
        v.next_sync()
        epochs.append(v.current)
    assert all(b > a and (a ^ b) & 1 for a, b in zip(epochs, epochs[1:]))
    assert epochs[0] == round((T0 - secoc.EPOCH_ORIGIN_S) * 1000)
    clock.t += 0.1 * 5  # restarted after its syncs: the clock has moved past every epoch issued
    restarted = secoc.CommandVerifier(C, KEY, clock)
    restarted.next_sync()
    assert restarted.current > epochs[-1]


def test_signer_takes_only_authentic_newer_syncs() -> None:
    clock = Clock()
    signer, verifier, _ = pair(clock)
    old = verifier.next_sync()
    assert signer.accept_sync(old)
    assert not signer.accept_sync(old)  # replayed
    clock.t += 0.1
    forged = bytearray(verifier.next_sync())
    forged[0] ^= 0x02  # another epoch, the old MAC
    assert not signer.accept_sync(bytes(forged))
    assert signer.syncs_rejected == 2


def test_unsynced_signer_sends_zero_authenticator_and_is_refused() -> None:
    signer = secoc.CommandSigner(C, KEY)
    verifier = secoc.CommandVerifier(C, KEY, Clock())
    verifier.next_sync()
    data = signer.sign(VALUES, 0)
    raw = C.message(secoc.COMMAND).decode(data, decode_choices=False, scaling=False)
    assert raw["AuxSteerCmd_MAC"] == 0 and not accepts(verifier, data)


@settings(max_examples=300, deadline=None)
@given(data=st.binary(min_size=8, max_size=8))
def test_random_frames_never_raise(data: bytes) -> None:
    signer, verifier, _ = pair()
    decoded = C.decode(CMD, data)
    if decoded.status is mrsteer_dbc.E2EStatus.OK:
        assert verifier.verify(CMD, data, decoded.signals) in (True, False)
    assert signer.accept_sync(data) in (True, False)


# ---------------------------------------------------------------------- the plant (actuator)


@pytest.fixture
def plant(channel: str):
    plant_bus = can.Bus(interface="virtual", channel=channel)
    ctl = can.Bus(interface="virtual", channel=channel)
    node = PlantNode(plant_bus, scn.load("paper-fig9"), mode="realtime", ts=1e-3, secoc_key=KEY)
    yield node, ctl
    plant_bus.shutdown()
    ctl.shutdown()


def _sync_from(ctl: can.BusABC, signer: secoc.CommandSigner) -> None:
    while (m := ctl.recv(0.0)) is not None:
        if m.arbitration_id == SYNC_ID:
            assert signer.accept_sync(bytes(m.data))


def _forge(real: bytes, angle: float) -> bytes:
    """The best forgery without the key: next alive and FV counters, valid CRC, guessed MAC."""
    m = C.message(secoc.COMMAND)
    v = m.decode(real, decode_choices=False)
    v.update(AuxSteerCmd_Counter=(v["AuxSteerCmd_Counter"] + 1) % 15, AuxSteerCmd_Angle=angle,
             AuxSteerCmd_FvCounter=(v["AuxSteerCmd_FvCounter"] + 1) % 16, AuxSteerCmd_MAC=0x1234)
    data = bytearray(m.encode(v))
    data[0] = C.e2e_crc(secoc.COMMAND, bytes(data))
    return bytes(data)


def test_plant_applies_signed_commands_and_counts_forged_ones_as_rejected_and_failed(plant) -> None:
    # That the MAC is checked before the alive counter is the link's (tests/test_link.py).
    node, ctl = plant
    signer, ctr = secoc.CommandSigner(C, KEY), mrsteer_dbc.AliveCounter()
    node.step(0)  # the first step announces the epoch
    _sync_from(ctl, signer)
    # Angles a step apart within the actuator's authority rate (0.01 rad per 1 ms step).
    real = signed(signer, ctr, 0.004)
    ctl.send(can.Message(arbitration_id=CMD, data=real, is_extended_id=False))
    ctl.send(can.Message(arbitration_id=CMD, data=_forge(real, 0.009), is_extended_id=False))
    node.step(1)
    assert node.actuator.applied == pytest.approx(0.004)
    assert node.stats.cmd_auth_failed == 1 and node.stats.cmd_rejected == 1 and node.stats.cmd_accepted == 1
    ctl.send(can.Message(arbitration_id=CMD, data=signed(signer, ctr, 0.012), is_extended_id=False))
    node.step(2)
    assert node.actuator.applied == pytest.approx(0.012) and node.stats.cmd_rejected == 1


def test_without_secoc_the_same_forgery_is_taken(channel: str) -> None:
    """Why SecOC: E2E alone accepts a forgery with the next counter (documented in faults.md)."""
    with can.Bus(interface="virtual", channel=channel) as pb, can.Bus(interface="virtual", channel=channel) as ctl:
        node = PlantNode(pb, scn.load("paper-fig9"), mode="realtime", ts=1e-3)
        real = C.encode(secoc.COMMAND, dict(VALUES, AuxSteerCmd_Angle=0.004), 0)
        ctl.send(can.Message(arbitration_id=CMD, data=real, is_extended_id=False))
        ctl.send(can.Message(arbitration_id=CMD, data=_forge(real, 0.009), is_extended_id=False))
        node.step(0)
        assert node.actuator.applied == pytest.approx(0.009)


def test_plant_rejects_unauthenticated_commands_when_secoc_is_on(plant) -> None:
    node, ctl = plant
    ctl.send(can.Message(arbitration_id=CMD, data=C.encode(secoc.COMMAND, VALUES, 0), is_extended_id=False))
    node.step(0)
    assert node.actuator.applied == 0.0 and node.stats.cmd_auth_failed == 1


def test_plant_discards_what_was_queued_before_it_started(plant) -> None:
    node, ctl = plant
    for _ in range(3):  # a previous instance's commands, still on the bus when this one starts
        ctl.send(can.Message(arbitration_id=CMD, data=C.encode(secoc.COMMAND, VALUES, 0), is_extended_id=False))
    node.sc = dataclasses.replace(node.sc, duration=0.005)
    stats = node.run()
    assert stats.rx_before_start == 3 and stats.cmd_rejected == 0 and stats.cmd_auth_failed == 0


def test_plant_announces_the_epoch_at_the_sync_cycle_time(plant) -> None:
    node, ctl = plant
    for k in range(250):
        node.step(k)
    syncs = [m for m in iter(lambda: ctl.recv(0.0), None) if m.arbitration_id == SYNC_ID]
    assert len(syncs) == 3  # steps 0, 100, 200 at 1 ms: every 100 ms


# ---------------------------------------------------------------------- the controller


def test_controller_signs_once_synced_and_reports_a_lost_sync(channel: str) -> None:
    clock = Clock()
    verifier = secoc.CommandVerifier(C, KEY, clock)
    with can.Bus(interface="virtual", channel=channel) as cb, can.Bus(interface="virtual", channel=channel) as vb:
        node = rt.ControllerNode(cb, rt.RuntimeConfig(rate_hz=1000.0, secoc_key=KEY))
        counters = {n: mrsteer_dbc.AliveCounter() for n in (names.MSG_STEER, names.MSG_YAW, names.MSG_SPEED)}
        sensors = secoc.SensorSigner(C, KEY)

        def cycle(k: int) -> tuple[bool, int]:
            for name, values in ((names.MSG_STEER, {"DriverSteer_Angle": 0.0}), (names.MSG_SPEED, {"VehicleSpeed_Speed": 20.0}),
                                 (names.MSG_YAW, {"YawRate_YawRate": 0.0})):
                data = sensors.sign(name, values, counters[name].next(), verifier.current)
                vb.send(can.Message(arbitration_id=C.frame_id(name), data=data, is_extended_id=False))
            node.drain()
            node.control()
            cmds = [m for m in iter(lambda: vb.recv(0.0), None) if m.arbitration_id == CMD]
            return len(cmds) == 1 and accepts(verifier, bytes(cmds[0].data)), node.cause

        # No sync yet: no command goes out (the actuator could not verify it), the status says why.
        before = [cycle(k) for k in range(3)]
        assert all(not ok and cause & names.CAUSE_AUTH for ok, cause in before)
        assert node.stats.cmd_withheld == 3 and verifier.stats.failed == 0
        vb.send(can.Message(arbitration_id=SYNC_ID, data=verifier.next_sync(), is_extended_id=False))
        results = [cycle(k) for k in range(3, 302)]
        assert all(ok for ok, _ in results)
        assert not any(cause & names.CAUSE_AUTH for _, cause in results)
        # No sync for three of its cycles (300 ms): the status says so and no command goes out
        # (the actuator has moved two epochs on, or restarted: it would reject it as an attack).
        withheld = node.stats.cmd_withheld
        late = [cycle(k) for k in range(302, 312)][1:]  # the sync came in cycle 3: 300 cycles is the limit
        assert all(not ok and cause & names.CAUSE_AUTH for ok, cause in late)
        assert node.stats.cmd_withheld == withheld + 9 and verifier.stats.failed == 0
        # A restarted actuator's first sync: signing again at once, every command verified.
        verifier = secoc.CommandVerifier(C, KEY, lambda: clock() + 1.0)
        vb.send(can.Message(arbitration_id=SYNC_ID, data=verifier.next_sync(), is_extended_id=False))
        again = [cycle(k) for k in range(312, 316)]
        assert all(ok and not cause & names.CAUSE_AUTH for ok, cause in again)
        assert verifier.stats.failed == 0
        forged = bytearray(verifier.next_sync())
        forged[7] ^= 0x01
        vb.send(can.Message(arbitration_id=SYNC_ID, data=bytes(forged), is_extended_id=False))
        cycle(313)
        assert node.stats.syncs_rejected == 1


@pytest.mark.parametrize("cmd", ["controller", "plant"])
def test_secoc_options_need_a_good_key(cmd: str, tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != secoc.KEY_ENV}
    run = [sys.executable, "-m", "mrsteer_cli", cmd, "--interface", "virtual", "--channel", "none"]
    p = subprocess.run([*run, "--secoc"], capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 2 and secoc.KEY_ENV in p.stderr and "Traceback" not in p.stderr
    bad = tmp_path / "k"
    bad.write_text("xyz")
    p = subprocess.run([*run, "--secoc-key", str(bad)], capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 2 and "not hexadecimal" in p.stderr
    p = subprocess.run([*run, "--secoc", "--secoc-key", str(bad)], capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 2 and "not allowed with" in p.stderr
