"""How every node of a supervised run is started: its entry point and its command line.

Each node kind (bus broker, logger, controller, plant, fault bridge) has a ``NodeSpec``: the
module a user runs with ``python -m`` and the ``module:function`` a forked child calls (see
``processes``).  ``broker``, ``logger``, ``controller``, ``plant`` and ``bridge`` turn typed
settings into a ``Launch``, the node and its arguments, which ``start`` runs either way.  The
HIL runner, the fault matrix and the loop benchmark all build their command lines here, so a
node's flags are spelled in one place (besides the node's own parser).

The controller need not be the Python one: ``ControllerSettings.program`` names any process that
speaks the DBC and takes the controller's flags (``--controller-cmd``); ``controller_program``
gives the one a ``--controller-impl`` choice means (``c``: ``ports/c/build/mrs_node``, built
first with ``make -C ports/c node``).
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import json
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

from firmware_py import calibration_file
from firmware_py.calibration import ControllerConfig
from sim_plant.harness.processes import Proc, spawn, spawn_preloaded
from sim_plant.nodes.fault_bridge import Fault


@dataclass(frozen=True)
class NodeSpec:
    """Where a node's code is: ``module`` for ``python -m``, ``entry`` (``module:function``,
    called with the argument list) for a child forked from a supervisor that imported it."""

    module: str
    entry: str


# The controller and the plant run as ``python -m firmware_py`` and ``python -m sim_plant``,
# the commands the README gives; their mains live deeper.
BROKER = NodeSpec("firmware_py.platform.fallback_broker", "firmware_py.platform.fallback_broker:main")
LOGGER = NodeSpec("sim_plant.nodes.logger", "sim_plant.nodes.logger:main")
CONTROLLER = NodeSpec("firmware_py", "firmware_py.controller.main:main")
PLANT = NodeSpec("sim_plant", "sim_plant.nodes.plant:main")
BRIDGE = NodeSpec("sim_plant.nodes.fault_bridge", "sim_plant.nodes.fault_bridge:main")


@dataclass(frozen=True)
class Launch:
    """A node and its arguments; ``program``, when given, is an external executable (and its
    leading arguments) that runs instead of the Python node, with the same arguments."""

    node: NodeSpec
    argv: tuple[str, ...]
    program: tuple[str, ...] | None = None

    def command(self) -> list[str]:
        """The command line of a fresh process running the node."""
        if self.program is not None:
            return [*self.program, *self.argv]
        return [sys.executable, "-m", self.node.module, *self.argv]


CONTROLLER_IMPLS = ("python", "c")
PORT_DIR = Path(__file__).resolve().parents[2] / "ports" / "c"
C_NODE = PORT_DIR / "build" / "mrs_node"


class LaunchError(RuntimeError):
    """A controller program cannot be had (the C node does not build, a command is empty)."""


# In the temporary directory, not the tree: the tree may be read-only (the real-SocketCAN VM
# shares it so; the node, built on the host, is up to date there and make writes nothing).
MAKE_LOCK = Path(tempfile.gettempdir()) / f"mrsteer-make-{hashlib.sha256(bytes(PORT_DIR)).hexdigest()[:16]}.lock"


def make_port(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``make -s -C ports/c ARGS``, one at a time across processes (an flock on ``MAKE_LOCK``, one
    per tree): two builds in one tree at once (parallel test workers, two runs) write the same files."""
    with MAKE_LOCK.open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return subprocess.run(["make", "-s", "-C", str(PORT_DIR), *args], capture_output=True, text=True,
                              timeout=timeout)


def build_c_node() -> Path:
    """``make -C ports/c node`` (quick when up to date): the C node's path."""
    try:
        proc = make_port("node", f"PYTHON={sys.executable}")
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise LaunchError(f"cannot build the C node: {exc}") from None
    if proc.returncode != 0 or not C_NODE.exists():
        last = (proc.stderr.strip().splitlines() or ["make failed"])[-1]
        raise LaunchError(f"cannot build the C node (make -C ports/c node): {last}")
    return C_NODE


