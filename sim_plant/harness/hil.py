"""Hardware-in-the-loop runner: plant, controller and bus logger as separate processes.

``run()`` starts (on the fallback bus: a private broker first) the logger, the controller and
the plant, each with the command line ``launch`` builds; waits for the plant to play its
scenario; stops the controller (which sends its final zero command) and the logger; and hands
the log and the plant's per-step trace to ``hil_report``.  If any process dies early the others
are stopped, nothing is left running, and ``HilError`` names the process and its exit status.
Every child gets SIGTERM if this process dies (Linux ``PR_SET_PDEATHSIG``), so even a killed
runner leaves no orphans.

What ``out`` holds afterwards: every output, written whole, of a run that finished; of a run
that failed after frames were logged, only ``traffic.partial.log`` (the frames up to the
failure); of a run that failed before, or was interrupted (Ctrl-C: ``KeyboardInterrupt``
after every process is stopped), nothing new, and no directory the run created.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from mrsteer_dbc import secoc as secoc_mod
from firmware_py.platform import bus_open
from firmware_py.platform.cli import output_dir_problem
from firmware_py.platform.files import make_dirs, remove_empty
from firmware_py import model_regulator as mr
from firmware_py.controller.node import DEFAULT_RATE_HZ
from sim_plant.car import scenario as scn
from sim_plant.car.sensor_faults import parse_spec
from sim_plant.harness.hil_report import TRACE, HilRun, finish
from sim_plant.harness import launch
from sim_plant.harness.processes import Proc, RunError, stop, tail, wait_for_socket, wait_ready, wait_stderr

MODES = ("lockstep", "realtime")


HilError = RunError  # a HIL run failed; the message says which process and how


_DEFAULT = mr.ControllerConfig()


@dataclass(frozen=True)
class HilConfig:
    scenario: str = "paper-fig9"
    mode: str = "lockstep"
    rate_hz: float = DEFAULT_RATE_HZ
    interface: str | None = None
    channel: str | None = None
    v: float | None = None
    mu: float | None = None
    mz: float | None = None
    duration: float | None = None  # s; None: the scenario's
    controller: str = mr.Q_LIMITED  # or "none"
    calibration: mr.ControllerConfig = _DEFAULT  # run at rate_hz (its ts is replaced)
    delay_steps: int = 1
    plant: str | None = None  # the car (``PlantSettings``); None: the scenario's
    actuator: str | None = None
    sensors: str | None = None
    seed: int | None = None
    sensor_faults: tuple[str, ...] = ()  # --sensor-fault specs for the plant (sim_plant.car.sensor_faults)
    out: Path = Path("out/hil")
    secoc_key: bytes | None = None  # authenticate the commands and the sensor frames (mrsteer_dbc.secoc)
    # The controller process: None for the Python one, else an external program that takes the
    # controller's flags (``launch.controller_program``: the C node, or --controller-cmd).
    controller_program: tuple[str, ...] | None = None


def run(cfg: HilConfig, progress: Callable[[str], None] | None = None) -> HilRun:
    say = progress or (lambda m: None)
    if cfg.mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}")
    # The scenario on the chosen car, checked here: a bad choice fails before anything starts.
    sc = scn.load(cfg.scenario).with_overrides(v=cfg.v, mu=cfg.mu, mz=cfg.mz, duration=cfg.duration).with_models(
        cfg.plant, cfg.actuator, cfg.sensors, cfg.seed)
    # ModelFileError, ScenarioError (a fault after the run's end): one line
    sc = sc.with_sensor_faults(tuple(parse_spec(spec) for spec in cfg.sensor_faults))
    ctrl = replace(cfg.calibration, q_form=cfg.controller if cfg.controller != "none" else cfg.calibration.q_form,
                   ts=1.0 / cfg.rate_hz)
    mr.configure(ctrl)  # reject an impossible calibration before starting anything
    if (problem := output_dir_problem("--out", cfg.out)) is not None:
        raise ValueError(problem)
    notices: list[str] = []
    iface, channel = bus_open.resolve(cfg.interface, cfg.channel, notice=notices.append)
    bus_open.check(iface, channel, between_processes=True)  # BusOpenError: no such bus here, before anything
    created = make_dirs(cfg.out)
    for line in notices:
        say(line)
    work = Path(tempfile.mkdtemp(prefix=".hil-", dir=cfg.out))
    procs: list[Proc] = []
    try:
        env = dict(os.environ)
        if cfg.secoc_key is not None:
            # Through the environment, not argv: a command line is visible to every user.
            env[secoc_mod.KEY_ENV] = cfg.secoc_key.hex()
        if iface == bus_open.FALLBACK[0] and cfg.channel is None:
            # A private bus for this run: nothing else on it, and it goes away with the run.
            channel = f"hil-{os.getpid()}-{int(time.time() * 1000) % 100000}"
            procs.append(launch.start("bus broker", launch.broker(channel), work, env, preload=True))
            wait_for_socket(channel, procs[-1])
        bus = launch.BusArgs(iface, channel)
        say(f"bus: {iface} {channel}" if channel else f"bus: {iface}")

        logger = launch.start("logger", launch.logger(bus, launch.LoggerSettings(
            work / "traffic.log", iface_name=str(channel), stats_out=work / "logger.json")), work, env, stdout=True,
            preload=True)
        procs.append(logger)
        wait_ready(logger)

        if cfg.controller != "none":
            procs.append(launch.start("controller", launch.controller(bus, launch.ControllerSettings(
                cfg.rate_hz, launch.write_calibration(work, ctrl),
                trigger="sensors" if cfg.mode == "lockstep" else "clock", q_form=cfg.controller,
                stats_out=work / "controller.json", secoc=cfg.secoc_key is not None,
                program=cfg.controller_program)), work, env, preload=True))
            wait_stderr(procs[-1], "running at")  # bus open, filters set: the first frame will count
        plant = launch.start("plant", launch.plant(bus, launch.PlantSettings(
            cfg.rate_hz, cfg.mode, cfg.scenario, delay_steps=cfg.delay_steps, v=cfg.v, mu=cfg.mu, mz=cfg.mz,
            duration=cfg.duration, plant=cfg.plant, actuator=cfg.actuator, sensors=cfg.sensors, seed=cfg.seed,
            sensor_faults=cfg.sensor_faults, no_controller=cfg.controller == "none", trace_out=work / TRACE, stats_out=work / "plant.json",
            secoc=cfg.secoc_key is not None)), work, env, preload=True)
        procs.append(plant)
        impl = "" if cfg.controller_program is None else f" ({' '.join(cfg.controller_program)})"
        say(f"running {sc.name}: {sc.duration:g} s, {cfg.mode}, {cfg.rate_hz:g} Hz, controller {cfg.controller}{impl}")

        # A hang guard, generous: under QEMU without KVM a lockstep second of Python plant takes ~1-2 min.
        limit = time.monotonic() + max(300.0, 100.0 * sc.duration)
        while plant.popen.poll() is None:
            for p in procs:
                if p is not plant and p.popen.poll() is not None:
                    raise HilError(f"{p.name} exited unexpectedly with status {p.popen.returncode}"
                                   f"{tail(p)} ; stopped the others")
            if time.monotonic() > limit:
                raise HilError("the plant did not finish in time; stopped everything")
            time.sleep(0.05)
        if plant.popen.returncode != 0:
            raise HilError(f"plant exited with status {plant.popen.returncode}{tail(plant)}")
        for p in [p for p in procs if p.name == "controller"] + [logger]:
            stop(p)
            if p.popen.returncode not in (0, -signal.SIGTERM):
                raise HilError(f"{p.name} exited with status {p.popen.returncode}{tail(p)}")
        return finish(cfg, sc, ctrl, work, say)
    except KeyboardInterrupt:
        # Interrupted: nothing of this run is kept.  A second Ctrl-C may not cut the clean-up short.
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            _clean_up(procs, work, created)
        finally:
            signal.signal(signal.SIGINT, previous)
        raise
    except BaseException:
        for p in reversed(procs):  # the logger stopped first: it flushes, the copy is whole
            stop(p)
        partial = work / "traffic.log"
        if partial.exists() and partial.stat().st_size > 0:
            shutil.copy(partial, cfg.out / "traffic.partial.log")
        _clean_up(procs, work, created)
        raise
    finally:
        _clean_up(procs, work, None)


def _clean_up(procs: list[Proc], work: Path, created: list[Path] | None) -> None:
    """Stop every process (the last started first), remove the work directory and, given
    ``created``, each directory the run created that is still empty."""
    for p in reversed(procs):
        stop(p)
    procs.clear()
    shutil.rmtree(work, ignore_errors=True)
    remove_empty(created or [])


