"""The plant's actuator accepts only valid, fresh commands; stepping on a virtual bus."""

from __future__ import annotations

import math

import can
import pytest

import mrsteer_dbc
from sim_plant.car import scenario as scn
from sim_plant.nodes.plant import PlantNode

C = mrsteer_dbc.load()
CMD = C.frame_id("MRS_AuxSteerCmd")


@pytest.fixture
def rig(channel: str):
    plant_bus = can.Bus(interface="virtual", channel=channel)
    ctl = can.Bus(interface="virtual", channel=channel)
    node = PlantNode(plant_bus, scn.load("paper-fig9"), mode="realtime", ts=1e-3)
    yield node, ctl
    plant_bus.shutdown()
    ctl.shutdown()


def _cmd(ctl: can.BusABC, angle: float, counter: int, corrupt: bool = False) -> None:
    data = bytearray(C.encode("MRS_AuxSteerCmd", {"AuxSteerCmd_State": 1, "AuxSteerCmd_Angle": angle,
                                                  "AuxSteerCmd_MeasCounter": 15}, counter))
    if corrupt:
        data[3] ^= 0x01
    ctl.send(can.Message(arbitration_id=CMD, data=bytes(data), is_extended_id=False))


def test_valid_commands_are_applied_bad_ones_ignored(rig) -> None:
    node, ctl = rig  # steps within the authority limiter's 10 rad/s (0.01 rad per 1 ms step)
    _cmd(ctl, 0.008, 0)
    node.step(0)
    assert node.actuator.applied == pytest.approx(0.008)
    _cmd(ctl, -0.001, 1, corrupt=True)  # bad CRC
    _cmd(ctl, -0.001, 0)  # counter 0 again: stale
    node.step(1)
    assert node.actuator.applied == pytest.approx(0.008)
    assert node.stats.cmd_rejected == 2
    _cmd(ctl, 0.012, 1)
    node.step(2)
    assert node.actuator.applied == pytest.approx(0.012)


def test_spoofed_out_of_range_command_is_refused(rig) -> None:
    node, ctl = rig
    data = C.encode("MRS_AuxSteerCmd", {"AuxSteerCmd_State": 1, "AuxSteerCmd_Angle": 0.5,
                                        "AuxSteerCmd_MeasCounter": 15}, 0, strict=False)
    ctl.send(can.Message(arbitration_id=CMD, data=data, is_extended_id=False))
    node.step(0)
    assert node.actuator.applied == 0.0 and node.stats.cmd_rejected == 1


def test_a_command_at_the_signals_edge_is_clamped_to_the_actuators_3_degrees(rig) -> None:
    # The DBC's range (0.0524 rad) is 3.0023 deg: an E2E-valid command there (a forgery where
    # SecOC is off) must still leave the actuator within its +-3 deg.
    node, ctl = rig
    edge = C.signal_range("MRS_AuxSteerCmd", "AuxSteerCmd_Angle")[1]
    assert edge > math.radians(3.0)
    for k in range(30):  # +edge, then -edge: the authority limiter's rate takes 6 and 11 steps
        _cmd(ctl, edge if k < 15 else -edge, k % 15)
        node.step(k)
        assert abs(node.actuator.applied) <= math.radians(3.0)
        if k in (14, 29):
            assert abs(node.actuator.applied) == pytest.approx(math.radians(3.0), abs=1e-15)


def test_missing_commands_fade_the_actuator_to_zero(rig) -> None:
    node, ctl = rig
    for k in range(5):
        _cmd(ctl, 0.05, k)
        node.step(k)
    assert node.actuator.applied == pytest.approx(0.05)
    applied = []
    for k in range(5, 200):  # the controller goes quiet
        node.step(k)
        applied.append(node.actuator.applied)
    timeout = node.actuator.timeout_steps
    assert applied[timeout - 2] == pytest.approx(0.05)  # held while still fresh
    fade = math.radians(30.0) * 1e-3
    diffs = [a - b for a, b in zip(applied, applied[1:])]
    assert max(diffs) <= fade + 1e-12  # bounded rate, no jump
    assert applied[-1] == 0.0
    assert node.stats.actuator_timeouts == 1
    # Commands come back at 0.04 rad: the actuator slews there at the same rate, no jump.
    back = []
    for k in range(200, 300):
        _cmd(ctl, 0.04, k % 15)
        node.step(k)
        back.append(node.actuator.applied)
    steps = [b - a for a, b in zip([0.0] + back, back)]
    assert max(steps) <= fade + 1e-12 and back[-1] == pytest.approx(0.04)


