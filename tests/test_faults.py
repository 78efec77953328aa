"""Fault injection: the bridge's transformations, fuzzing of the receive path, and the whole
fault matrix on live processes (as `mrsteer faults run` runs it)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import mrsteer_dbc
from firmware_py.controller import node as rt
from mrsteer_dbc import E2EStatus
from sim_plant.nodes.fault_bridge import HISTORY, Bridge, Fault
from sim_plant.harness import faults as F
from sim_plant.harness.faults import CALIBRATIONS, ROWS, Setup, format_table, run_matrix
from sim_plant.harness.faults.verdicts import faulted_after_bad_frames
from sim_plant.harness.processes import RunError
from sim_plant.nodes.candump_log import Frame

from conftest import matrix_with_one_rerun

ROOT = Path(__file__).resolve().parents[1]
C = mrsteer_dbc.load()
YAW = C.frame_id("MRS_YawRate")


def _yaw(counter: int, value: float = 0.1) -> can.Message:
    return can.Message(arbitration_id=YAW, is_extended_id=False,
                       data=C.encode("MRS_YawRate", {"YawRate_YawRate": value}, counter))


@pytest.fixture
def bridge(channel: str):
    buses = [can.Bus(interface="virtual", channel=f"{channel}-{side}") for side in ("a", "b")]

    def make(kind: str, param: float = 1.0) -> Bridge:
        b = Bridge(*buses, Fault(kind, "MRS_YawRate", 1.0, 2.0, param))
        b.stats.t0 = 100.0
        return b

    yield make
    for b in buses:
        b.shutdown()


@pytest.mark.parametrize("kind,status", [("corrupt_payload", E2EStatus.BAD_CRC), ("corrupt_crc", E2EStatus.BAD_CRC),
                                         ("corrupt_counter", E2EStatus.BAD_COUNTER),
                                         ("wrong_length", E2EStatus.BAD_LENGTH),
                                         ("out_of_range", E2EStatus.OUT_OF_RANGE)])
def test_corruptions_are_the_ones_named(bridge, kind: str, status: E2EStatus) -> None:
    b = bridge(kind, 3.2)  # outside the range of +-3, inside the 16-bit field
    (when, out), = b.transform(_yaw(3), 101.5)
    assert when == 101.5 and C.decode(YAW, bytes(out.data)).status is status
    (_, untouched), = b.transform(_yaw(4), 102.5)  # outside the window
    assert C.decode(YAW, bytes(untouched.data)).status is E2EStatus.OK
    assert b.stats.affected == 1


def test_timing_faults(bridge) -> None:
    assert bridge("drop", 1.0).transform(_yaw(1), 101.0) == []
    (when, _), = bridge("delay", 0.004).transform(_yaw(1), 101.0)
    assert when == pytest.approx(101.004)
    assert len(bridge("duplicate").transform(_yaw(1), 101.0)) == 2
    r = bridge("reorder")
    assert r.transform(_yaw(1), 101.0) == []
    (_, first), (_, second) = r.transform(_yaw(2), 101.002)
    assert [C.decode(YAW, bytes(m.data)).counter for m in (first, second)] == [2, 1]
    p = bridge("replay", 1.0)
    p.transform(_yaw(5), 100.5)  # before the window: recorded
    (_, real), (_, old) = p.transform(_yaw(6), 101.0)
    assert C.decode(YAW, bytes(real.data)).counter == 6 and C.decode(YAW, bytes(old.data)).counter == 5


def test_substitution_sends_the_old_frame_instead(bridge) -> None:
    b = bridge("substitute", 15.0)
    for counter in range(15):
        b.transform(_yaw(counter, 0.01 * counter), 100.0 + 0.002 * counter)  # recorded
    (_, out), = b.transform(_yaw(0, 0.5), 101.0)  # the 16th frame: counter 0 again after 0..14
    old = C.decode(YAW, bytes(out.data))
    assert old.status is E2EStatus.OK and old.counter == 0 and old.signals["YawRate_YawRate"] == 0.0


@pytest.mark.parametrize("kind", ["substitute", "replay"])
def test_without_that_much_history_a_frame_is_forwarded_and_not_counted(bridge, kind: str) -> None:
    b = bridge(kind, 3.0)
    sent = [b.transform(_yaw(k), 101.0 + 0.002 * k) for k in range(5)]  # all inside the window
    assert [len(out) for out in sent] == [1, 1, 1, 1 if kind == "substitute" else 2, 1 if kind == "substitute" else 2]
    assert all(bytes(out[0][1].data) == bytes(_yaw(k).data) for k, out in enumerate(sent[:3]))
    assert b.stats.affected == 2  # the 4th and 5th frames, which had 3 before them


def test_a_substitution_is_as_old_at_every_matrix_rate() -> None:
    from sim_plant.harness.faults.run import bridge_fault

    row = next(r for r in ROWS if r.fault.kind == "substitute")
    depths = {rate: bridge_fault(row, Setup(rate_hz=rate)).param for rate in CALIBRATIONS}
    assert depths == {1000.0: 300, 500.0: 150, 200.0: 60, 100.0: 30}  # 0.3 s, counter-aligned (15)
    assert all(d <= HISTORY for d in depths.values())


def test_the_forger_takes_the_next_counters_with_a_valid_crc(channel: str) -> None:
    buses = [can.Bus(interface="virtual", channel=f"{channel}-{side}") for side in ("a", "b")]
    try:
        b = Bridge(*buses, Fault("spoof_command", "commands", 1.0, 2.0, 0.05))
        b.stats.t0 = 100.0
        name = "MRS_AuxSteerCmd"
        real = can.Message(arbitration_id=C.frame_id(name), is_extended_id=False,
                           data=C.encode(name, {"AuxSteerCmd_State": 1, "AuxSteerCmd_Angle": 0.01,
                                                "AuxSteerCmd_MeasCounter": 15, "AuxSteerCmd_FvCounter": 15}, 14))
        (_, first), (_, forged) = b.transform(real, 101.0)
        assert first is real
        d = C.decode(real.arbitration_id, bytes(forged.data))
        assert d.status is E2EStatus.OK and d.counter == 0 and d.signals["AuxSteerCmd_FvCounter"] == 0
        assert d.signals["AuxSteerCmd_Angle"] == pytest.approx(0.05) and b.stats.affected == 1
    finally:
        for bus in buses:
            bus.shutdown()


def test_a_stopped_bridge_forwards_its_whole_backlog_and_nothing_later(channel: str) -> None:
    # A bridge that lagged behind (a stalled machine) still has frames queued when it is told to
    # stop; they were on the bus, so they must cross and be counted.  Frames sent after the stop
    # are not its business.
    names = [f"{channel}-{side}" for side in ("a", "b")]
    buses = [can.Bus(interface="virtual", channel=n) for n in names]
    plant, controller_side = (can.Bus(interface="virtual", channel=n) for n in names)
    try:
        b = Bridge(*buses, Fault("none"))
        for counter in range(600):
            plant.send(_yaw(counter % 15))
        b.stop()
        plant.send(_yaw(0))  # after the stop
        stats = b.run()
        assert stats.seen_on_vehicle == stats.forwarded_to_controller == 600
        received = 0
        while controller_side.recv(0.0) is not None:
            received += 1
        assert received == 600
    finally:
        for bus in (*buses, plant, controller_side):
            bus.shutdown()


def test_the_flood_sends_its_rate_over_its_window(channel: str) -> None:
    # 5000 frames/s (past a 500 kbit/s bus's capacity) over a 0.2 s window: 1000 frames, sent
    # in bursts as they fall due rather than one per sleep, which the scheduler would stretch.
    import threading
    import time

    buses = [can.Bus(interface="virtual", channel=f"{channel}-{side}") for side in ("a", "b")]
    try:
        b = Bridge(*buses, Fault("flood", "MRS_YawRate", 0.05, 0.25, 5000.0))
        b.stats.t0 = time.time()
        flooder = threading.Thread(target=b.flood)
        flooder.start()
        time.sleep(0.4)
        b.stop()
        flooder.join()
        assert 900 <= b.stats.injected_to_controller <= 1001  # a starved thread may miss the last ms
        assert F.FLOOD_CAPACITY < 5000.0  # the matrix row's rate saturates a real bus
    finally:
        for bus in buses:
            bus.shutdown()


def test_bridge_rejects_a_bad_fault_spec() -> None:
    proc = subprocess.run([sys.executable, "-m", "sim_plant.nodes.fault_bridge", "--vehicle", "a", "--controller", "b",
                           "--fault", '{"kind": "explode"}'], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "fault kind must be one of" in proc.stderr


@settings(max_examples=400, deadline=None)
@given(frame_id=st.integers(0, 0x7FF), data=st.binary(max_size=8))
def test_decoder_and_e2e_never_raise_on_random_frames(frame_id: int, data: bytes) -> None:
    d = C.decode(frame_id, data)
    if d is None:
        assert C.name_of(frame_id) is None
        return
    assert isinstance(d.status, E2EStatus)
    if d.status is E2EStatus.OK:
        msg = C.message(d.name)
        assert len(data) == msg.length
        for s in msg.signals:
            assert s.minimum <= d.signals[s.name] <= s.maximum
        if d.counter is not None:
            assert mrsteer_dbc.E2EReceiver().check(d.counter).accepted


@settings(max_examples=300, deadline=None)
@given(frames=st.lists(st.tuples(st.sampled_from([0x100, 0x101, 0x102, 0x0A0, 0x7AB]), st.binary(max_size=8),
                                 st.booleans()), max_size=40))
def test_controller_receive_path_survives_any_frame_sequence(frames) -> None:
    bus = can.Bus(interface="virtual", channel="mrsteer-fuzz-receive")
    try:
        node = rt.ControllerNode(bus, rt.RuntimeConfig())
        for fid, data, extended in frames:
            node.receive(can.Message(arbitration_id=fid, data=data, is_extended_id=extended))
            node.control()  # and the cycle behind it
        s = node.stats
        assert s.rx_frames == len(frames) and s.rx_rejected + s.rx_ignored <= s.rx_frames
        assert abs(node.state.u_prev) <= node.coeffs.u_max
    finally:
        bus.shutdown()


# The Python controller's matrix runs at 200 Hz (its calibration for that rate) here: at 500 Hz,
# six Python processes on this 2-core machine leave the plant late in up to 14 % of its steps,
# and a stall past a sensor's timeout, in paper-fig9's disturbance, latches the monitor's
# OUTSIDE_MODEL (issue 53: a false alarm under load, rerun or not).  The C node's matrix runs at
# 500 Hz (test_c_node.py); `mrsteer faults run` at 500 Hz with Python is run by hand.
PYTHON_MATRIX_RATE_HZ = 200.0


@pytest.mark.slow
@pytest.mark.serial
def test_fault_matrix_on_the_fallback_bus(tmp_path: Path) -> None:
    setup = Setup(rate_hz=PYTHON_MATRIX_RATE_HZ)
    results = matrix_with_one_rerun(lambda rows, keep: run_matrix(rows, keep=keep, setup=setup), ROWS, tmp_path)
    table = format_table(results)
    assert all(r.ok for r in results), table
    assert len(results) == len(ROWS) >= 20
    detected = {r.name: r.detection_cycles for r in results if r.detection_cycles is not None}
    assert detected["yaw-rate frames lost (burst)"] <= rt.RuntimeConfig().timeout_cycles + 2
    assert json.loads((tmp_path / "01" / "bridge.json").read_text())["affected"] == 0  # the baseline is clean


@pytest.mark.parametrize("rate", sorted(CALIBRATIONS))
def test_every_matrix_calibration_keeps_its_margins_at_its_rate(rate: float) -> None:
    from sim_plant.offline import margins as M
    from sim_plant.offline import tuning as T

    cfg = CALIBRATIONS[rate]
    assert cfg.ts == 1.0 / rate
    res = M.envelope_margins(cfg, 1, with_delay_margin=False)  # (the delay margin: 98 % of the time, unasserted)
    assert res.stable
    w = res.worst()
    assert w["gain_margin_db"] >= T.GM_MIN_DB - 0.01 and w["phase_margin_deg"] >= T.PM_MIN_DEG - 0.01


@pytest.mark.parametrize("kwargs,needle", [
    (dict(rate_hz=300.0), "--rate-hz 300: no calibration for 300 Hz"),
    (dict(time_scale=0.5), "time scale"),
    (dict(startup_s=-1.0), "start-up"),
    (dict(slow_motion=0.5), r"--slow-motion must be in \[1, 100\]"),
    (dict(slow_motion=float("inf")), r"--slow-motion must be in \[1, 100\], got inf"),
    (dict(interface="socketcan"), "needs --channels"),
    (dict(interface="socketcan", channels=("vcan0", "vcan0")), "two different channels"),
])
def test_matrix_setup_refuses_what_it_cannot_run(kwargs: dict, needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        Setup(**kwargs)
    key, value = next(iter(kwargs.items()))
    flag = {"rate_hz": "--rate-hz", "time_scale": "--time-scale", "slow_motion": "--slow-motion"}.get(key)
    if flag:
        argv = [flag, f"{value:g}"]
        proc = subprocess.run([sys.executable, "-m", "mrsteer_cli", "faults", "run", *argv], capture_output=True,
                              text=True, timeout=60)
        # the run subcommand's own usage error: one line, named for the command that was given
        assert proc.returncode == 2 and re.search(needle, proc.stderr)
        assert proc.stderr.startswith("mrsteer: faults run: ") and proc.stderr.count("\n") == 1


@pytest.mark.parametrize("argv", [["faults", "--help"], ["faults", "run", "--help"], ["faults", "bridge", "--help"]])
def test_every_faults_command_has_help(argv: list[str]) -> None:
    proc = subprocess.run([sys.executable, "-m", "mrsteer_cli", *argv], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "usage:" in proc.stdout


def test_faults_run_rejects_an_unknown_row() -> None:
    proc = subprocess.run([sys.executable, "-m", "mrsteer_cli", "faults", "run", "--only", "no such row"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "no row matches" in proc.stderr


def _stamped(times: list[float], fid: int) -> list[Frame]:
    return [Frame(t, fid, b"") for t in times]


def test_a_stalled_sender_is_judged_by_bad_frames_not_cycles() -> None:
    # The controller's rule: FAULT in the cycle after the 3rd consecutive bad frame.  Cycles
    # every 10 ms; bad yaw-rate frames from t = 1.0 s, but only one every 40 ms (a stall).
    row = next(r for r in ROWS if r.name.startswith("yaw-rate CRC"))
    bad = _stamped([1.001, 1.041, 1.081], YAW)
    cmds = [(1.0 + 0.01 * k + 0.005, 1.0) for k in range(20)]
    assert rt.RuntimeConfig().e2e_fail_max == 3
    assert faulted_after_bad_frames(bad, cmds, row, 1.0, first_fault=1.085)  # the next cycle
    assert faulted_after_bad_frames(bad, cmds, row, 1.0, first_fault=1.095)  # the one after
    assert not faulted_after_bad_frames(bad, cmds, row, 1.0, first_fault=1.105)  # a cycle late
    assert not faulted_after_bad_frames(bad[:2], cmds, row, 1.0, first_fault=1.085)  # only 2 bad frames
    other = _stamped([1.001, 1.041, 1.081], C.frame_id("MRS_VehicleSpeed"))
    assert not faulted_after_bad_frames(other, cmds, row, 1.0, first_fault=1.085)  # not the faulted message


def test_faults_run_refuses_a_keep_directory_it_cannot_create(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    proc = subprocess.run([sys.executable, "-m", "mrsteer_cli", "faults", "run", "--only", "baseline", "--keep",
                           str(blocker / "rows")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1, proc.stderr
    assert "cannot create it" in proc.stderr


def test_matrix_will_not_judge_an_earlier_runs_files(tmp_path: Path) -> None:
    (tmp_path / "01").mkdir()
    (tmp_path / "01" / "controller.json").write_text("{}")
    with pytest.raises(RunError, match="not empty"):
        run_matrix(ROWS[:1], keep=tmp_path)
    proc = subprocess.run([sys.executable, "-m", "mrsteer_cli", "faults", "run", "--keep", str(tmp_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "is not empty" in proc.stderr


def test_receive_queue_is_deepened_on_kernel_sockets_only() -> None:
    import socket

    from firmware_py.platform.rx_queue import DEPTH_BYTES, deepen

    class KernelBus:
        def __init__(self) -> None:
            self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    bus = KernelBus()
    try:
        default = bus.socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        granted = deepen(bus)
        rmem_max = int(Path("/proc/sys/net/core/rmem_max").read_text())
        # Privileged: the whole depth (the kernel doubles it for its bookkeeping); else rmem_max.
        assert granted == bus.socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        assert granted >= min(DEPTH_BYTES, rmem_max) and granted >= default
        if os.geteuid() == 0:
            assert granted >= DEPTH_BYTES
    finally:
        bus.socket.close()
    assert deepen(can.Bus(interface="virtual", channel="mrsteer-rxq")) is None


@pytest.mark.parametrize("back,replays_taken,live_taken", [
    (1, 0, 200), (2, 0, 200), (15, 0, 200), (16, 0, 200), (17, 0, 200), (30, 0, 200),
    (5, 0, 1), (10, 0, 1), (11, 0, 1),
    (12, 200, 1), (13, 200, 1), (14, 200, 1), (27, 200, 1), (28, 200, 1), (29, 200, 1)])
def test_replay_aliasing_is_what_the_safety_docs_state(back: int, replays_taken: int, live_taken: int) -> None:
    # docs/faults.md, "Known limits": a replay sent after each live frame, the one `back` frames
    # older, against the controller's counter check (window 3).  Change one, change the other.
    receiver = mrsteer_dbc.E2EReceiver(rt.RuntimeConfig().max_counter_delta)
    replays = live = 0
    for n in range(20, 220):
        live += receiver.check(n % 15).accepted
        replays += receiver.check((n - back) % 15).accepted
    assert (replays, live) == (replays_taken, live_taken)


def test_secured_rows_authenticate_every_row_and_drop_the_e2e_only_ones() -> None:
    rows = F.secured_rows()
    assert all(r.secoc for r in rows)
    assert not any(r.e2e_only for r in rows) and any(r.e2e_only for r in F.ROWS)
    names = [r.name for r in rows]
    assert "baseline" in names and "SecOC: baseline" not in names  # the same run once
    assert "SecOC: commands forged" in names and "plant killed and restarted" in names
    assert len(rows) == len(F.ROWS) - 2


# A realtime row at 500 Hz judged on the wall clock: beside the other test worker the plant was
# late in 364 of 1301 steps and the monitor latched OUTSIDE_MODEL (issue 53's timing false alarm).
@pytest.mark.slow
@pytest.mark.serial
def test_faults_run_secoc_judges_a_row_with_the_sensor_frames_authenticated(capsys: pytest.CaptureFixture[str]) -> None:
    assert F.main(["run", "--secoc", "--only", "yaw-rate frames replayed", "--json"]) == 0
    (result,) = json.loads(capsys.readouterr().out)
    assert result["passed"], result
    # Every replay 1 back was refused by the controller's MAC, not only counted as rejected.
    refused = int(result["observed"].split("controller: ")[1].split(" sensor frames failed SecOC")[0])
    assert refused >= 190


def test_a_matrix_row_that_fails_once_is_run_again_and_reported() -> None:
    from dataclasses import replace as dc_replace

    from sim_plant.harness.faults.verdicts import RowResult

    def result(name: str, ok: bool) -> RowResult:
        return RowResult(name, "", ok, "", 0.0, 0.0, None, [] if ok else ["late"])

    calls: list[tuple[str, ...]] = []

    def run(outcome: dict[str, list[bool]]):
        def go(rows, keep):
            calls.append(tuple(r.name for r in rows))
            return [result(r.name, outcome[r.name].pop(0)) for r in rows]
        return go

    rows = tuple(dc_replace(ROWS[0], name=n) for n in "abc")
    with pytest.warns(UserWarning, match="b: late -> PASS"):
        res = matrix_with_one_rerun(run({"a": [True], "b": [False, True], "c": [True]}), rows, Path("/x"))
    assert [r.passed for r in res] == [True, True, True] and calls == [("a", "b", "c"), ("b",)]
    calls.clear()
    with pytest.warns(UserWarning, match="FAIL again"):
        res = matrix_with_one_rerun(run({"a": [False, False], "b": [True], "c": [True]}), rows, Path("/x"))
    assert [r.passed for r in res] == [False, True, True]
    calls.clear()
    res = matrix_with_one_rerun(run({"a": [False], "b": [False], "c": [False]}), rows, Path("/x"))  # too many
    assert calls == [("a", "b", "c")] and not any(r.passed for r in res)


def test_a_recovery_that_ends_faded_again_is_no_recovery() -> None:
    from firmware_py import model_regulator as mr
    from sim_plant.harness.faults.verdicts import off_to_the_end

    A, D, F_ = mr.STATUS_ACTIVE, mr.STATUS_DEGRADED, mr.STATUS_FAULT
    assert off_to_the_end([(1.0, A), (1.1, D), (1.2, D)]) == (1.1, D)
    assert off_to_the_end([(1.0, A), (1.1, F_), (1.2, D)]) == (1.1, F_)
    # a missing frame's DEGRADED comes and goes: the function is back at the end
    assert off_to_the_end([(1.0, A), (1.1, D), (1.2, A)]) is None
    assert off_to_the_end([]) is None


def test_a_known_defect_is_named_only_when_it_is_the_only_failure() -> None:
    from dataclasses import replace as dc_replace

    from sim_plant.harness.faults.rows import NOT_KEPT, OUTSIDE_MODEL_AFTER_OUTAGE
    from sim_plant.harness.faults.verdicts import RowResult, known_defect

    row = next(r for r in ROWS if r.known is OUTSIDE_MODEL_AFTER_OUTAGE)
    kept = f"{NOT_KEPT}: DEGRADED from 60 ms after the fault to the end"
    assert known_defect(row, [kept]) == OUTSIDE_MODEL_AFTER_OUTAGE.why
    assert known_defect(row, [kept, "detected after 9 cycles, allowed 5"]) == ""  # another failure: FAIL
    assert known_defect(row, []) == ""  # passed
    assert known_defect(dc_replace(row, known=None), [kept]) == ""
    known = RowResult(row.name, row.expected, False, "", 0.0, 0.0, 3, [kept], known_defect(row, [kept]))
    failed = RowResult("x", "", False, "", 0.0, 0.0, None, ["late"])
    assert known.ok and not failed.ok
    table = format_table([known, failed])
    assert f"{row.name:<38}{row.expected:<42}KNOWN" in table and "issue 53" in table
    assert table.endswith("0/2 rows pass, 1 fail as a known defect")


def test_a_killed_plants_outage_starts_after_its_last_frame_even_one_logged_after_the_kill() -> None:
    """The dead plant's last yaw-rate frame can reach the bus after the SIGKILL (it was in the
    broker's queue): the controller's timeout runs from that frame, so the outage does too."""
    from types import SimpleNamespace

    from sim_plant.harness.faults.verdicts import outage
    c = mrsteer_dbc.load()
    yaw = c.frame_id("MRS_YawRate")
    cycle = c.cycle_time_s("MRS_YawRate", 0.002)
    row = next(r for r in ROWS if r.kill_plant)
    frames = [Frame(t, yaw, b"") for t in (1.000, 1.002, 1.004, 1.5, 1.502)]
    e = SimpleNamespace(row=row, setup=SimpleNamespace(ts=0.002), killed_at=1.003, restarted=1.4, frames=frames,
                        bridge={"first_affected": None, "last_affected": None})
    # the frame at 1.004 was sent before the kill at 1.003 and logged after it
    assert outage(e) == (pytest.approx(1.004 + cycle), 1.5)
