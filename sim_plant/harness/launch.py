"""How every node of a supervised run is started: its entry point and its command line.

Each node kind (bus broker, logger, controller, plant, fault bridge) has a ``NodeSpec``: the
module a user runs with ``python -m`` and the ``module:function`` a forked child calls (see
``processes``).  ``broker``, ``logger``, ``controller``, ``plant`` and ``bridge`` turn typed
settings into a ``Launch``, the node and its arguments, which ``start`` runs either way.  The
HIL runner, the fault matrix and the loop benchmark all build their command lines here, so a
node's flags are spelled in one place (besides the node's own parser).
"""

from __future__ import annotations

import json
import sys
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
    """A node and its arguments."""

    node: NodeSpec
    argv: tuple[str, ...]

    def command(self) -> list[str]:
        """The command line of a fresh interpreter running the node."""
        return [sys.executable, "-m", self.node.module, *self.argv]


def start(name: str, launch: Launch, work: Path, env: dict[str, str], *, stdout: bool = False,
          preload: bool = False) -> Proc:
    """Run ``launch`` as the supervised process ``name``: a fresh interpreter, or (``preload``)
    a child forked from this process (``processes.spawn_preloaded``)."""
    if preload:
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


def controller(bus: BusArgs, s: ControllerSettings) -> Launch:
    gains = [] if s.calibration is None else ["--calibration", str(s.calibration)]
    return Launch(CONTROLLER, (
        *bus.argv(), "--rate-hz", _num(s.rate_hz), *_opt("--trigger", s.trigger), *_opt("--controller", s.q_form),
        *gains, *_opt("--rate-limit", s.rate_limit), *_opt("--duration", s.duration),
        *_opt("--rt-priority", s.rt_priority), *_opt("--cpu", s.cpu), *_opt("--stats-out", s.stats_out),
        *_flag("--secoc", s.secoc)))


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
    no_controller: bool = False
    trace_out: Path | None = None  # the true state of every step, as CSV
    stats_out: Path | None = None
    secoc: bool = False


def plant(bus: BusArgs, s: PlantSettings) -> Launch:
    return Launch(PLANT, (
        *bus.argv(), "--scenario", s.scenario, "--mode", s.mode, "--rate-hz", _num(s.rate_hz),
        *_opt("--delay-steps", s.delay_steps), *_opt("--duration", s.duration),
        *_opt("--actuator-rate", s.actuator_rate), *_opt("--cmd-timeout", s.cmd_timeout),
        *_opt("--v", s.v), *_opt("--mu", s.mu), *_opt("--mz", s.mz), *_opt("--plant", s.plant),
        *_opt("--actuator", s.actuator), *_opt("--sensors", s.sensors), *_opt("--seed", s.seed),
        *_flag("--no-controller", s.no_controller), *_opt("--trace-out", s.trace_out),
        *_opt("--stats-out", s.stats_out), *_flag("--secoc", s.secoc)))


def bridge(interface: str, vehicle: str, controller_side: str, fault: Fault, stats_out: Path | None = None) -> Launch:
    return Launch(BRIDGE, ("--interface", interface, "--vehicle", vehicle, "--controller", controller_side,
                           "--fault", json.dumps(asdict(fault)), *_opt("--stats-out", stats_out)))
