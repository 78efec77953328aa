"""Real SocketCAN: HIL on vcan0, candump/cantools interop, cansend injection, kernel filters.

These run where a ``vcan0`` interface exists (``tools/vcan.sh up``); elsewhere they are skipped
with the reason.  ``tools/vcan-vm-test`` boots a stock Debian kernel under QEMU and runs them
there, and ``.ci/run`` does that on every CI run.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import MATRIX_RERUN_MAX, ctrl_c_reaches_it, lockstep_traffic, matrix_with_one_rerun
from firmware_py.platform.bus_open import vcan_available
from mrsteer_dbc import names

pytestmark = [
    pytest.mark.vcan,
    # In the VM stage MRSTEER_REQUIRE_VCAN is set: there a missing vcan0 must fail, not skip.
    pytest.mark.skipif(not vcan_available("vcan0") and not os.environ.get("MRSTEER_REQUIRE_VCAN"),
                       reason="no SocketCAN vcan0 on this kernel (create one with tools/vcan.sh up, "
                       "or run tools/vcan-vm-test)"),
]

ROOT = Path(__file__).resolve().parents[1]
IFACE = ["--interface", "socketcan", "--channel", "vcan0"]


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"{name} (can-utils) is not installed")
    return path


def _mrsteer(*args: str) -> str:
    """``mrsteer ARGS`` in this process (its stdout): under QEMU a new interpreter spends half a
    minute importing what this one has already imported."""
    from mrsteer_cli.cli import main

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(list(args))
    assert code == 0, f"mrsteer {' '.join(args)}: exit status {code}"
    return printed.getvalue()


class Candump:
    """The real ``candump [-L] vcan0``, line-buffered into a file, ready when it has seen a probe."""

    def __init__(self, path: Path, log_format: bool = True) -> None:
        self.path = path
        self._out = path.open("w")
        self.proc = subprocess.Popen(["stdbuf", "-oL", _tool("candump"), *(["-L"] if log_format else []), "vcan0"],
                                     stdout=self._out, stderr=subprocess.PIPE, preexec_fn=ctrl_c_reaches_it)
        deadline = time.monotonic() + 120
        while not any(probe in path.read_text() for probe in ("7FF#", "7FF   [1]")):
            assert self.proc.poll() is None, self.proc.stderr.read()
            assert time.monotonic() < deadline, "candump never saw the probe frame"
            subprocess.run([_tool("cansend"), "vcan0", "7FF#00"], check=True)
            time.sleep(0.2)

    def stop(self) -> str:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(60)
        self._out.close()
        return self.path.read_text()


# One Python lockstep run on vcan0 serves the offline comparison, candump's decoding and the C
# node's comparison: under QEMU a run costs minutes, most of it Python starting its processes.
LOCKSTEP_ARGS = ("hil", "run", *IFACE, "--scenario", "paper-fig9", "--mode", "lockstep", "--rate-hz", "200",
                 "--k", "3", "--tau", "0.05", "--v", "24", "--mu", "0.95", "--duration", "1.5", "--json")


def _lockstep(out: Path, impl: str) -> dict:
    """A lockstep run of ``LOCKSTEP_ARGS`` by ``impl``'s controller; again (once) if the plant
    stalled for a watchdog cycle of the controller's (``lockstep_traffic``): the VM's load."""
    for _ in range(2):
        if out.exists():  # the run before, which stalled
            shutil.rmtree(out)
        run = json.loads(_mrsteer(*LOCKSTEP_ARGS, "--controller-impl", impl, "--out", str(out)))
        if not lockstep_traffic(out / "traffic.log")["stalls"] and not run["loop"]["plant"].get("lockstep_timeouts"):
            break
    return run


@pytest.fixture(scope="module")
def python_lockstep(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path, str, str]:
    """The Python controller's lockstep run, with what ``candump -L vcan0`` and plain
    ``candump vcan0`` saw meanwhile."""
    tmp = tmp_path_factory.mktemp("python-lockstep")
    dump = Candump(tmp / "candump.log")
    plain = Candump(tmp / "candump.txt", log_format=False)  # what `candump vcan0 | cantools decode` reads
    try:
        run = _lockstep(tmp / "hil", "python")
    finally:
        text = dump.stop()
        plain_text = plain.stop()
    return run, tmp / "hil", text, plain_text


def test_lockstep_hil_on_vcan0_matches_offline_and_candump_decodes(
        python_lockstep: tuple[dict, Path, str, str]) -> None:
    import mrsteer_dbc

    hil, _, text, plain_text = python_lockstep
    offline = json.loads(_mrsteer("sim", "disturbance", "--mz", "4000", "--v", "24", "--mu", "0.95", "--ts", "0.005",
                                  "--delay-steps", "1", "--k", "3", "--tau", "0.05", "--duration", "1.5", "--json"))
    for key in ("peak_aux_steer_deg", "final_aux_steer_deg", "peak_yaw_rate_rad_s", "final_yaw_rate_rad_s"):
        assert hil[key] == pytest.approx(offline[key], rel=0.01), key

    # What the real candump saw is everything the plant and controller sent, and every frame
    # decodes with the DBC.
    frames = [ln.split()[2].split("#") for ln in text.splitlines()
              if ln.startswith("(") and "vcan0" in ln and "7FF#" not in ln]
    assert len(frames) >= hil["frames"]["sent_plant"] + hil["frames"]["sent_controller"]
    db = mrsteer_dbc.load()
    decoded = {db.db.get_message_by_frame_id(int(fid, 16)).name for fid, _ in frames}
    for fid, data in frames:
        db.db.decode_message(int(fid, 16), bytes.fromhex(data))
    assert {"MRS_YawRate", "MRS_AuxSteerCmd", "MRS_DriverSteer", "MRS_VehicleSpeed"} <= decoded

    # The README's pipe: plain `candump vcan0` output decodes too.
    dec = subprocess.run([sys.executable, "-m", "cantools", "decode", str(ROOT / "dbc" / "mrsteer.dbc")],
                         input=plain_text, capture_output=True, text=True, timeout=600)
    assert dec.returncode == 0, dec.stderr
    assert "MRS_YawRate(" in dec.stdout and "MRS_AuxSteerCmd(" in dec.stdout


# What the cansend test's feeder sends every 10 ms (the yaw rate's second element SNA: a sender
# without it), and every 50 ms: the lateral acceleration v r and the second steering channel.
FEED = {names.MSG_STEER: {"DriverSteer_Angle": 0.0}, names.MSG_SPEED: {"VehicleSpeed_Speed": 20.0},
        names.MSG_YAW: {"YawRate_YawRate": 0.01}}
REDUNDANT = {"RedundantSensors_LatAccel": 0.2, "RedundantSensors_SteerAngle": 0.0}


def test_controller_rejects_frames_injected_with_cansend_and_keeps_running(tmp_path: Path) -> None:
    import can

    import mrsteer_dbc
    from firmware_py import model_regulator as mr

    c = mrsteer_dbc.load()
    stats = tmp_path / "ctl.json"
    ctl = subprocess.Popen([sys.executable, "-m", "firmware_py", *IFACE, "--rate-hz", "100", "--stats-out", str(stats)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    bus = can.Bus(interface="socketcan", channel="vcan0")
    counters = {n: mrsteer_dbc.AliveCounter() for n in (*FEED, names.MSG_REDUNDANT)}
    run, paused = threading.Event(), threading.Event()
    run.set()
    last_yaw: list[bytes] = []

    def feed() -> None:
        # Every sensor message at its DBC cycle (the redundant one's 50 ms every 5th of 10 ms), a
        # car going straight at 20 m/s: the controller is ACTIVE, neither STARTING nor DEGRADED.
        n = 0
        while run.is_set():
            if not paused.is_set():
                sends = list(FEED.items()) + ([(names.MSG_REDUNDANT, REDUNDANT)] if n % 5 == 0 else [])
                for name, values in sends:
                    data = c.encode(name, values, counters[name].next())
                    bus.send(can.Message(arbitration_id=c.frame_id(name), data=data, is_extended_id=False))
                    if name == names.MSG_YAW:
                        last_yaw[:] = [data]
                n += 1
            time.sleep(0.01)

    feeder = threading.Thread(target=feed, daemon=True)
    try:
        deadline = time.monotonic() + 120
        while "running at" not in (line := ctl.stderr.readline()):
            assert line or ctl.poll() is None, "controller died at start-up"
            assert time.monotonic() < deadline
        feeder.start()
        time.sleep(2.0)
        paused.set()
        time.sleep(0.3)
        yaw_id = f"{c.frame_id(names.MSG_YAW):03X}"
        good = last_yaw[0]
        bad_crc = bytes([good[0] ^ 0x5A]) + good[1:]
        injections = [
            f"{yaw_id}#{bad_crc.hex().upper()}",  # corrupted CRC
            f"{yaw_id}#{good.hex().upper()}",  # the last frame again: repeated counter, stale
            f"{yaw_id}#{good[:3].hex().upper()}",  # wrong length
            "7AB#DEADBEEF",  # an ID nobody defined: filtered out in the kernel
        ]
        for frame in injections:
            subprocess.run([_tool("cansend"), "vcan0", frame], check=True, timeout=60)
        time.sleep(1.0)
        paused.clear()
        time.sleep(2.0)
        assert ctl.poll() is None, "the controller must survive bad frames"
        recent = []
        # The controller keeps sending, so read for a bounded time rather than until silence.
        until = time.monotonic() + 1.0
        while time.monotonic() < until and (m := bus.recv(0.2)) is not None:
            if m.arbitration_id == c.frame_id(names.MSG_CMD):
                recent.append(c.decode(m.arbitration_id, bytes(m.data)).signals["AuxSteerCmd_State"])
        # Recovered, not latched by the bad frames: active again in the window.  Not "the last
        # command": under emulation the feeder thread stalls past the inputs' timeout at times, and
        # FAULT is then the controller's right answer to frames that really stopped.
        assert recent and {mr.STATUS_ACTIVE, mr.STATUS_SATURATED} & set(recent), recent
    finally:
        run.clear()
        if feeder.is_alive():
            feeder.join(10)
        ctl.send_signal(signal.SIGTERM)
        code = ctl.wait(120)
        bus.shutdown()
    assert code == 0
    s = json.loads(stats.read_text())
    assert s["rx_rejected"] == 3  # CRC, stale counter, length
    assert s["rx_ignored"] == 0  # the unknown ID never reached the process


def test_the_vm_stage_collects_this_file_alone(request: pytest.FixtureRequest) -> None:
    """tools/vcan-vm-test names this file alone: collecting the whole suite under emulation takes
    about 4 minutes (an empty argument once made pytest collect the tree)."""
    if not os.environ.get("MRSTEER_REQUIRE_VCAN"):
        pytest.skip("the VM stage's own pytest command is what this checks")
    paths = [arg.split("::")[0] for arg in request.config.args]
    assert paths and all(Path(a).name == "test_vcan.py" for a in paths), paths


def test_controller_filters_are_installed_in_the_kernel() -> None:
    import can

    from firmware_py.controller import node as rt

    bus = can.Bus(interface="socketcan", channel="vcan0")
    try:
        node = rt.ControllerNode(bus, rt.RuntimeConfig(rate_hz=100.0))
        raw = bus.socket.getsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER, 16 * 8)
        filters = [struct.unpack_from("=II", raw, i) for i in range(0, len(raw), 8)]
        assert sorted(fid for fid, _ in filters) == sorted(node.inputs)
        assert all(mask & 0x7FF == 0x7FF for _, mask in filters)
    finally:
        bus.shutdown()


# Under QEMU without KVM (TCG) a pure-Python loop runs about 70x slower than on this host: the
# matrix runs at 100 Hz (with the calibration tuned for 100 Hz) in 4x slow motion (every node's
# period 40 ms of wall time: the plant keeps up, so the loop is the car's), with 5 scenario
# seconds (20 s of wall time) for the restarted Python controller to come up.  Every check is the
# same as on the fallback bus, judged in the car's time.  tools/vcan-vm-test runs it with the C
# node, and with the Python controller too when MRSTEER_VCAN_MATRIX=1 (MRSTEER_VCAN_C_MATRIX=0
# leaves the C node's out; docs/decisions/0018-slow-motion-on-an-emulated-machine.md).
VM_SETUP = dict(rate_hz=100.0, slow_motion=4.0, startup_s=5.0)


def test_fault_matrix_on_vcan0_and_vcan1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from sim_plant.harness.faults import ROWS, Setup, format_table, run_matrix
    from firmware_py.platform.rx_queue import DEPTH_BYTES

    if os.environ.get("MRSTEER_VCAN_MATRIX") == "0":
        pytest.skip("MRSTEER_VCAN_MATRIX=0 (tools/vcan-vm-test's default: 9 min under QEMU): the Python "
                    "controller's fault matrix on vcan0/vcan1 left out; it runs on the fallback bus in make test-slow")
    if not vcan_available("vcan1"):
        pytest.fail("the fault matrix needs vcan1 too (tools/vcan.sh up 2)")

    def say(msg: str) -> None:  # progress past pytest's capture: the matrix takes minutes here
        with capsys.disabled():
            print(f"fault matrix on vcan: {msg}", flush=True)

    setup = Setup("socketcan", ("vcan0", "vcan1"), **VM_SETUP)
    # A row the emulated machine stalled runs once more, as on the host (conftest).
    results = matrix_with_one_rerun(lambda rows, keep: run_matrix(rows, say, keep=keep, setup=setup), ROWS, tmp_path)
    table = format_table(results)
    say("\n" + table)
    assert all(r.ok for r in results), table
    assert len(results) == len(ROWS)
    # The processes that must see every frame run with deep kernel receive queues (root here):
    # every row's run that wrote its statistics (a rerun's are under rerun/).
    bridges = sorted(tmp_path.rglob("bridge.json"))
    assert len(bridges) >= len(ROWS) - MATRIX_RERUN_MAX
    for bridge in bridges:
        stats = [json.loads((bridge.parent / f).read_text()) for f in ("bridge.json", "logger-vehicle.json")]
        assert all(st["rx_queue_bytes"] >= DEPTH_BYTES for st in stats), bridge.parent


# ---- the C controller node (ports/c/mrs_node) on real SocketCAN -----------------------------


@pytest.fixture(scope="module")
def c_node() -> tuple[str, ...]:
    from sim_plant.harness import launch

    if shutil.which("gcc") is None:
        pytest.fail("gcc is needed to build the C node (.ci/run installs it)")
    return launch.controller_program("c")  # built on the host before the VM starts (tools/vcan-vm-test)


def test_c_node_lockstep_on_vcan0_sends_the_python_controllers_frames(
        c_node: tuple[str, ...], python_lockstep: tuple[dict, Path, str, str], tmp_path: Path) -> None:
    if os.environ.get("MRSTEER_VCAN_C_LOCKSTEP") == "0":
        pytest.skip("MRSTEER_VCAN_C_LOCKSTEP=0: the C node's lockstep comparison on vcan left out (the same "
                    "comparison runs on the fallback bus in test_c_node.py)")
    py, py_out, _, _ = python_lockstep
    c = _lockstep(tmp_path / "c", "c")
    assert c["loop"]["controller"]["implementation"] == "c"
    py_t, c_t = lockstep_traffic(py_out / "traffic.log"), lockstep_traffic(tmp_path / "c" / "traffic.log")
    assert len(c_t["commands"]) >= 300
    assert c_t["plant"] == py_t["plant"] and c_t["commands"] == py_t["commands"]
    assert c["peak_aux_steer_deg"] == py["peak_aux_steer_deg"] > 0.0


def test_c_node_filters_in_the_kernel_and_rejects_a_bad_frame(c_node: tuple[str, ...], tmp_path: Path) -> None:
    import mrsteer_dbc

    c = mrsteer_dbc.load()
    stats = tmp_path / "c.json"
    ctl = subprocess.Popen([*c_node, *IFACE, "--stats-out", str(stats)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while "running at" not in (line := ctl.stderr.readline()):
            assert line or ctl.poll() is None, "the C node died at start-up"
            assert time.monotonic() < deadline
        good = c.encode(names.MSG_YAW, {"YawRate_YawRate": 0.01}, 0)
        yaw_id = f"{c.frame_id(names.MSG_YAW):03X}"
        for frame in (f"{yaw_id}#{bytes([good[0] ^ 0x5A]).hex().upper()}{good[1:].hex().upper()}",  # bad CRC
                      "7AB#DEADBEEF", f"{yaw_id}#{good.hex().upper()}"):  # unknown ID, then a good frame
            subprocess.run([_tool("cansend"), "vcan0", frame], check=True, timeout=60)
        time.sleep(1.0)
    finally:
        ctl.send_signal(signal.SIGTERM)
        code = ctl.wait(60)
    assert code == 0
    s = json.loads(stats.read_text())
    assert s["rx_frames"] == 2 and s["rx_rejected"] == 1 and s["rx_ignored"] == 0  # 7AB never reached it


# The rows where the transport is what is tested (MRSTEER_VCAN_C_MATRIX=bus, tools/vcan-vm-test's
# default): every frame through the kernel and the bridge, a flood against the kernel's filters
# and queues, late and lost frames, signed frames, and sockets closed and opened again mid-run by
# a restarted node; one sensor fault end to end.  The other rows change only what the bridge
# writes into a frame, which the whole matrix on the fallback bus (make test-slow) judges the
# same way; MRSTEER_VCAN_C_MATRIX=all runs them here too (9 min under QEMU against 2).
BUS_ROWS = ("baseline", "sensor frames delayed 4 ms", "bus flooded with another ID", "command frames lost (burst)",
            "SecOC: baseline", "controller killed and restarted", "plant killed and restarted",
            "curve: yaw-rate gain 0.5")


def test_fault_matrix_with_the_c_node_on_vcan0_and_vcan1(c_node: tuple[str, ...], tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    from sim_plant.harness.faults import ROWS, Setup, format_table, run_matrix

    choice = os.environ.get("MRSTEER_VCAN_C_MATRIX", "all")
    if choice == "0":
        pytest.skip("MRSTEER_VCAN_C_MATRIX=0: the C node's fault matrix on vcan left out")
    if choice not in ("all", "bus"):
        pytest.fail(f"MRSTEER_VCAN_C_MATRIX must be all, bus or 0, got {choice!r}")
    rows = ROWS if choice == "all" else tuple(r for r in ROWS if r.name in BUS_ROWS)
    assert len(rows) == len(BUS_ROWS) or choice == "all", "a row of BUS_ROWS is not in the matrix"

    def say(msg: str) -> None:
        with capsys.disabled():
            print(f"fault matrix, C node, on vcan: {msg}", flush=True)

    # The plant, bridge and loggers are still Python (the VM's 70x): the same slow motion, but the
    # restarted C node starts at once, so the restart rows need only half a scenario second more.
    setup = Setup("socketcan", ("vcan0", "vcan1"), **{**VM_SETUP, "startup_s": 0.5}, controller_program=c_node)
    results = matrix_with_one_rerun(lambda rows, keep: run_matrix(rows, say, keep=keep, setup=setup), rows, tmp_path)
    table = format_table(results)
    say("\n" + table)
    assert all(r.ok for r in results), table
    assert len(results) == len(rows)
    assert json.loads((tmp_path / "01" / "controller.json").read_text())["implementation"] == "c"
