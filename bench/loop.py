"""Loop timing, latency and memory of a controller process on the fallback bus, with the
plant running in real time: the product as users run it, measured from outside.

``loop_timing`` runs one controller (the Python one, or any program that takes its flags, such
as the C node ``ports/c/build/mrs_node``) and reads its ``--stats-out`` (lateness, missed
cycles, memory; the C node writes the same fields) and a latency probe on the bus (the time from
a yaw-rate frame to the command answering it, from the two frames' bus timestamps).
``loop_compare`` puts the Python and the C controller side by side, quiet and loaded."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import can
import numpy as np

import mrsteer_dbc
from mrsteer_dbc import names
from sim_plant.harness import launch

READY_TIMEOUT_S = 60.0
RT_PRIORITY = 50  # the controllers' SCHED_FIFO priority in every loop run
# The plant's and the broker's, with ``harness_rt``: below the controller's, on the other CPUs,
# so that the sensor frames come on time and the figures are the controller's (a real ECU's
# sensors do not wait for a shared CPU).
HARNESS_RT_PRIORITY = 40
BASELINE_NAME = "empty absolute-deadline loop, same rate, bench process, no RT priority"


class _LatencyProbe:
    """A bus client that pairs each yaw-rate frame with the command answering it
    (AuxSteerCmd_MeasCounter) and keeps the time between their bus timestamps: the broker stamps
    a frame when it puts it on the bus, so the probe's own scheduling (a Python thread, on a
    loaded CPU) does not enter the figure."""

    def __init__(self, channel: str) -> None:
        c = mrsteer_dbc.load()
        self.yaw_id, self.cmd_id = c.frame_id(names.MSG_YAW), c.frame_id(names.MSG_CMD)
        self.contract = c
        self.bus = can.Bus(interface="mrsteer", channel=channel,
                           can_filters=[{"can_id": i, "can_mask": 0x7FF, "extended": False}
                                        for i in (self.yaw_id, self.cmd_id)])
        self.latencies: list[float] = []
        self._yaw_at: dict[int, float] = {}
        self._run = True
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        clock = time.time  # the bus stamps' clock, if a frame came without one
        while self._run:
            msg = self.bus.recv(0.1)
            if msg is None:
                continue
            now = msg.timestamp or clock()
            d = self.contract.decode(msg.arbitration_id, bytes(msg.data))
            if d is None or not d.status.accepted:
                continue
            if msg.arbitration_id == self.yaw_id:
                self._yaw_at[d.counter] = now
            else:
                meas = int(d.signals["AuxSteerCmd_MeasCounter"])
                t = self._yaw_at.pop(meas, None)
                if t is not None and now - t < 0.1:
                    self.latencies.append(now - t)

    def stop(self) -> list[float]:
        """End the probe (again: no effect) and give the latencies, in s."""
        if self._run:
            self._run = False
            self.thread.join(5)
            self.bus.shutdown()
        return self.latencies


def _spawn(argv: list[str], err: Path) -> subprocess.Popen:
    return subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err.open("w"))


def _wait_for(path: Path, needle: str, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while needle not in (path.read_text() if path.exists() else ""):
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"benchmark process did not start: {path.read_text()[-500:]}")
        time.sleep(0.05)


def bare_loop_lateness(rate_hz: float, seconds: float) -> dict[str, float]:
    """The baseline: an empty absolute-deadline loop in this process, same rate, same clock.
    What the machine's timer and scheduler alone cost, measured in the same run. A wake-up
    later than a period counts its whole periods as missed and restarts the grid from there,
    as the controllers do."""
    period = 1.0 / rate_hz
    late = []
    missed = 0
    clock = time.monotonic
    deadline = clock()
    end = deadline + seconds
    while True:
        now = clock()
        if now < deadline:
            time.sleep(deadline - now)
            now = clock()
        late.append(now - deadline)
        if now - deadline >= period:
            lost = int((now - deadline) // period)
            missed += lost
            deadline += lost * period
        deadline += period
        if now >= end:
            break
    arr = np.array(late)
    return {"p50_us": float(1e6 * np.median(arr)), "p99_us": float(1e6 * np.percentile(arr, 99)),
            "max_us": float(1e6 * arr.max()), "missed_cycles": missed}


# The empty loop in a fresh process with the controllers' real-time set-up: what any process at
# that priority on that CPU gets from this kernel, with nothing of a controller in it.
_RT_LOOP = ("import json, sys\n"
            "from firmware_py.platform.realtime import apply_platform\n"
            "from mrsteer_bench.loop import bare_loop_lateness\n"
            "cpu = int(sys.argv[4])\n"
            "granted = apply_platform(int(sys.argv[3]), None if cpu < 0 else cpu)\n"
            "print(json.dumps({**bare_loop_lateness(float(sys.argv[1]), float(sys.argv[2])), **granted}))\n")


def realtime_process(pid: int, priority: int, cpus: set[int] | None) -> dict[str, Any]:
    """SCHED_FIFO ``priority`` for every thread of process ``pid`` (threads it starts later
    inherit it) and its CPUs, where permitted; says what was granted.  All or nothing: where
    one thread is refused, those already changed go back to normal priority."""
    changed: list[int] = []
    try:
        for tid in (int(t) for t in os.listdir(f"/proc/{pid}/task")):
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
                changed.append(tid)
                if cpus:
                    os.sched_setaffinity(tid, cpus)
            except ProcessLookupError:
                continue  # the thread ended meanwhile: nothing to set
    except (OSError, ValueError) as exc:
        for tid in changed:
            try:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
            except OSError:
                pass  # gone, or no longer ours to change
        return {"rt_priority": 0, "denied": str(exc)}
    return {"rt_priority": priority, "cpus": sorted(cpus) if cpus else None}


def harness_cpus(pin: bool) -> set[int] | None:
    """The CPUs of the plant and the broker: every one but the pinned controller's."""
    ctl = controller_cpu(pin)
    cpus = set(range(os.cpu_count() or 1)) - ({ctl} if ctl is not None else set())
    return cpus or None


