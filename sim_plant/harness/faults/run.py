"""Running the fault matrix: each row's processes on two buses joined by the fault bridge,
the kill or restart it asks for, then its verdict (``judge``).

Every node is forked from this process (``processes.spawn_preloaded``): a row starts five or
more, and a fresh interpreter each time is too slow on a slow machine.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

from mrsteer_dbc.secoc import KEY_ENV as SECOC_KEY_ENV
from sim_plant.harness import launch
from sim_plant.harness.faults.verdicts import RowResult, judge
from sim_plant.nodes.fault_bridge import Fault
from sim_plant.harness.faults.rows import ROWS, Row, plant_fault
from sim_plant.harness.faults.settings import (ACTUATOR_RATE, DRAIN_TIMEOUT, DURATION, KILL_AT, RATE_HZ,
                                               RATE_LIMIT, RESTART_AT, Setup, scenario_spec)
from sim_plant.harness.processes import Proc, RunError, stop, wait_for_socket, wait_ready, wait_stderr


@dataclass
class _RowRun:
    """One row's processes, all stopped when the row ends."""

    row: Row
    work: Path
    setup: Setup
    vehicle: str  # the two channels
    controller_side: str
    env: dict[str, str]
    procs: list[Proc] = field(default_factory=list)

    def start(self, name: str, what: launch.Launch, stdout: bool = False) -> Proc:
        p = launch.start(name, what, self.work, self.env, stdout=stdout, preload=True)
        self.procs.append(p)
        return p

    def start_buses(self) -> list[Proc]:
        """The brokers (private fallback buses only), the loggers, then the bridge: it must see
        every frame the controller ever sends.  Returns the bridge and the loggers, which are
        given time to drain at the end."""
        for ch in (self.vehicle, self.controller_side) if self.setup.channels is None else ():
            wait_for_socket(ch, self.start(f"broker {ch}", launch.broker(ch)))
        loggers = []
        for side, ch in (("vehicle", self.vehicle), ("controller", self.controller_side)):
            lg = self.start(f"logger {side}", launch.logger(launch.BusArgs(self.setup.interface, ch), launch.LoggerSettings(
                self.work / f"{side}.log", iface_name=side, stats_out=self.work / f"logger-{side}.json")), stdout=True)
            loggers.append(lg)
            wait_ready(lg)
        bridge = self.start("bridge", launch.bridge(self.setup.interface, self.vehicle, self.controller_side,
                                                    bridge_fault(self.row, self.setup), self.work / "bridge.json"))
        wait_stderr(bridge, "bridging")
        return [bridge, *loggers]

    def start_controller(self, name: str) -> Proc:
        return self.start(name, launch.controller(
            launch.BusArgs(self.setup.interface, self.controller_side),
            # The rows' rate limit in the calibration file itself: controller.cfg is then what the
            # controller ran with, and replays the row's log (``mrsteer replay --recorded-calibration``).
            launch.ControllerSettings(self.setup.rate_hz,
                                      launch.write_calibration(self.work,
                                                               replace(self.setup.calibration(), rate_limit=RATE_LIMIT)),
                                      stats_out=self.work / "controller.json", secoc=self.row.secoc,
                                      program=self.setup.controller_program, slow_motion=self.setup.slow_motion)))

    def start_plant(self, name: str, seconds: float) -> Proc:
        # A killed plant writes nothing: its statistics and trace are the next one's files.
        spec = scenario_spec(self.row.scenario, self.work, plant_fault(self.row))
        return self.start(name, launch.plant(launch.BusArgs(self.setup.interface, self.vehicle), launch.PlantSettings(
            self.setup.rate_hz, "realtime", spec, duration=seconds, actuator_rate=ACTUATOR_RATE,
            cmd_timeout=self.setup.cmd_timeout, plant=self.setup.plant, actuator=self.setup.actuator,
            sensors=self.setup.sensors, trace_out=self.work / "trace.csv",
            stats_out=self.work / "plant.json", secoc=self.row.secoc, slow_motion=self.setup.slow_motion)))

    def play(self, ctl: Proc, plant: Proc, duration: float) -> tuple[Proc, float | None, float | None]:
        """Wait for the plant to finish, killing and restarting what the row says on the way:
        the controller now running, and when the victim was killed and restarted (epoch s)."""
        row, scale = self.row, self.setup.time_scale * self.setup.slow_motion  # wall s per scenario s
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
                    ctl = self.start_controller("controller-2")
                    restarted = time.time()
                elif row.kill_plant:
                    plant = self.start_plant("plant-2", (DURATION - RESTART_AT) * self.setup.time_scale
                                             + self.setup.startup_s)
                    restarted = time.time()
            if time.monotonic() - start > 120 + 2 * duration * self.setup.slow_motion:
                raise RunError("the plant did not finish in time")
            time.sleep(0.01)
        return ctl, killed_at, restarted


