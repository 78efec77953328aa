"""Real separate processes on the fallback bus: HIL runs against the offline simulation,
faults, shutdown and crash handling."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

import mrsteer_dbc
from mrsteer_dbc import names
from firmware_py import model_regulator as mr
from firmware_py.controller import node as rt
from sim_plant import figures
from sim_plant.car import scenario as scn
from sim_plant.harness import hil_plot
from sim_plant.harness.hil_steps import read_steps_csv

from conftest import logged_states

ROOT = Path(__file__).resolve().parents[1]
C = mrsteer_dbc.load()


def mrsteer(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mrsteer_cli", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout, env=os.environ.copy())


def _offline(*args: str) -> dict:
    proc = mrsteer("sim", "disturbance", *args, "--json")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _close(a: dict, b: dict, rel: float) -> None:
    for key in ("peak_aux_steer_deg", "final_aux_steer_deg", "peak_yaw_rate_rad_s", "final_yaw_rate_rad_s"):
        assert a[key] == pytest.approx(b[key], rel=rel), key


@pytest.fixture(scope="module")
def lockstep_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("hil-lockstep")
    proc = mrsteer("hil", "run", "--scenario", "paper-fig9", "--mode", "lockstep", "--v", "27", "--mu", "0.9",
                   "--mz", "3000", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout), out


def test_lockstep_matches_the_offline_firmware_simulation(lockstep_run: tuple[dict, Path]) -> None:
    hil, _ = lockstep_run
    assert hil["rate_hz"] == rt.DEFAULT_RATE_HZ and hil["delay_steps"] == 1 and hil["mode"] == "lockstep"
    offline = _offline("--mz", "3000", "--v", "27", "--mu", "0.9", "--ts", repr(1.0 / rt.DEFAULT_RATE_HZ),
                       "--delay-steps", "1")
    _close(hil, offline, rel=0.01)
    assert hil["saturated"] == offline["saturated"] and hil["stable"] == offline["stable"]
    assert hil["commands_answering_measurements"] == hil["measurements"]  # every step answered
    f = hil["frames"]
    assert f["on_bus_logged"] == f["sent_plant"] + f["sent_controller"]  # the logger lost nothing
    assert f["rejected_controller"] == 0 and f["rejected_plant"] == 0


def test_lockstep_with_secoc_authenticates_every_command_and_changes_nothing(
        lockstep_run: tuple[dict, Path], tmp_path: Path) -> None:
    key = tmp_path / "key.hex"
    key.write_text(os.urandom(16).hex())
    proc = mrsteer("hil", "run", "--scenario", "paper-fig9", "--mode", "lockstep", "--v", "27", "--mu", "0.9",
                   "--mz", "3000", "--out", str(tmp_path / "out"), "--json", "--secoc-key", str(key))
    assert proc.returncode == 0, proc.stderr
    secured, (plain, _) = json.loads(proc.stdout), lockstep_run
    assert secured["secoc"] and not plain["secoc"]
    f = secured["frames"]
    assert f["rejected_plant"] == 0 and f["auth_failed_plant"] == 0  # the sync precedes the first command
    assert secured["commands_answering_measurements"] == secured["measurements"]
    for k in ("peak_aux_steer_deg", "final_aux_steer_deg", "peak_yaw_rate_rad_s", "final_yaw_rate_rad_s"):
        assert secured[k] == plain[k], k  # authentication does not touch the values
    syncs = [line for line in (tmp_path / "out" / "traffic.log").read_text().splitlines() if " 0A1#" in line]
    assert len(syncs) == round(secured["duration"] / 0.1) + 1  # one every 100 ms of plant time, from step 0


def test_outputs_are_written_and_the_log_decodes_with_cantools(lockstep_run: tuple[dict, Path]) -> None:
    _, out = lockstep_run
    assert sorted(p.name for p in out.iterdir()) == ["plot.png", "signals.csv", "steps.csv", "summary.json",
                                                     "traffic.log"]
    log = (out / "traffic.log").read_text()
    first = log.splitlines()[0]
    assert first.startswith("(") and "#" in first  # candump -L
    dec = subprocess.run([sys.executable, "-m", "cantools", "decode", str(mrsteer_dbc.DBC_PATH)],
                         input=log, capture_output=True, text=True, timeout=300)
    assert dec.returncode == 0, dec.stderr
    for name in ("MRS_YawRate(", "MRS_AuxSteerCmd(", "MRS_DriverSteer(", "MRS_VehicleSpeed(", "MRS_CtrlStatus("):
        assert name in dec.stdout
    assert "Unknown frame id" not in dec.stdout
    header = (out / "signals.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["t_s", "bus_time_s", "message", "e2e"] and "YawRate_YawRate" in header


PNG = b"\x89PNG\r\n\x1a\n"


def test_the_step_table_spans_the_scenario_and_the_plot_is_drawn_from_it(lockstep_run: tuple[dict, Path]) -> None:
    hil, out = lockstep_run
    steps = read_steps_csv(out / "steps.csv")
    ts = 1.0 / hil["rate_hz"]
    assert abs(len(steps) - (hil["duration"] / ts + 1)) <= 1 and hil["steps"] == len(steps)
    assert steps[0].t_s == 0.0 and abs(steps[-1].t_s - hil["duration"]) <= ts
    assert all(b.t_s - a.t_s == pytest.approx(ts, abs=1e-6) for a, b in zip(steps, steps[1:]))
    assert all(b.wall_s > a.wall_s for a, b in zip(steps, steps[1:]))
    # Scenario time, not wall time: the 3000 Nm step is at the scenario's 0.5 s.
    onset = next(s.t_s for s in steps if s.m_z_nm != 0.0)
    assert onset == pytest.approx(scn.load("paper-fig9").first_disturbance_time) and steps[-1].m_z_nm == 3000.0
    assert all(s.ctrl_state in ("ACTIVE", "SATURATED") for s in steps)  # every step answered, none faulted
    assert {s.ctrl_cause for s in steps[-100:]} == {0}
    # The table agrees with the bus summary, and nothing after the scenario is in it: the
    # controller's final zero command (in the log) is no step's command.
    deg = figures.resolution_of("peak_aux_steer_deg")  # the summary's rounding
    assert math.degrees(max(abs(s.aux_cmd_rad) for s in steps)) == pytest.approx(hil["peak_aux_steer_deg"], abs=deg)
    assert math.degrees(steps[-1].aux_cmd_rad) == pytest.approx(hil["final_aux_steer_deg"], abs=deg)
    lsb = mrsteer_dbc.load().message(names.MSG_YAW).get_signal_by_name(names.SIG_YAW_RATE).scale
    assert steps[-1].yaw_rate_rad_s == pytest.approx(hil["final_yaw_rate_rad_s"], abs=0.5 * lsb + 1e-12)  # rounded on the bus
    with (out / "signals.csv").open() as f:
        last_cmd = [r for r in csv.DictReader(f) if r["message"] == "MRS_AuxSteerCmd"][-1]
    assert float(last_cmd["AuxSteerCmd_Angle"]) == 0.0 and float(last_cmd["bus_time_s"]) > steps[-1].wall_s
    assert (out / "plot.png").read_bytes()[:8] == PNG
    png = hil_plot.run_png(steps, hil_plot.event_marks(scn.load("paper-fig9")), "from steps.csv")
    assert png is not None and png[:8] == PNG


def test_a_clean_lockstep_run_shows_no_fault_or_degraded_and_enters_no_fault(lockstep_run: tuple[dict, Path]) -> None:
    """STARTING (the watchdog cycles before the plant's first frame) instead of FAULT, then
    ACTIVE or SATURATED to the end, INACTIVE last (the shutdown); the loop's faults_entered 0."""
    hil, out = lockstep_run
    cmds, statuses, after = logged_states(out / "traffic.log")
    run = [s for s, late in zip(cmds, after) if not late]
    first = next(i for i, s in enumerate(run) if s != mr.STATUS_STARTING)
    assert set(run[:first]) <= {mr.STATUS_STARTING} and set(run[first:]) <= {mr.STATUS_ACTIVE, mr.STATUS_SATURATED}
    assert cmds[-1] == mr.STATUS_INACTIVE and set(statuses) <= {mr.STATUS_STARTING, mr.STATUS_ACTIVE,
                                                                 mr.STATUS_SATURATED}
    # a watchdog cycle after the plant ended (a loaded machine stopping the controller late) is a fault
    post = any(s == mr.STATUS_FAULT for s, late in zip(cmds, after) if late)
    assert hil["loop"]["controller"]["faults_entered"] == int(post)


def test_the_command_at_the_limit_reads_at_most_3_deg_on_the_bus(tmp_path: Path) -> None:
    proc = mrsteer("hil", "run", "--scenario", "paper-fig9", "--mz", "10000", "--duration", "0.7", "--out",
                   str(tmp_path), "--json")
    assert proc.returncode == 0, proc.stderr
    hil = json.loads(proc.stdout)
    with (tmp_path / "signals.csv").open() as f:
        angles = [float(r["AuxSteerCmd_Angle"]) for r in csv.DictReader(f) if r["message"] == names.MSG_CMD]
    assert max(abs(a) for a in angles) == pytest.approx(52359e-6, abs=1e-12)  # not 52360e-6 (3.00001 deg)
    assert hil["saturated"] and hil["time_at_limit_s"] > 0.05
    assert hil["peak_aux_steer_deg"] <= 3.0 and f"{hil['peak_aux_steer_deg']:.3f}" == "3.000"
    assert "SATURATED" in {s.ctrl_state for s in read_steps_csv(tmp_path / "steps.csv")}


def test_a_monitor_degraded_run_says_degraded_on_the_wire_and_in_steps_csv(tmp_path: Path) -> None:
    """A lateral acceleration 2 m/s^2 off from 0.6 s, which the yaw rate's second element
    out-votes: the monitor's OUTSIDE_MODEL, DEGRADED in every command from the report on (the
    command fades), in the status and in steps.csv."""
    proc = mrsteer("hil", "run", "--scenario", "paper-fig9", "--duration", "1.2", "--sensor-fault",
                   "lat_accel:bias:2@0.6", "--out", str(tmp_path), "--json")
    assert proc.returncode == 0, proc.stderr
    hil = json.loads(proc.stdout)
    t_report = hil["plausibility"]["first_degraded_s"]
    assert hil["plausibility"]["reported_as"] == "degraded" and 0.6 < t_report < 0.95
    cmds, statuses, after = logged_states(tmp_path / "traffic.log")
    run = [s for s, late in zip(cmds, after) if not late][:-1]
    k = run.index(mr.STATUS_DEGRADED)
    assert set(run[k:]) == {mr.STATUS_DEGRADED} and mr.STATUS_FAULT not in run
    assert statuses[-1] == mr.STATUS_DEGRADED
    steps = read_steps_csv(tmp_path / "steps.csv")
    degraded = [s.t_s for s in steps if s.ctrl_state == "DEGRADED"]
    assert degraded[0] == pytest.approx(t_report, abs=1e-9) and degraded[-1] == steps[-1].t_s
    assert all(s.ctrl_state == "ACTIVE" for s in steps if s.t_s < t_report)
    assert steps[-1].aux_cmd_rad == 0.0  # faded


def test_the_plots_controller_lane_has_a_level_for_every_state() -> None:
    assert hil_plot.lane_levels() == ["STARTING", "INACTIVE", "ACTIVE", "SATURATED", "DEGRADED", "FAULT"]


def test_signals_csv_starts_with_scenario_time_and_keeps_the_logs_microsecond_times(
        lockstep_run: tuple[dict, Path]) -> None:
    hil, out = lockstep_run
    with (out / "signals.csv").open() as f:
        rows = list(csv.DictReader(f))
    # scenario time first: from the plant's first frame, each yaw-rate frame at its step's time
    ts = 1.0 / hil["rate_hz"]
    steps = read_steps_csv(out / "steps.csv")
    yaw = [float(r["t_s"]) for r in rows if r["message"] == names.MSG_YAW]
    first = next(i for i, r in enumerate(rows) if r["message"] not in (names.MSG_CMD, names.MSG_STATUS))
    assert float(rows[first]["t_s"]) == 0.0 and yaw == [s.t_s for s in steps]
    assert all(float(r["t_s"]) < 0.0 for r in rows[:first])  # a controller's frames before the plant's first
    # lockstep: each step's command at its step's time (a watchdog command the controller sent
    # while a slow plant was starting is before its first frame: not one of them)
    answers = [float(r["t_s"]) for r in rows[first:] if r["message"] == names.MSG_CMD][:len(steps)]
    assert answers == [s.t_s for s in steps]
    logged = [line[1:line.index(")")] for line in (out / "traffic.log").read_text().splitlines()]
    written = [r["bus_time_s"] for r in rows]
    assert written == logged and all(re.fullmatch(r"\d+\.\d{6}", t) for t in written)
    times = [float(t) for t in written]
    assert all(b >= a for a, b in zip(times, times[1:]))
    assert len(set(written)) > 0.99 * len(written)  # distinct: not one 8-digit value for every row


def test_demo_overlays_both_runs_and_tells_a_held_wheel_story(tmp_path: Path) -> None:
    proc = mrsteer("hil", "demo", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert "wheel held" in proc.stdout and "takes over" not in proc.stdout
    on, off = (json.loads((tmp_path / run / "summary.json").read_text())
               for run in ("with-controller", "without-controller"))
    cut = round(100 * (1 - on["peak_yaw_rate_rad_s"] / off["peak_yaw_rate_rad_s"]))
    assert f"{cut}% less" in proc.stdout and f"keeps up its {on['final_aux_steer_deg']:.2f} deg" in proc.stdout
    assert (tmp_path / "plot.png").read_bytes()[:8] == PNG
    for run in ("with-controller", "without-controller"):
        assert len(read_steps_csv(tmp_path / run / "steps.csv")) == on["steps"]


def _timing_held(hil: dict) -> bool:
    """Whether a realtime run stayed near the fixed-delay loop the offline comparison assumes: the
    99th percentile of the commands' latency within one and a half periods (a loaded machine's
    jitter; the run that failed had 6.4 ms in a 5 ms loop, and a shared machine 5.1-5.9 ms
    without a failure), no overrun, and never DEGRADED (a sample withheld in a stall makes the
    monitor DEGRADED, which opens the panic window and changes the law's output: that failure)."""
    period = 1.0 / hil["rate_hz"]
    return (hil["latency_p99_s"] < 1.5 * period and hil["loop"]["controller"]["overruns"] == 0
            and hil["loop"]["plant"]["overruns"] == 0 and hil["plausibility"]["first_degraded_s"] is None)


@pytest.mark.slow
@pytest.mark.serial
def test_realtime_matches_within_five_percent(tmp_path: Path) -> None:
    # A gentler tuning that stays stable with the 1-3 samples of delay a free-running
    # Python loop sees (the paper's K=10, tau=6 ms needs exactly one sample at 1 kHz).
    # A starved machine can stall either process for more than a period; such a run measures
    # the machine, not the loop, so it is run again (at most three runs) and reported if none held.
    runs = []
    for attempt in range(3):
        out = tmp_path / f"run{attempt}"
        proc = mrsteer("hil", "run", "--scenario", "paper-fig9", "--mode", "realtime", "--rate-hz", "200", "--k",
                       "3", "--tau", "0.05", "--v", "22", "--mu", "1", "--out", str(out), "--json")
        assert proc.returncode == 0, proc.stderr
        hil = json.loads(proc.stdout)
        runs.append(hil)
        if _timing_held(hil):
            break
    else:
        pytest.skip("no realtime run held its 5 ms timing on this machine: p99 latencies "
                    + ", ".join(f"{r['latency_p99_s'] * 1e3:.1f} ms" for r in runs)
                    + ", DEGRADED at " + ", ".join(str(r["plausibility"]["first_degraded_s"]) for r in runs))
    assert hil["mode"] == "realtime" and hil["delay_steps"] >= 1
    offline = _offline("--mz", "4000", "--v", "22", "--mu", "1", "--ts", "0.005", "--delay-steps",
                       str(hil["delay_steps"]), "--k", "3", "--tau", "0.05")
    _close(hil, offline, rel=0.05)
    assert hil["loop"]["controller"]["cycles"] > 500


def test_without_controller_the_car_yaws_freely(tmp_path: Path) -> None:
    proc = mrsteer("hil", "run", "--controller", "none", "--mode", "lockstep", "--out", str(tmp_path), "--json")
    assert proc.returncode == 0, proc.stderr
    hil = json.loads(proc.stdout)
    offline = _offline("--mz", "4000", "--v", "20", "--mu", "1", "--controller", "none", "--ts", "0.001")
    assert hil["peak_yaw_rate_rad_s"] == pytest.approx(offline["peak_yaw_rate_rad_s"], rel=1e-3)
    assert hil["peak_aux_steer_deg"] == 0.0


def _start(argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, *argv], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=os.environ.copy())


def test_controller_process_faults_on_a_silenced_sensor_and_recovers(channel: str) -> None:
    bus = can.Bus(interface="mrsteer", channel=channel)
    ctl = _start(["-m", "firmware_py", "--interface", "mrsteer", "--channel", channel, "--rate-hz", "200"])
    counters = {n: mrsteer_dbc.AliveCounter() for n in names.VEHICLE_SENSORS}
    seen: list[tuple[float, dict]] = []
    statuses: list[dict] = []
    sent = [0]  # yaw-rate samples: the redundant frame goes with every 10th (its 50 ms at 200 Hz)

    def feed(seconds: float, yaw: bool) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for name, values in ((names.MSG_STEER, {"DriverSteer_Angle": 0.0}),
                                 (names.MSG_SPEED, {"VehicleSpeed_Speed": 20.0}),
                                 (names.MSG_REDUNDANT, {names.SIG_LAT_ACCEL: 0.4 + 0.002 * (sent[0] // 10 % 2),
                                                        names.SIG_STEER_ANGLE_2: 0.0}),
                                 (names.MSG_YAW, {"YawRate_YawRate": 0.02})):
                if (name == names.MSG_YAW and not yaw) or (name == names.MSG_REDUNDANT and sent[0] % 10):
                    continue
                bus.send(can.Message(arbitration_id=C.frame_id(name), data=C.encode(name, values,
                                     counters[name].next()), is_extended_id=False))
            sent[0] += 1
            deadline = time.monotonic() + 0.004
            while (m := bus.recv(max(0.0, deadline - time.monotonic()))) is not None:
                d = C.decode(m.arbitration_id, bytes(m.data))
                if d and d.name == names.MSG_CMD:
                    seen.append((time.monotonic(), d.signals))
                elif d and d.name == names.MSG_STATUS:
                    statuses.append(d.signals)
                if time.monotonic() >= deadline:
                    break

    try:
        feed(1.0, yaw=True)
        healthy = [s for _, s in seen[-20:]]
        assert all(s["AuxSteerCmd_State"] in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED) for s in healthy)
        cut = time.monotonic()
        feed(1.0, yaw=False)
        faulted = [(t, s) for t, s in seen if t > cut and s["AuxSteerCmd_State"] == mr.STATUS_FAULT]
        assert faulted, "no fault after the yaw-rate sensor went quiet"
        assert faulted[0][0] - cut < 0.5  # 10 cycles of 5 ms, plus scheduling slack
        assert any(int(s["CtrlStatus_Cause"]) & names.CAUSE_YAW_MISSING for s in statuses)
        assert seen[-1][1]["AuxSteerCmd_Angle"] == 0.0  # faded out
        back = time.monotonic()
        feed(1.0, yaw=True)
        after = [s for t, s in seen if t > back + 0.2]
        assert after and all(s["AuxSteerCmd_State"] != mr.STATUS_FAULT for s in after)
        assert ctl.poll() is None
    finally:
        ctl.send_signal(signal.SIGTERM)
        code = ctl.wait(20)
        last = None
        while (m := bus.recv(0.5)) is not None:
            d = C.decode(m.arbitration_id, bytes(m.data))
            if d and d.name == names.MSG_CMD:
                last = d.signals
        bus.shutdown()
    assert code == 0
    assert last is not None and last["AuxSteerCmd_Angle"] == 0.0 and last["AuxSteerCmd_State"] == mr.STATUS_INACTIVE


def _children_of(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    return stat.exists() and stat.read_text().split()[2] != "Z"


def test_killing_the_plant_mid_run_stops_everything_and_says_so(tmp_path: Path) -> None:
    runner = subprocess.Popen([sys.executable, "-m", "mrsteer_cli", "hil", "run", "--mode", "realtime",
                               "--rate-hz", "200", "--k", "3", "--tau", "0.05", "--out", str(tmp_path)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                              env=os.environ.copy())
    deadline = time.monotonic() + 60
    plant = None
    kids: list[int] = []
    while plant is None and time.monotonic() < deadline:
        kids = _children_of(runner.pid)
        for pid in kids:
            if Path(f"/proc/{pid}/comm").read_text().strip() == "plant":  # the runner names its nodes
                plant = pid
        time.sleep(0.05)
    assert plant is not None, "the plant never started"
    time.sleep(1.0)
    kids = _children_of(runner.pid)
    os.kill(plant, signal.SIGKILL)
    _, err = runner.communicate(timeout=60)
    assert runner.returncode != 0
    assert "plant" in err and "status" in err
    time.sleep(0.5)
    assert [pid for pid in kids if _alive(pid)] == [], "orphan processes left behind"
    assert not (tmp_path / "summary.json").exists()  # nothing half-written under a final name


def test_bad_scenario_file_is_one_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('duration = 2\n[[events]]\nt = 0.5\nyaw_momnet = 100\n')
    proc = mrsteer("hil", "run", "--scenario", str(bad), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2
    assert "yaw_momnet" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "summary.json").exists()