def controller_cpu(pin: bool) -> int | None:
    """The CPU a pinned controller runs on: the last one (the probe is not pinned; the plant and
    the broker, with ``harness_rt``, are on the others: ``harness_cpus``)."""
    ncpu = os.cpu_count() or 1
    return ncpu - 1 if pin and ncpu > 1 else None


def rt_loop_lateness(rate_hz: float, seconds: float, pin: bool = True) -> dict[str, Any]:
    """``bare_loop_lateness`` in a child under the controllers' SCHED_FIFO priority and CPU
    (``RT_PRIORITY``, ``controller_cpu``), with what was granted."""
    cpu = controller_cpu(pin)
    argv = [sys.executable, "-c", _RT_LOOP, repr(rate_hz), repr(seconds), str(RT_PRIORITY),
            str(-1 if cpu is None else cpu)]
    try:
        proc = subprocess.run(argv, capture_output=True, text=True, timeout=seconds + 60.0)
    except subprocess.TimeoutExpired:
        raise RuntimeError("the real-time empty loop did not finish") from None
    if proc.returncode != 0:
        raise RuntimeError(f"the real-time empty loop failed: {proc.stderr.strip()[-300:]}")
    return dict(json.loads(proc.stdout))


def loop_timing(rate_hz: float, seconds: float, pin: bool = True, program: tuple[str, ...] | None = None,
                baseline: bool = True, harness_rt: bool = False) -> dict[str, Any]:
    """Controller (clock trigger) and plant (realtime) for ``seconds`` on a private fallback bus.

    ``program``: the controller process (``launch.controller_program``); None: the Python one.
    ``baseline``: also time an empty deadline loop in this process afterwards (up to 5 s).
    ``harness_rt``: the broker and the plant at ``HARNESS_RT_PRIORITY`` on ``harness_cpus``."""
    harness: dict[str, Any] = {"rt_priority": 0}
    with tempfile.TemporaryDirectory(prefix="mrsteer-bench-") as tmp:
        work = Path(tmp)
        env_channel = f"bench-{os.getpid()}-{int(rate_hz)}-{int(time.time()) % 100000}"
        bus = launch.BusArgs("mrsteer", env_channel)
        procs: list[subprocess.Popen] = []
        probe: _LatencyProbe | None = None
        try:
            broker = _spawn(launch.broker(env_channel).command(), work / "bus.err")
            procs.append(broker)
            _wait_for(work / "bus.err", "serving", broker)
            probe = _LatencyProbe(env_channel)
            # The plant first, sending before the controller's timed window opens: a process
            # start (about a second here, longer on a loaded machine) must not eat the window.
            plant = _spawn(launch.plant(bus, launch.PlantSettings(rate_hz, "realtime", "paper-fig9",
                                                                 duration=seconds + 60.0)).command(), work / "plant.err")
            procs.append(plant)
            _wait_for(work / "plant.err", "realtime", plant)
            if harness_rt:
                granted = [realtime_process(p.pid, HARNESS_RT_PRIORITY, harness_cpus(pin)) for p in (broker, plant)]
                harness = next((g for g in granted if "denied" in g), granted[0])
            ctl = _spawn(launch.controller(bus, launch.ControllerSettings(
                rate_hz, duration=seconds, rt_priority=RT_PRIORITY, cpu=controller_cpu(pin),
                stats_out=work / "ctl.json", program=program)).command(), work / "ctl.err")
            procs.append(ctl)
            if ctl.wait(seconds + 120) != 0:
                raise RuntimeError(f"controller failed: {(work / 'ctl.err').read_text()[-500:]}")
            lat = probe.stop()
            stats = json.loads((work / "ctl.json").read_text())
        finally:
            if probe is not None:
                probe.stop()  # before the broker goes, or its thread dies on a closed bus
            for p in reversed(procs):
                if p.poll() is None:
                    p.send_signal(signal.SIGTERM)
                    try:
                        p.wait(10)
                    except subprocess.TimeoutExpired:
                        p.kill()
    cycles = max(1, stats["cycles"] + stats["missed_cycles"])
    arr = np.array(lat) if lat else np.array([np.nan])
    out = {
        "implementation": stats.get("implementation", "python"),
        "rate_hz": rate_hz, "seconds": seconds, "cycles": stats["cycles"],
        "lateness_p50_us": 1e6 * stats["lateness_p50_s"], "lateness_p99_us": 1e6 * stats["lateness_p99_s"],
        "lateness_max_us": 1e6 * stats["lateness_max_s"], "missed_cycles": stats["missed_cycles"],
        "missed_percent": 100.0 * stats["missed_cycles"] / cycles,
        "latency_p50_us": float(1e6 * np.median(arr)), "latency_p99_us": float(1e6 * np.percentile(arr, 99)),
        "latency_samples": len(lat),
        "rss_kb": stats["rss_kb_loop_end"], "rss_growth_kb": stats["rss_kb_growth"],
        "rt_priority": stats.get("rt_priority"), "rt_priority_denied": stats.get("rt_priority_denied"),
        "cpu_affinity": stats.get("cpu_affinity"), "gc_disabled_in_loop": stats.get("gc_disabled_in_loop"),
        "harness": harness,
    }
    if baseline:
        base = bare_loop_lateness(rate_hz, min(seconds, 5.0))
        out.update({"baseline_lateness_p50_us": base["p50_us"], "baseline_lateness_p99_us": base["p99_us"],
                    "baseline_lateness_max_us": base["max_us"], "baseline_name": BASELINE_NAME})
    return out