def bridge_fault(row: Row, setup: Setup) -> Fault:
    """The row's fault as the bridge is to inject it, in wall time: its window stretched by the
    time scale (a sensor row's start is a point of the car's motion, which the time scale does
    not stretch) and everything timed stretched by the slow motion (the window, a delay; a
    flood's rate and a drift's slope slowed); a substitution as deep as the same age at the
    matrix's rate.  A fault the plant injects leaves the bridge only forwarding."""
    f, slow = row.fault, setup.slow_motion
    start = f.start * (1.0 if row.plausibility else setup.time_scale)
    fault = replace(f, start=start * slow, stop=f.stop * setup.time_scale * slow)
    if f.kind == "delay":
        fault = replace(fault, param=f.param * slow)
    elif f.kind == "substitute":
        # The rows give a substitution's depth in frames at the shipped rate (150: 0.3 s, and a
        # multiple of the alive counter's 15): the same age at the matrix's rate.
        fault = replace(fault, param=round(f.param * setup.rate_hz / RATE_HZ))
    elif f.kind in ("flood", "sensor_drift"):
        fault = replace(fault, param=f.param / slow)
    if row.at_plant:
        fault = replace(fault, kind="none", signal=None)
    return fault


def run_row(row: Row, work: Path, say: Callable[[str], None], setup: Setup = Setup()) -> RowResult:
    env = dict(os.environ)
    duration = (row.duration or DURATION) * setup.time_scale + (setup.startup_s if row.restart else 0.0)
    if setup.channels is None:
        tag = f"f{os.getpid()}-{int(time.time() * 1000) % 10**7}"
        ch_a, ch_b = f"{tag}-veh", f"{tag}-ctl"
    else:
        ch_a, ch_b = setup.channels
    if row.secoc:
        env[SECOC_KEY_ENV] = os.urandom(16).hex()
    run = _RowRun(row, work, setup, ch_a, ch_b, env)
    try:
        drained = run.start_buses()
        ctl = run.start_controller("controller")
        wait_stderr(ctl, "running at")
        plant = run.start_plant("plant", duration)
        wait_stderr(plant, "realtime) on")  # started: kill and restart times count from here
        ctl, killed_at, restarted = run.play(ctl, plant, duration)
        ctl_code = None
        if ctl.popen.poll() is None:
            stop(ctl)
            ctl_code = ctl.popen.returncode
        for p in drained:
            stop(p, timeout=DRAIN_TIMEOUT)
    finally:
        for p in reversed(run.procs):
            stop(p)
    return judge(row, work, ctl_code, killed_at, restarted, setup)


def holds_files(keep: Path | None) -> bool:
    """A --keep directory must start empty: an earlier run's statistics would be judged as this run's."""
    return keep is not None and keep.is_dir() and any(keep.iterdir())


def run_matrix(rows: tuple[Row, ...] = ROWS, say: Callable[[str], None] | None = None,
               keep: Path | None = None, setup: Setup = Setup()) -> list[RowResult]:
    say = say or (lambda m: None)
    if holds_files(keep):
        raise RunError(f"{keep} is not empty: an earlier run's files would be judged as this run's")
    results = []
    with tempfile.TemporaryDirectory(prefix="mrsteer-faults-") as tmp:
        for i, row in enumerate(rows, 1):
            work = (keep or Path(tmp)) / f"{i:02d}"
            work.mkdir(parents=True, exist_ok=True)
            say(f"[{i}/{len(rows)}] {row.name}")
            try:
                results.append(run_row(row, work, say, setup))
            except KeyboardInterrupt:
                # Interrupted: the row's processes are stopped (run_row); its files are half a
                # row's and go, the rows before it stay in ``keep``, each whole.
                shutil.rmtree(work, ignore_errors=True)
                raise
    return results
