"""The fault matrix (``mrsteer faults run``): every fault on a live bus, judged from the traffic.

Each row runs the plant (realtime, ``paper-fig9``: 4000 Nm at 0.5 s) and the controller as
separate processes on two fallback buses joined by the fault bridge (``fault_bridge.py``), with
a logger on each bus.  The bridge injects one fault in a window; the runner may kill or restart
the controller or the plant.  Every row is then judged from what was logged and reported:

* **safe** (every row): the applied angle (the plant's trace; the plant stands in for the
  actuator ECU and limits its own slew to 60°/s whatever arrives) never exceeds the ±3° limit
  nor that rate, so it never jumps; and the controller's own commands on the bus never step
  by more than its rate limit (40°/s, set for these runs) from one cycle to the next;
* **nothing lost** (every row): each logger logged every frame that was on its bus, counted by
  the bridge, which sees every frame of both buses;
* **alive** (every row but the controller-kill rows): the controller ran to the end and exited cleanly;
* row-specific: detection within the stated number of controller cycles (counted in commands
  on the bus, not in wall time), the cause in ``MRS_CtrlStatus``, recovery after the fault,
  rejected frames counted, the actuator's fade after a controller crash.

Rows marked SecOC run controller and plant with a fresh random key (``$MRSTEER_SECOC_KEY``).  A
16-bit MAC lets a random guess through with probability 2^-16, so those rows allow up to
``MAC_LUCK`` lucky frames in a few hundred (the chance of more is below 1e-8) and report them.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import mrsteer_dbc
from mrsteer_dbc.busload import frame_bits
from firmware_py import model_regulator as mr
from firmware_py.controller import node as rt
from mrsteer_dbc import secoc
from mrsteer_dbc.secoc import KEY_ENV as SECOC_KEY_ENV
from sim_plant.nodes.fault_bridge import Fault
from sim_plant.harness.processes import Proc, RunError, spawn_preloaded, stop, wait_for_socket, wait_ready, wait_stderr

RATE_HZ = 1.0 / mr.ControllerConfig().ts
RATE_LIMIT = math.radians(40.0)  # rad/s, the controller's command rate limit in these runs
PLANT_FADE = math.radians(30.0)  # rad/s, the actuator's fade (plant_node default)
CMD_TIMEOUT = 0.02  # s, the actuator's command timeout (plant_node default)
DURATION = 2.6  # s of scenario
WINDOW = (1.0, 1.4)  # s after the first frame: the fault window
BUS_RESOLUTION = 1e-6  # rad, AuxSteerCmd_Angle's scale in the DBC
TRACE_RESOLUTION = 1e-8  # rad: angles up to 0.06 rad written with 9 significant digits
ACTUATOR_RATE = math.radians(60.0)  # rad/s, the actuator's own slew limit in these runs
DRAIN_TIMEOUT = 60.0  # s for bridge and loggers to work off a backlog (a slow machine lags) and exit
KILL_AT = 1.2  # s after the plant started
RESTART_AT = 1.7
# Calibrations tuned for other control rates (docs/design.md, `mrsteer design tune`): each keeps
# 6 dB / 45 deg over the envelope at its rate.  K, tau, tau_n, modelled delay.
_SHIPPED = mr.ControllerConfig()
CALIBRATIONS: dict[float, tuple[float, float, float, int]] = {
    1000.0: (50.0, 0.012, 0.02, 1),
    500.0: (_SHIPPED.k, _SHIPPED.tau, _SHIPPED.tau_n, _SHIPPED.model_delay_steps),
    200.0: (14.2, 0.0161, 0.02, 1),
    100.0: (4.52, 0.0075, 0.02, 1),
}


@dataclass(frozen=True)
class Setup:
    """Where and how fast the matrix runs.  The default is two private fallback buses at the
    shipped rate; on real SocketCAN give two interfaces (vehicle, controller).  A slow machine
    (QEMU without KVM) needs a lower rate, stretched time and longer process start-ups."""

    interface: str = "mrsteer"
    channels: tuple[str, str] | None = None  # (vehicle, controller); None: fresh fallback buses
    rate_hz: float = RATE_HZ
    time_scale: float = 1.0  # stretches the scenario, the fault window and the kill/restart times
    startup_s: float = 0.0  # extra scenario time in the restart rows for the new process to start

    def __post_init__(self) -> None:
        if self.rate_hz not in CALIBRATIONS:
            raise ValueError(f"rate must be one of {', '.join(f'{r:g}' for r in CALIBRATIONS)} Hz (a tuned "
                             f"calibration exists for each), got {self.rate_hz:g}")
        if not (math.isfinite(self.time_scale) and 1.0 <= self.time_scale <= 20.0):
            raise ValueError(f"time scale must be in [1, 20], got {self.time_scale:g}")
        if not (math.isfinite(self.startup_s) and 0.0 <= self.startup_s <= 120.0):
            raise ValueError(f"start-up allowance must be in [0, 120] s, got {self.startup_s:g}")
        if self.channels is not None and (len(self.channels) != 2 or self.channels[0] == self.channels[1]):
            raise ValueError("give two different channels: vehicle side, controller side")
        if self.channels is None and self.interface != "mrsteer":
            raise ValueError(f"--interface {self.interface} needs --channels VEHICLE,CONTROLLER")

    @property
    def ts(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def cmd_timeout(self) -> float:
        """The actuator's command timeout: the plant's 20 ms, and never under 4 control periods."""
        return max(CMD_TIMEOUT, 4.0 * self.ts)

    def gains(self) -> list[str]:
        k, tau, tau_n, m = CALIBRATIONS[self.rate_hz]
        return ["--k", repr(k), "--tau", repr(tau), "--tau-n", repr(tau_n), "--model-delay", str(m)]
TIMEOUT_CYCLES = rt.RuntimeConfig().timeout_cycles
E2E_FAIL_MAX = rt.RuntimeConfig().e2e_fail_max
# The forger's angle: the DBC maximum, just beyond the controller's 3 deg limit, so a forgery the
# actuator took is told apart from every real command.
FORGED_ANGLE = mrsteer_dbc.load().signal_range(rt.MSG_CMD, "AuxSteerCmd_Angle")[1]
MAC_LUCK = 2
COUNTER_WINDOW = mrsteer_dbc.E2EReceiver().max_delta  # the actuator's alive-counter window
# 8-byte frames a 500 kbit/s bus carries per second at most (no stuff bits): a flood at this
# rate saturates a real bus of the vehicle's kind.
FLOOD_CAPACITY = 500e3 / frame_bits(8, worst_case=False)
CONTROLLER = "firmware_py.controller.main:main"


@dataclass(frozen=True)
class Row:
    name: str
    fault: Fault
    expected: str
    detect_within: int | None = None  # controller cycles from the first affected frame to FAULT
    cause: int = 0  # CtrlStatus_Cause bit expected while faulted
    no_fault: bool = False  # the controller must stay ACTIVE/SATURATED throughout
    reject_all: bool = False  # the controller rejects (at least) every affected frame
    plant_rejects: bool = False  # the plant must reject the affected command frames
    kill: bool = False  # the runner kills the controller (SIGKILL) ...
    restart: bool = False  # ... and restarts it
    kill_plant: bool = False  # the runner kills the plant (SIGKILL) and restarts it
    secoc: bool = False  # controller and plant authenticate the commands and the sensor frames
    auth_rejects: bool = False  # the plant's SecOC check must reject the affected command frames
    e2e_only: bool = False  # shows what E2E alone lets through: meaningless with SecOC on


def _f(kind: str, target: str = "MRS_YawRate", param: float = 1.0) -> Fault:
    return Fault(kind, target, *WINDOW, param)


ROWS = (
    Row("baseline", _f("none"), "runs clean", no_fault=True),
    Row("yaw-rate frames lost (burst)", _f("drop"), "FAULT within the timeout, fade, recover",
        detect_within=TIMEOUT_CYCLES + 2, cause=rt.CAUSE_YAW_MISSING),
    Row("sensor frames lost (20 % random)", _f("drop", "sensors", 0.2), "tolerated, no fault", no_fault=True),
    Row("yaw-rate payload bit flipped", _f("corrupt_payload"), "rejected (CRC), FAULT after 3, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=rt.CAUSE_E2E, reject_all=True),
    Row("yaw-rate CRC corrupted", _f("corrupt_crc"), "rejected, FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=rt.CAUSE_E2E, reject_all=True),
    Row("yaw-rate counter invalid (15)", _f("corrupt_counter"), "rejected, FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=rt.CAUSE_E2E, reject_all=True),
    Row("driver-angle frame too short", _f("wrong_length", "MRS_DriverSteer"), "rejected, FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=rt.CAUSE_E2E, reject_all=True),
    Row("yaw-rate frames replayed", _f("replay", param=1.0), "every replayed frame rejected, no fault",
        no_fault=True, reject_all=True),
    Row("yaw rate out of range (5 rad/s)", _f("out_of_range", param=5.0), "rejected (range), FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=rt.CAUSE_RANGE, reject_all=True),
    Row("sensor frames duplicated", _f("duplicate", "sensors"), "copies rejected as repeated, no fault",
        no_fault=True, reject_all=True),
    Row("yaw-rate frames reordered", _f("reorder"), "out-of-order frames rejected, no fault", no_fault=True),
    Row("sensor frames delayed 4 ms", _f("delay", "sensors", 0.004), "tolerated, no fault", no_fault=True),
    Row("bus flooded with another ID", _f("flood", param=5000.0), "filtered out, no fault, nothing lost",
        no_fault=True),
    Row("command frames lost (burst)", _f("drop", "commands"), "actuator times out, fades, slews back"),
    Row("command CRC corrupted", _f("corrupt_crc", "commands"), "actuator rejects them", plant_rejects=True),
    # The same forger without SecOC: E2E alone takes it (docs/faults.md, "E2E is not security");
    # the actuator's own +-3 deg still bounds what it does.
    Row("commands forged, E2E only", _f("spoof_command", "commands", FORGED_ANGLE),
        "forgeries taken, actuator within 3 deg", e2e_only=True),
    Row("SecOC: baseline", _f("none"), "runs clean, every frame authenticated", no_fault=True, secoc=True),
    # The forger sends the next alive counter with a valid CRC: E2E alone would take it.
    Row("SecOC: commands forged", _f("spoof_command", "commands", FORGED_ANGLE),
        "forgeries rejected (MAC), real ones kept", secoc=True, auth_rejects=True),
    # 13 back lands 2 ahead of the 4-bit alive counter: E2E alone takes every replay and rejects
    # the live frames instead (docs/faults.md); the sensor frames' MAC must refuse them.
    Row("SecOC: yaw-rate replayed 13 back", _f("replay", param=13.0), "every replay rejected (MAC), no fault",
        no_fault=True, reject_all=True, secoc=True),
    # 150 frames (0.3 s) back: counter-aligned, so E2E alone would take them (docs/faults.md).
    Row("SecOC: 0.3 s old commands substituted", _f("substitute", "commands", 150.0),
        "stale freshness rejected, fade, slew back", secoc=True, auth_rejects=True),
    Row("controller killed", _f("none"), "actuator at zero within timeout + fade", kill=True),
    Row("controller killed and restarted", _f("none"), "resumes without a jump", kill=True, restart=True),
    # The vehicle side crashes: every input goes missing at once, then comes back from a fresh
    # plant (its counters from 0, its scenario from the start).
    Row("plant killed and restarted", _f("none"), "FAULT within the timeout, fade, recover",
        detect_within=TIMEOUT_CYCLES + 2, cause=rt.CAUSE_YAW_MISSING, kill_plant=True),
)


@dataclass
class RowResult:
    name: str
    expected: str
    passed: bool
    observed: str
    worst_applied_deg: float
    worst_step_deg: float
    detection_cycles: int | None
    failures: list[str] = field(default_factory=list)


def _parse_log(path: Path) -> list[tuple[float, int, bytes]]:
    frames = []
    for line in path.read_text().splitlines():
        stamp, _, body = line.split(" ", 2)
        ident, _, data = body.partition("#")
        frames.append((float(stamp.strip("()")), int(ident, 16), bytes.fromhex(data)))
    return frames


def _trace(path: Path) -> tuple[list[float], list[float], list[float], list[float]]:
    """Plant time, applied angle, the command the actuator holds and the wall clock (epoch s)
    of every plant step."""
    t, applied, held, wall = [], [], [], []
    lines = path.read_text().splitlines()
    head = lines[0].split(",")
    ti, ai, ci, wi = (head.index(n) for n in ("t_s", "aux_applied_rad", "aux_cmd_rad", "wall_s"))
    for line in lines[1:]:
        cols = line.split(",")
        t.append(float(cols[ti]))
        applied.append(float(cols[ai]))
        held.append(float(cols[ci]))
        wall.append(float(cols[wi]))
    return t, applied, held, wall


def _gaps(frames: list[tuple[float, int, bytes]], ids: list[int], longer: float) -> list[tuple[float, float]]:
    """Intervals in which a message of ``ids`` went quiet for longer than ``longer`` s."""
    out = []
    for fid in ids:
        times = [t for t, f, _ in frames if f == fid]
        out += [(a, b) for a, b in zip(times, times[1:]) if b - a > longer]
    return out


def _fault_on_bad_frame(frames: list[tuple[float, int, bytes]], cmds: list[tuple[float, float]], bridge: dict,
                        row: Row, first_fault: float) -> bool:
    """The controller's own rule, for rejected-frame faults: FAULT in the first cycle after
    the ``E2E_FAIL_MAX``-th bad frame reached its bus (or the next, if that frame came while
    the cycle was under way).  Detection in cycles equals this when frames come once a cycle;
    when the machine stalls the sender, the cycles run on without frames and the count grows."""
    c = mrsteer_dbc.load()
    ids = {c.frame_id(n) for n in row.fault.targets()}
    bad = [t_ for t_, fid, _ in frames if fid in ids and t_ >= bridge["first_affected"]]
    if len(bad) < E2E_FAIL_MAX:
        return False
    nth = bad[E2E_FAIL_MAX - 1]
    return sum(1 for t_, _ in cmds if nth < t_ < first_fault) <= 1


def run_row(row: Row, work: Path, say: Callable[[str], None], setup: Setup = Setup()) -> RowResult:
    env = dict(os.environ)
    scale = setup.time_scale
    fault = replace(row.fault, start=row.fault.start * scale, stop=row.fault.stop * scale)
    duration = DURATION * scale + (setup.startup_s if row.restart else 0.0)
    restart_duration = (DURATION - RESTART_AT) * scale + setup.startup_s  # the second plant's
    if setup.channels is None:
        tag = f"f{os.getpid()}-{int(time.time() * 1000) % 10**7}"
        ch_a, ch_b = f"{tag}-veh", f"{tag}-ctl"
    else:
        ch_a, ch_b = setup.channels
    iface = ["--interface", setup.interface]
    procs: list[Proc] = []
    secoc = ["--secoc"] if row.secoc else []
    if row.secoc:
        env[SECOC_KEY_ENV] = os.urandom(16).hex()
    ctl_cmd = [*iface, "--channel", ch_b, "--rate-hz", repr(setup.rate_hz), *setup.gains(),
               "--rate-limit", repr(RATE_LIMIT), "--stats-out", str(work / "controller.json"), *secoc]
    try:
        for ch in (ch_a, ch_b) if setup.channels is None else ():
            procs.append(spawn_preloaded(f"broker {ch}", "firmware_py.platform.fallback_broker:main", ["--channel", ch], work, env))
            wait_for_socket(ch, procs[-1])
        loggers = []
        for side, ch in (("vehicle", ch_a), ("controller", ch_b)):
            lg = spawn_preloaded(f"logger {side}", "sim_plant.nodes.logger:main",
                                 [*iface, "--channel", ch, "--out", str(work / f"{side}.log"), "--iface-name", side,
                                  "--stats-out", str(work / f"logger-{side}.json")], work, env, stdout=True)
            procs.append(lg)
            loggers.append(lg)
            wait_ready(lg)
        # The bridge first: it must see every frame the controller ever sends.
        bridge = spawn_preloaded("bridge", "sim_plant.nodes.fault_bridge:main",
                                 [*iface, "--vehicle", ch_a, "--controller", ch_b, "--fault", json.dumps(asdict(fault)),
                                  "--stats-out", str(work / "bridge.json")], work, env)
        procs.append(bridge)
        wait_stderr(bridge, "bridging")
        ctl = spawn_preloaded("controller", CONTROLLER, ctl_cmd, work, env)
        procs.append(ctl)
        wait_stderr(ctl, "running at")

        def start_plant(name: str, seconds: float) -> Proc:
            # A killed plant writes nothing: its statistics and trace are the next one's files.
            p = spawn_preloaded(name, "sim_plant.nodes.plant:main",
                                [*iface, "--channel", ch_a, "--mode", "realtime", "--rate-hz", repr(setup.rate_hz),
                                 "--actuator-rate", repr(ACTUATOR_RATE), "--cmd-timeout", repr(setup.cmd_timeout),
                                 "--scenario", "paper-fig9", "--duration", repr(seconds),
                                 "--trace-out", str(work / "trace.csv"), "--stats-out", str(work / "plant.json"),
                                 *secoc], work, env)
            procs.append(p)
            return p

        plant = start_plant("plant", duration)
        wait_stderr(plant, "realtime) on")  # started: kill and restart times count from here
        start = time.monotonic()
        killed_at = restarted = None
        while plant.popen.poll() is None or (row.kill_plant and restarted is None):
            now = time.monotonic() - start
            victim = ctl if row.kill else plant if row.kill_plant else None
            if victim is not None and killed_at is None and now >= KILL_AT * scale:
                victim.popen.send_signal(signal.SIGKILL)
                victim.popen.wait()
                killed_at = time.time()
            if killed_at is not None and restarted is None and now >= RESTART_AT * scale:
                if row.restart:
                    ctl = spawn_preloaded("controller-2", CONTROLLER, ctl_cmd, work, env)
                    procs.append(ctl)
                    restarted = time.time()
                elif row.kill_plant:
                    plant = start_plant("plant-2", restart_duration)
                    restarted = time.time()
            if time.monotonic() - start > 120 + 2 * duration:
                raise RunError("the plant did not finish in time")
            time.sleep(0.01)
        ctl_code = None
        if ctl.popen.poll() is None:
            stop(ctl)
            ctl_code = ctl.popen.returncode
        for p in (bridge, *loggers):
            stop(p, timeout=DRAIN_TIMEOUT)
    finally:
        for p in reversed(procs):
            stop(p)
    return judge(row, work, ctl_code, killed_at, restarted, setup)


def judge(row: Row, work: Path, ctl_code: int | None, killed_at: float | None,
          restarted: float | None, setup: Setup = Setup()) -> RowResult:
    c = mrsteer_dbc.load()
    fails: list[str] = []
    observed: list[str] = []
    t, applied, held, wall = _trace(work / "trace.csv")
    ts = setup.ts
    limit = mr.ControllerConfig().aux_limit
    worst = max(abs(a) for a in applied)
    steps = [abs(b - a) for a, b in zip(applied, applied[1:])]
    worst_step = max(steps) if steps else 0.0
    if worst > limit + BUS_RESOLUTION:  # the command travels rounded to the DBC's 1e-6 rad
        fails.append(f"applied {math.degrees(worst):.3f} deg beyond the limit")
    # The actuator (the plant, standing in for its ECU) limits its own slew to ACTUATOR_RATE
    # whatever arrives; this checks that it does, step by step, faults and crashes included.
    # The trace holds 9 significant digits: a step at exactly the limit may read up to ~1e-9 rad over.
    if worst_step > max(ACTUATOR_RATE, PLANT_FADE) * ts + TRACE_RESOLUTION:
        fails.append(f"applied angle jumped {math.degrees(worst_step):.4f} deg in one step")

    bridge = json.loads((work / "bridge.json").read_text())
    plant = json.loads((work / "plant.json").read_text())
    vehicle_frames = _parse_log(work / "vehicle.log")
    plant_tx = plant["tx_frames"]
    if row.kill_plant and restarted is not None:
        # The killed plant wrote no statistics: its frames are the ones its logger saw.
        own = {c.frame_id(n) for n in (rt.MSG_STEER, rt.MSG_YAW, rt.MSG_SPEED, secoc.SYNC)}
        plant_tx += sum(1 for t_, fid, _ in vehicle_frames if fid in own and t_ < restarted)
        observed.append("applied angle judged on the restarted plant's trace")
    logged = {side: json.loads((work / f"logger-{side}.json").read_text())["frames"]
              for side in ("vehicle", "controller")}
    on_a = bridge["seen_on_vehicle"] + bridge["forwarded_to_vehicle"] + bridge["injected_to_vehicle"]
    on_b = bridge["seen_on_controller"] + bridge["forwarded_to_controller"] + bridge["injected_to_controller"]
    if logged["vehicle"] != on_a or logged["controller"] != on_b:
        fails.append(f"logger lost frames: vehicle {logged['vehicle']}/{on_a}, controller {logged['controller']}/{on_b}")
    if bridge["seen_on_vehicle"] != plant_tx:
        fails.append(f"bridge saw {bridge['seen_on_vehicle']} of the plant's {plant_tx} frames")
    observed.append(f"logged {logged['vehicle']}+{logged['controller']} frames, none lost")
    if plant["overruns"] > 0.1 * plant["steps"]:
        # Every check still holds, but the closed loop's shape is not the one a 100 % on-time
        # plant gives: say so next to the result.
        observed.append(f"machine too slow: plant late in {plant['overruns']}/{plant['steps']} steps")

    ctl_stats = json.loads((work / "controller.json").read_text()) if (work / "controller.json").exists() else None
    if not row.kill:
        if ctl_code != 0:
            fails.append(f"controller exit status {ctl_code}")
        if ctl_stats is None:
            fails.append("controller wrote no statistics")

    # Commands and status on the controller's bus.
    frames = _parse_log(work / "controller.log")
    cmd_id, status_id = c.frame_id(rt.MSG_CMD), c.frame_id(rt.MSG_STATUS)
    cmds = [(ts_, c.decode(fid, data)) for ts_, fid, data in frames if fid == cmd_id]
    cutoff = max(ts_ for ts_, fid, _ in vehicle_frames
                 if fid == c.frame_id(rt.MSG_YAW))  # the plant's last measurement: the run's end
    angles = [(t_, d.signals["AuxSteerCmd_Angle"]) for t_, d in cmds
              if d is not None and d.status.accepted and t_ <= cutoff]
    cmds = [(t_, d.signals["AuxSteerCmd_State"]) for t_, d in cmds
            if d is not None and d.status.accepted and t_ <= cutoff]
    # The controller's own commands respect its rate limit, faults and restarts included
    # (bus resolution 1e-6 rad); across a kill the next instance starts again from zero.
    for (ta, a), (tb, b) in zip(angles, angles[1:]):
        crash = killed_at is not None and ta <= killed_at and (restarted is None or tb >= restarted)
        if not crash and abs(b - a) > RATE_LIMIT * ts + 2e-6:
            fails.append(f"command stepped {math.degrees(abs(b - a)):.4f} deg in one cycle")
            break

    statuses = [(t_, c.decode(fid, data)) for t_, fid, data in frames if fid == status_id]
    causes = [(t_, int(d.signals["CtrlStatus_Cause"])) for t_, d in statuses if d is not None]
    first_active = next((t_ for t_, s in cmds if s in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED)), None)
    faults_after = [t_ for t_, s in cmds if s == mr.STATUS_FAULT and first_active is not None and t_ > first_active]
    detection = None
    if row.no_fault and faults_after:
        # A FAULT is the right answer when the machine stalled the plant past the timeout: judge
        # only those without such a gap in the sensor frames the controller was given.
        # Each input times out after TIMEOUT_CYCLES of its own cycle (speed: 10 ms at most rates).
        gaps = [g for n in (rt.MSG_STEER, rt.MSG_YAW, rt.MSG_SPEED)
                for g in _gaps(frames, [c.frame_id(n)], TIMEOUT_CYCLES * (c.cycle_time_s(n, ts) or ts) - ts)]
        unexplained = [t_ for t_ in faults_after if not any(g0 - 0.005 <= t_ <= g1 + 0.1 for g0, g1 in gaps)]
        if unexplained:
            fails.append(f"controller faulted without a cause {len(unexplained)} times")
        else:
            observed.append(f"{len(gaps)} sensor gap(s) from machine stalls, each detected")
    affected0, affected1 = bridge["first_affected"], bridge["last_affected"]
    if row.kill_plant and killed_at is not None:
        # The outage, as the controller saw it: from when the dead plant's next yaw-rate frame
        # was due to the restarted plant's first one.
        yaws = [t_ for t_, fid, _ in frames if fid == c.frame_id(rt.MSG_YAW)]
        last = max((t_ for t_ in yaws if t_ <= killed_at), default=None)
        affected0 = None if last is None else last + (c.cycle_time_s(rt.MSG_YAW, ts) or ts)
        affected1 = min((t_ for t_ in yaws if restarted is not None and t_ >= restarted), default=killed_at)
    first_fault = None
    if row.detect_within is not None:
        if affected0 is None:
            fails.append("the fault never hit a frame")
        else:
            first_fault = next((t_ for t_ in faults_after if t_ >= affected0), None)
            if first_fault is None:
                fails.append("fault not detected")
            else:
                detection = sum(1 for t_, _ in cmds if affected0 <= t_ <= first_fault)
                observed.append(f"FAULT after {detection} cycles")
                if detection > row.detect_within:
                    stalled = row.reject_all and _fault_on_bad_frame(frames, cmds, bridge, row, first_fault)
                    if stalled:
                        observed.append(f"bad frames came slower than cycles (machine stall); FAULT in the cycle "
                                        f"after the {E2E_FAIL_MAX}th")
                    else:
                        fails.append(f"detected after {detection} cycles, allowed {row.detect_within}")
                seen = [cause for t_, cause in causes if first_fault <= t_ <= affected1 + 0.05]
                if row.cause and not any(cause & row.cause for cause in seen):
                    fails.append(f"status never gave cause 0x{row.cause:02X} (saw {sorted(set(seen))})")
            back = next((t_ for t_, s in cmds if t_ > affected1 and s in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED)), None)
            if back is None:
                fails.append("did not recover after the fault")
            else:
                observed.append(f"recovered {1e3 * (back - affected1):.0f} ms after")
    if row.kill_plant and first_fault is not None:
        # With every input gone the controller fades its command: it never grows meanwhile.
        fading = [abs(a) for t_, a in angles if first_fault <= t_ <= affected1]
        if any(b > a + 2e-6 for a, b in zip(fading, fading[1:])):
            fails.append("the command grew while the inputs were missing")
        elif fading:
            observed.append(f"command faded {math.degrees(fading[0]):.2f}° to {math.degrees(fading[-1]):.2f}° "
                            f"while the plant was down")
    if ctl_stats is not None:
        rejected = ctl_stats["rx_rejected"]
        observed.append(f"controller rejected {rejected}")
        if row.reject_all and rejected < bridge["affected"]:
            fails.append(f"controller rejected {rejected} of {bridge['affected']} bad frames")
        if ctl_stats["rx_ignored"]:
            fails.append(f"{ctl_stats['rx_ignored']} foreign frames reached the controller process")
    if row.fault.kind == "flood":
        rate = bridge["injected_to_controller"] / ((row.fault.stop - row.fault.start) * setup.time_scale)
        observed.append(f"flood {rate:.0f} frames/s, {100.0 * rate / FLOOD_CAPACITY:.0f} % of a 500 kbit/s bus")
    if row.plant_rejects:
        if plant["cmd_rejected"] < bridge["affected"]:
            fails.append(f"plant rejected {plant['cmd_rejected']} of {bridge['affected']} corrupted commands")
        observed.append(f"plant rejected {plant['cmd_rejected']}")
    if row.secoc:
        # Real commands fail too: before the controller has the first sync, and when they reach
        # the actuator an epoch too late (a stalled machine).  Both are right; shown, not judged.
        observed.append(f"plant: {plant['cmd_auth_failed']} failed SecOC")
        if ctl_stats is not None:
            sensor_failed = ctl_stats.get("rx_auth_failed", 0)
            observed.append(f"controller: {sensor_failed} sensor frames failed SecOC")
            # With E2E alone an aliased replay is accepted and the live frame rejected instead, so
            # the count of rejections proves nothing here: the MAC must be what refused them.
            # (Corrupted frames are refused earlier, by their CRC, length or range.)
            if row.fault.kind == "replay" and sensor_failed < bridge["affected"]:
                fails.append(f"the controller's SecOC refused {sensor_failed} of {bridge['affected']} replayed frames")
    if row.auth_rejects:
        failed = plant["cmd_auth_failed"]
        if failed < bridge["affected"] - MAC_LUCK:
            fails.append(f"plant's SecOC rejected {failed} of {bridge['affected']} bad commands")
    if row.fault.kind == "spoof_command" and row.secoc:
        # Each forgery the actuator took would show as its marker angle in the held command.
        taken = sum(1 for a, b in zip([0.0, *held], held) if abs(b - FORGED_ANGLE) < 5e-7 <= abs(a - FORGED_ANGLE))
        observed.append(f"{taken} of {bridge['affected']} forgeries taken")
        if taken > MAC_LUCK:
            fails.append(f"the actuator took {taken} forged commands")
        # Authentication comes before the counter check, so forgeries cannot push the real
        # commands out of the alive-counter sequence.
        # Real commands that fail authentication (before the first sync; an epoch late when the
        # machine stalls) leave gaps in the sequence the actuator saw, and a gap wider than the
        # counter window (3) costs the next command: only those are allowed.
        e2e_rejected = plant["cmd_rejected"] - plant["cmd_auth_failed"]
        real_lost = max(0, plant["cmd_auth_failed"] - bridge["affected"])
        allowed = MAC_LUCK + real_lost // (COUNTER_WINDOW + 1)
        if e2e_rejected > allowed:
            fails.append(f"{e2e_rejected} real commands rejected by the counter check after forgeries "
                         f"({allowed} explained by {real_lost} real commands that failed SecOC)")
    elif row.fault.kind == "spoof_command":
        # Without SecOC the same forger must get through (else the SecOC row proves nothing);
        # the actuator's own range still holds (the "safe" check above).
        steps = sum(1 for b in held if abs(b - FORGED_ANGLE) < 5e-7)
        observed.append(f"the actuator held a forged command in {steps} steps; real ones pushed out of sequence: "
                        f"{plant['cmd_rejected']}")
        if steps == 0:
            fails.append("no forgery was taken: the forger is not the threat the SecOC row claims to stop")
    if row.kill and killed_at is not None:
        # The actuator's timeout runs from the last command it was given: the dead controller's
        # last one as it reached the vehicle's bus (the bridge forwards in order, and late when
        # the machine stalls it).
        sent = sum(1 for t_, fid, _ in frames if fid == cmd_id and t_ <= killed_at)
        delivered = [t_ for t_, fid, _ in vehicle_frames if fid == cmd_id]
        last_cmd = delivered[sent - 1] if 0 < sent <= len(delivered) else killed_at
        # The step that first ran after that command was on the bus: a plant that lags the wall
        # clock (a slow machine) gets there late, and its timeout counts its own steps from there.
        i_kill = next((i for i, w in enumerate(wall) if w >= last_cmd), len(t) - 1)
        a_kill = abs(applied[i_kill])
        allowed = setup.cmd_timeout + a_kill / PLANT_FADE + 3 * ts + 0.05
        i_zero = next((i for i in range(i_kill, len(t)) if applied[i] == 0.0), None)
        end = next((t[i] for i, w in enumerate(wall) if w >= restarted), t[-1]) if restarted is not None else t[-1]
        if i_zero is None or t[i_zero] - t[i_kill] > allowed or t[i_zero] > end:
            fails.append(f"actuator not at zero within {allowed * 1e3:.0f} ms of the controller's death")
        else:
            observed.append(f"actuator at 0 {1e3 * (t[i_zero] - t[i_kill]):.0f} ms after the last command")
        if row.restart:
            back = [t_ for t_, s in cmds if restarted is not None and t_ > restarted and s == mr.STATUS_ACTIVE]
            if not back:
                fails.append("the restarted controller never became active")
            else:
                observed.append("restarted controller active again")
    return RowResult(row.name, row.expected, not fails, "; ".join(observed), math.degrees(worst),
                     math.degrees(worst_step), detection, fails)


def secured_rows(rows: tuple[Row, ...] = ROWS) -> tuple[Row, ...]:
    """The rows as they run with SecOC on (``faults run --secoc``): every row authenticates,
    the E2E-only rows are left out, and a row that became the same run as an earlier one (the
    baseline and "SecOC: baseline") appears once."""
    out: list[Row] = []
    seen: set[Row] = set()
    for row in rows:
        if row.e2e_only:
            continue
        row = replace(row, secoc=True)
        key = replace(row, name="", expected="")
        if key not in seen:
            seen.add(key)
            out.append(row)
    return tuple(out)


def _holds_files(keep: Path | None) -> bool:
    """A --keep directory must start empty: an earlier run's statistics would be judged as this run's."""
    return keep is not None and keep.is_dir() and any(keep.iterdir())


def run_matrix(rows: tuple[Row, ...] = ROWS, say: Callable[[str], None] | None = None,
               keep: Path | None = None, setup: Setup = Setup()) -> list[RowResult]:
    say = say or (lambda m: None)
    if _holds_files(keep):
        raise RunError(f"{keep} is not empty: an earlier run's files would be judged as this run's")
    results = []
    with tempfile.TemporaryDirectory(prefix="mrsteer-faults-") as tmp:
        for i, row in enumerate(rows, 1):
            work = (keep or Path(tmp)) / f"{i:02d}"
            work.mkdir(parents=True, exist_ok=True)
            say(f"[{i}/{len(rows)}] {row.name}")
            results.append(run_row(row, work, say, setup))
    return results


def format_table(results: list[RowResult]) -> str:
    lines = [f"{'fault':<38}{'expected':<42}{'result':<7}{'max |applied|':>14}{'max step':>10}{'detect':>8}  observed",
             "-" * 160]
    for r in results:
        det = "-" if r.detection_cycles is None else f"{r.detection_cycles} cyc"
        lines.append(f"{r.name:<38}{r.expected:<42}{'PASS' if r.passed else 'FAIL':<7}{r.worst_applied_deg:>12.3f} deg"
                     f"{r.worst_step_deg:>8.4f}°{det:>8}  {r.observed}")
        for f in r.failures:
            lines.append(f"{'':<38}!! {f}")
    n_pass = sum(r.passed for r in results)
    lines.append(f"{n_pass}/{len(results)} rows pass")
    return "\n".join(lines)


def main(argv: list[str] | None = None, prog: str = "mrsteer faults") -> int:
    import argparse

    from firmware_py.platform.cli import Parser

    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["bridge"]:  # the bridge owns its whole argument list, --help included
        from sim_plant.nodes.fault_bridge import main as bridge_main

        return bridge_main(argv[1:], prog=f"{prog} bridge")
    p = Parser(prog=prog, description="Fault injection: the fault matrix, or the bridge on its own.")
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    r = sub.add_parser("run", help="run the fault matrix and print the table",
                       description="Run every row of the fault matrix (each a few seconds of realtime plant and "
                       "controller joined by the fault bridge) and judge it from the logged traffic.  By default "
                       "on two private fallback buses; on SocketCAN: --interface socketcan --channels vcan0,vcan1 "
                       "(tools/vcan.sh up 2).")
    r.add_argument("--only", action="append", metavar="TEXT", help="only rows whose name contains TEXT; repeatable")
    r.add_argument("--keep", type=Path, metavar="DIR", help="keep every row's logs, traces and statistics here")
    r.add_argument("--json", action="store_true", help="print the results as JSON")
    r.add_argument("--secoc", action="store_true",
                   help="run every row with the commands and sensor frames authenticated (a random key per row); "
                   "the rows that show what E2E alone lets through are left out")
    r.add_argument("--interface", default="mrsteer", help="python-can interface of both buses (default mrsteer, "
                   "the fallback bus)")
    r.add_argument("--channels", metavar="VEHICLE,CONTROLLER",
                   help="the two buses the bridge joins (default: two private fallback buses)")
    r.add_argument("--rate-hz", type=float, default=RATE_HZ,
                   help=f"control and plant rate, one of {', '.join(f'{k:g}' for k in CALIBRATIONS)}, each with its "
                   f"tuned calibration (default {RATE_HZ:g})")
    r.add_argument("--time-scale", type=float, default=1.0, metavar="F",
                   help="stretch scenario, fault window and kill/restart times by F, for slow machines (default 1)")
    r.add_argument("--startup-s", type=float, default=0.0, metavar="S",
                   help="extra scenario seconds in the restart rows for the new process to start (default 0)")
    b = sub.add_parser("bridge", help="the fault-injecting bridge on its own (see --help)", add_help=False)
    b.add_argument("args", nargs=argparse.REMAINDER)
    args = p.parse_args(argv)
    every = secured_rows() if args.secoc else ROWS
    rows = tuple(row for row in every if not args.only or any(o.lower() in row.name.lower() for o in args.only))
    if not rows:
        p.error(f"no row matches {args.only}; rows: " + "; ".join(r.name for r in every))
    try:
        channels = tuple(args.channels.split(",")) if args.channels else None
        setup = Setup(args.interface, channels, args.rate_hz, args.time_scale, args.startup_s)  # type: ignore[arg-type]
    except ValueError as exc:
        p.error(str(exc))
    if args.keep is not None and args.keep.exists() and not args.keep.is_dir():
        p.error(f"--keep {args.keep} exists and is not a directory")
    if _holds_files(args.keep):
        p.error(f"--keep {args.keep} is not empty: an earlier run's files would be judged as this run's")
    try:
        results = run_matrix(rows, lambda m: print(f"{prog}: {m}", file=sys.stderr, flush=True), args.keep, setup)
    except RunError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps([asdict(r) for r in results], indent=2))
    else:
        print(format_table(results))
    return 0 if all(r.passed for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