def test_frames_of_other_ids_are_ignored_even_if_they_pass_the_filter(rig) -> None:
    # SocketCAN queues every ID between opening the socket and installing the filter (the
    # plant's own sensor frames among them).
    node, _ = rig
    steer = C.encode("MRS_DriverSteer", {"DriverSteer_Angle": 0.0}, 0)
    msg = can.Message(arbitration_id=C.frame_id("MRS_DriverSteer"), data=steer, is_extended_id=False)
    assert node.receive(msg, 0) is False
    assert node.stats.rx_ignored == 1 and node.stats.cmd_accepted == node.stats.cmd_rejected == 0


def _status(ctl: can.BusABC, plausibility: int) -> None:
    values = {s.name: 0 for s in C.message("MRS_CtrlStatus").signals}
    values["CtrlStatus_Plausibility"] = plausibility
    ctl.send(can.Message(arbitration_id=C.frame_id("MRS_CtrlStatus"), data=C.encode("MRS_CtrlStatus", values),
                         is_extended_id=False))


@pytest.mark.parametrize("plausibility, held", [(0, True), (4, False), (None, False)])
def test_the_actuator_ends_an_intervention_at_the_panic_window_unless_the_inputs_are_checked(
        rig, plausibility: int | None, held: bool) -> None:
    # A second, independent authority limit (issue 18): a steady 2 deg lasts beyond the 2 s
    # panic window only while the controller's status says every check is running; DEGRADED (4)
    # or no status at all end it with a 6 deg/s fade.
    node, ctl = rig
    applied = []
    for k in range(3000):
        if plausibility is not None and k % 100 == 0:
            _status(ctl, plausibility)
        _cmd(ctl, math.radians(2.0), k % 15)
        node.step(k)
        applied.append(node.actuator.applied)
    assert applied[1990] == pytest.approx(math.radians(2.0), abs=1e-6)
    if held:
        # ... it limited only the first steps' rate (0.01 rad per 1 ms step up to 0.035 rad)
        assert applied[-1] == pytest.approx(math.radians(2.0), abs=1e-6) and node.stats.actuator_authority_steps == 3
    else:
        fade = math.radians(6.0) * 1e-3
        assert max(a - b for a, b in zip(applied[1990:], applied[1991:])) <= fade + 1e-12
        assert applied[-1] == 0.0 and node.stats.actuator_authority_steps > 0


def test_a_plausibility_fault_in_the_status_fades_the_actuator_whatever_the_command(rig) -> None:
    node, ctl = rig
    for k in range(100):
        _cmd(ctl, math.radians(2.0), k % 15)
        node.step(k)
    _status(ctl, 1)  # yaw rate implausible: the controller fades, and so does the actuator
    applied = []
    for k in range(100, 900):  # ... latched: the status going quiet does not bring the command back
        _cmd(ctl, math.radians(2.0), k % 15)
        node.step(k)
        applied.append(node.actuator.applied)
    assert applied[-1] == 0.0
    steps = [a - b for a, b in zip(applied, applied[1:])]
    assert max(steps) <= math.radians(30.0) * 1e-3 + 1e-12  # the authority limiter's fault fade
    assert max(steps) > math.radians(29.0) * 1e-3  # at that rate, not the hand-back's 6 deg/s


def test_the_actuators_defaults_are_the_plants_and_its_command_lines(rig) -> None:
    from sim_plant.car import actuator
    from sim_plant.nodes.plant import build_parser

    node, _ = rig
    assert (actuator.CMD_TIMEOUT_S, actuator.FADE_RATE_RAD_S, actuator.RATE_LIMIT_RAD_S) == (0.02, math.radians(30.0), 0.0)
    args = build_parser().parse_args([])
    assert (args.cmd_timeout, args.actuator_rate) == (0.02, 0.0)
    a = node.actuator  # at 1 ms: 20 steps of timeout, 30 deg/s of fade, +-3 deg
    assert (a.timeout_steps, a.fade_step, a.slew_step, a.limit) == (20, math.radians(30.0) * 1e-3, 0.0, math.radians(3.0))