def controller_program(impl: str = "python", command: str | None = None) -> tuple[str, ...] | None:
    """The controller program of ``--controller-impl impl`` / ``--controller-cmd command``: None for
    the Python controller, the C node (built) for ``c``, the split command line otherwise."""
    if command is not None:
        try:
            argv = tuple(shlex.split(command))
        except ValueError as exc:  # an unclosed quote
            raise LaunchError(f"--controller-cmd {command!r}: {exc}") from None
        if not argv:
            raise LaunchError("--controller-cmd is empty")
        return argv
    if impl == "c":
        return (str(build_c_node()),)
    if impl != "python":
        raise LaunchError(f"--controller-impl must be one of {', '.join(CONTROLLER_IMPLS)}, got {impl!r}")
    return None


def add_controller_impl_args(p: argparse.ArgumentParser) -> None:
    """--controller-impl and --controller-cmd, for every command that starts a controller."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--controller-impl", choices=CONTROLLER_IMPLS, default="python",
                   help="the controller process: python (mrsteer controller, default) or c (ports/c's mrs_node, "
                   "built with make -C ports/c node first)")
    g.add_argument("--controller-cmd", metavar="CMD",
                   help="run this command as the controller instead (split as a shell would, no shell): any "
                   "process that speaks the DBC, takes the flags of `mrsteer controller` appended to CMD and "
                   "prints a line containing 'running at' on stderr once its receive filters are set")


def program_of(args: argparse.Namespace) -> tuple[str, ...] | None:
    """The controller program those options ask for (``controller_program``); LaunchError if none,
    or if the command names no program here (refused before anything starts)."""
    program = controller_program(args.controller_impl, args.controller_cmd)
    if program is not None and shutil.which(program[0]) is None:
        raise LaunchError(f"--controller-cmd: {program[0]}: no such program (or not executable)")
    return program


def start(name: str, launch: Launch, work: Path, env: dict[str, str], *, stdout: bool = False,
          preload: bool = False) -> Proc:
    """Run ``launch`` as the supervised process ``name``: a fresh interpreter, or (``preload``)
    a child forked from this process (``processes.spawn_preloaded``); an external program is
    always executed."""
    if preload and launch.program is None:
        return spawn_preloaded(name, launch.node.entry, list(launch.argv), work, env, stdout=stdout)
    return spawn(name, launch.command(), work, env, stdout=stdout)


@dataclass(frozen=True)
class BusArgs:
    """The bus a node opens: a python-can interface and, unless its default, a channel."""

    interface: str
    channel: str | None = None

    def argv(self) -> list[str]:
        return ["--interface", self.interface] + (["--channel", self.channel] if self.channel else [])


def _num(value: float) -> str:
    return repr(float(value))  # repr: every digit, so the node gets exactly this float


def _slow_motion(factor: float) -> list[str]:
    """``--slow-motion F``, left off at real time: an external controller need not know the flag."""
    return _opt("--slow-motion", None if factor == 1.0 else factor)


def _opt(flag: str, value: float | int | str | Path | None) -> list[str]:
    """``flag value``, or nothing for ``None``; a float in full, an int (a count) as one."""
    if value is None:
        return []
    if isinstance(value, float):
        return [flag, _num(value)]
    return [flag, str(value)]


def _flag(flag: str, on: bool) -> list[str]:
    return [flag] if on else []


def broker(channel: str) -> Launch:
    return Launch(BROKER, ("--channel", channel))


@dataclass(frozen=True)
class LoggerSettings:
    out: Path
    iface_name: str | None = None  # written in the log instead of the channel
    stats_out: Path | None = None


def logger(bus: BusArgs, s: LoggerSettings) -> Launch:
    return Launch(LOGGER, (*bus.argv(), "--out", str(s.out), *_opt("--iface-name", s.iface_name),
                           *_opt("--stats-out", s.stats_out)))


def write_calibration(work: Path, cfg: ControllerConfig, name: str = "controller.cfg") -> Path:
    """The calibration as the file a controller process reads (``--calibration``)."""
    path = work / name
    path.write_text(calibration_file.dumps(cfg))
    return path


@dataclass(frozen=True)
class ControllerSettings:
    """The controller's flags; ``None`` leaves the node's default."""

    rate_hz: float
    calibration: Path | None = None  # a .cfg file (``write_calibration``); None: the shipped one
    trigger: str | None = None  # "sensors" (lockstep) or "clock"
    q_form: str | None = None  # --controller
    rate_limit: float | None = None  # rad/s
    duration: float | None = None  # s
    rt_priority: int | None = None
    cpu: int | None = None
    stats_out: Path | None = None
    secoc: bool = False  # the key comes through the environment, never argv
    program: tuple[str, ...] | None = None  # an external controller (``controller_program``); None: Python
    slow_motion: float = 1.0  # wall time per period over the period (a slow machine)


def controller(bus: BusArgs, s: ControllerSettings) -> Launch:
    gains = [] if s.calibration is None else ["--calibration", str(s.calibration)]
    return Launch(CONTROLLER, (
        *bus.argv(), "--rate-hz", _num(s.rate_hz), *_opt("--trigger", s.trigger), *_opt("--controller", s.q_form),
        *gains, *_opt("--rate-limit", s.rate_limit), *_opt("--duration", s.duration),
        *_opt("--rt-priority", s.rt_priority), *_opt("--cpu", s.cpu), *_opt("--stats-out", s.stats_out),
        *_slow_motion(s.slow_motion), *_flag("--secoc", s.secoc)), s.program)


@dataclass(frozen=True)
class PlantSettings:
    """The plant's flags; ``None`` leaves the node's default."""

    rate_hz: float
    mode: str  # "lockstep" or "realtime"
    scenario: str = "paper-fig9"
    duration: float | None = None  # s; default: the scenario's
    delay_steps: int | None = None
    actuator_rate: float | None = None  # rad/s
    cmd_timeout: float | None = None  # s
    v: float | None = None
    mu: float | None = None
    mz: float | None = None
    plant: str | None = None  # "linear" or "nonlinear"; default: the scenario's
    actuator: str | None = None  # ideal, default or a TOML file; default: the scenario's
    sensors: str | None = None  # ideal, default or a TOML file; default: the scenario's
    seed: int | None = None  # the sensors' noise seed; default: the scenario's
    sensor_faults: tuple[str, ...] = ()  # --sensor-fault specs (sim_plant.car.sensor_faults.parse_spec)
    no_controller: bool = False
    trace_out: Path | None = None  # the true state of every step, as CSV
    stats_out: Path | None = None
    secoc: bool = False
    slow_motion: float = 1.0  # realtime: wall time per step over the step (a slow machine)


def plant(bus: BusArgs, s: PlantSettings) -> Launch:
    return Launch(PLANT, (
        *bus.argv(), "--scenario", s.scenario, "--mode", s.mode, "--rate-hz", _num(s.rate_hz),
        *_opt("--delay-steps", s.delay_steps), *_opt("--duration", s.duration),
        *_opt("--actuator-rate", s.actuator_rate), *_opt("--cmd-timeout", s.cmd_timeout),
        *_opt("--v", s.v), *_opt("--mu", s.mu), *_opt("--mz", s.mz), *_opt("--plant", s.plant),
        *_opt("--actuator", s.actuator), *_opt("--sensors", s.sensors), *_opt("--seed", s.seed),
        *(arg for spec in s.sensor_faults for arg in ("--sensor-fault", spec)),
        *_flag("--no-controller", s.no_controller), *_opt("--trace-out", s.trace_out),
        *_opt("--stats-out", s.stats_out), *_slow_motion(s.slow_motion), *_flag("--secoc", s.secoc)))


def bridge(interface: str, vehicle: str, controller_side: str, fault: Fault, stats_out: Path | None = None) -> Launch:
    return Launch(BRIDGE, ("--interface", interface, "--vehicle", vehicle, "--controller", controller_side,
                           "--fault", json.dumps(asdict(fault)), *_opt("--stats-out", stats_out)))
