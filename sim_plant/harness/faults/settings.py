"""The fault matrix's numbers and where it runs (``Setup``): its rate and the calibration tuned
for it, the scenario's timing, the limits its verdicts hold the run to, and the constants
copied from the plant and the controller."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.authority import AuthorityConfig
from firmware_py.controller import node as rt
from firmware_py.calibration import RATE_CALIBRATIONS
from firmware_py.controller.node import DEFAULT_RATE_HZ
from firmware_py.controller.options import calibration_for_rate
from firmware_py.platform.cli import slow_motion_problem
from mrsteer_dbc.busload import frame_bits
from mrsteer_dbc import names
from sim_plant.car import scenario
from sim_plant.car.actuator import CMD_TIMEOUT_S, FADE_RATE_RAD_S
from sim_plant.car.actuator_dynamics import ActuatorModelConfig
from sim_plant.car.plants import LINEAR
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import SensorConfig

RATE_HZ = DEFAULT_RATE_HZ
RATE_LIMIT = math.radians(40.0)  # rad/s, the controller's command rate limit in these runs
CUT_RATE = AuthorityConfig().rate_max  # rad/s: the limiter removing a command on a pair check's fault
PLANT_FADE = FADE_RATE_RAD_S  # rad/s, the actuator's fade (the plant's default)
CMD_TIMEOUT = CMD_TIMEOUT_S  # s, the actuator's command timeout (the plant's default)
SCENARIO = "paper-fig9"  # the plant's scenario in every row but the curve rows (CURVE)
DURATION = 2.6  # s of scenario
WINDOW = (1.0, 1.4)  # s after the first frame: the fault window
BUS_RESOLUTION = 1e-6  # rad, AuxSteerCmd_Angle's scale in the DBC
TRACE_RESOLUTION = 1e-8  # rad: angles up to 0.06 rad written with 9 significant digits
ACTUATOR_RATE = math.radians(60.0)  # rad/s, the actuator's own slew limit in these runs
DRAIN_TIMEOUT = 60.0  # s for bridge and loggers to work off a backlog (a slow machine lags) and exit
KILL_AT = 1.2  # s after the plant started
RESTART_AT = 1.7
TIMEOUT_CYCLES = rt.RuntimeConfig().timeout_cycles
E2E_FAIL_MAX = rt.RuntimeConfig().e2e_fail_max
# The forger's angle: the DBC maximum, just beyond the controller's 3 deg limit, so a forgery the
# actuator took is told apart from every real command.
FORGED_ANGLE = mrsteer_dbc.load().signal_range(names.MSG_CMD, "AuxSteerCmd_Angle")[1]
MAC_LUCK = 2
COUNTER_WINDOW = mrsteer_dbc.E2EReceiver().max_delta  # the actuator's alive-counter window
# 8-byte frames a 500 kbit/s bus carries per second at most (no stuff bits): a flood at this
# rate saturates a real bus of the vehicle's kind.
FLOOD_CAPACITY = 500e3 / frame_bits(8, worst_case=False)

# Sensor-fault rows (a wrong value in well-formed frames, found by the plausibility monitor).
PLAUS_DETECT = 0.3  # s from the error exceeding its bound to the fault on the bus (issue 18's target)
PLAUS_FADE = AuthorityConfig().fault_fade_rate  # rad/s, the authority limiter's fade on a plausibility fault
STATUS_CYCLE = mrsteer_dbc.load().cycle_time_s(names.MSG_STATUS) or 0.1  # s, MRS_CtrlStatus
PLAUS_START = 1.0  # s: the paper-fig9 car is in its steady state (r 0.020 rad/s, aux -1.81 deg)
PLAUS_DURATION = 2.6  # s of scenario: detection (<= 0.3 s), a fade from 3 deg (0.1 s) and its latch fit after 1.0 s
#: The second scenario of the sensor rows: the paper's car at 20 m/s on mu 1, the driver turning
#: the wheel at a steady rate to 1.5 deg of front-wheel angle over 0.4 s from 0.5 s, then holding
#: it (the issue's "driver steers 1.5 deg into a curve": r 0.168 rad/s, a_y 3.4 m/s^2 from 1.4 s).
#: Faults that paper-fig9 hides need it: its driver holds the wheel straight (a steering angle
#: stuck at 0 is then the truth) and its yaw rate (0.02 rad/s) is too small for a gain error to
#: leave the monitor's bound.
CURVE = "curve"
CURVE_ANGLE = math.radians(1.5)
CURVE_STEPS = 40  # one steer event every 10 ms
CURVE_SCENARIO = scenario.Scenario(
    CURVE, 4.0, v=20.0, mu=1.0, description="driver steers 1.5 deg into a curve at 20 m/s (fault matrix)",
    events=tuple(scenario.Event(round(0.5 + 0.01 * i, 2), "steer", CURVE_ANGLE * (i + 1) / CURVE_STEPS)
                 for i in range(CURVE_STEPS)))


def scenario_toml(sc: scenario.Scenario, faults: tuple[SensorFault, ...] = ()) -> str:
    """``sc`` with ``faults`` as a scenario file (``sim_plant.car.scenario``'s format), for the
    plant's ``--scenario``.  Only what the matrix's scenarios use: the paper's ideal car, the
    wheel held, scalar events; anything else is refused rather than written wrong."""
    if (sc.plant != LINEAR or sc.driver.mode != "hold" or sc.actuator != ActuatorModelConfig.ideal()
            or sc.sensors != SensorConfig.ideal() or sc.sensor_faults or any(ev.load is not None for ev in sc.events)):
        raise ValueError(f"scenario {sc.name!r} is not one the fault matrix can write as a file")
    lines = [f"name = {json.dumps(sc.name)}", f"description = {json.dumps(sc.description)}",
             f"duration = {sc.duration!r}", f"v = {sc.v!r}", f"mu = {sc.mu!r}", f"mass = {sc.mass!r}"]
    for ev in sc.events:
        lines += ["", "[[events]]", f"t = {ev.t!r}", f"{ev.kind} = {ev.value!r}"]
    for f in faults:
        lines += ["", "[[sensor_fault]]", f"sensor = {json.dumps(f.sensor)}", f"kind = {json.dumps(f.kind)}",
                  f"start = {f.start!r}"]
        lines += [f"value = {f.value!r}"] if f.value is not None else []
        lines += [f"stop = {f.stop!r}"] if math.isfinite(f.stop) else []
    return "\n".join(lines) + "\n"


def row_scenario(name: str) -> scenario.Scenario:
    """The scenario a row names: the matrix's own curve, or a built-in."""
    return CURVE_SCENARIO if name == CURVE else scenario.load(name)


def scenario_spec(name: str, work: Path, fault: SensorFault | None = None) -> str:
    """What the plant's ``--scenario`` takes for a row: a built-in name as it is, or (the curve,
    or any scenario with a sensor fault for the plant to inject) a file written into ``work``."""
    if name != CURVE and fault is None:
        return name
    sc = row_scenario(name)
    path = work / "scenario.toml"
    path.write_text(scenario_toml(sc, () if fault is None else (fault,)))
    return str(path)


# The calibration of each rate the matrix runs at (the shipped one at 500 Hz, the tuned ones
# at the rates a VM needs): the firmware's table, which every command's --rate-hz goes by.
CALIBRATIONS: dict[float, mr.ControllerConfig] = RATE_CALIBRATIONS


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
    # The car the plant plays (``--plant``, ``--actuator``, ``--sensors``); None: the scenario's
    # (paper-fig9: the paper's ideal car).
    plant: str | None = None
    actuator: str | None = None
    sensors: str | None = None
    # The controller process (``launch.controller_program``): None for the Python one, else the C
    # node or any external program that takes the controller's flags.
    controller_program: tuple[str, ...] | None = None
    # Wall time per period over the period, for every node of a row (plant, controller, the
    # bridge's delays, flood and window, the kill and restart times): a machine too slow for
    # the loop (QEMU without KVM) runs the same car and law in slow motion.  The evidence is
    # read back in the car's time, so every verdict and limit is unchanged.
    slow_motion: float = 1.0

    def __post_init__(self) -> None:
        calibration_for_rate(self.rate_hz, file_flag=None)  # RateError, in every command's words
        if not (math.isfinite(self.time_scale) and 1.0 <= self.time_scale <= 20.0):
            raise ValueError(f"time scale must be in [1, 20], got {self.time_scale:g}")
        if (problem := slow_motion_problem(self.slow_motion)) is not None:
            raise ValueError(problem)
        if not (math.isfinite(self.startup_s) and 0.0 <= self.startup_s <= 120.0):
            raise ValueError(f"start-up allowance must be in [0, 120] s, got {self.startup_s:g}")
        if self.channels is not None and (len(self.channels) != 2 or self.channels[0] == self.channels[1]):
            raise ValueError("give two different channels: vehicle side, controller side")
        if self.channels is None and self.interface != "mrsteer":
            raise ValueError(f"--interface {self.interface} needs --channels VEHICLE,CONTROLLER")
        scenario.load(SCENARIO).with_models(self.plant, self.actuator, self.sensors)  # a bad choice: one line

    @property
    def ts(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def cmd_timeout(self) -> float:
        """The actuator's command timeout: the plant's 20 ms, and never under 4 control periods."""
        return max(CMD_TIMEOUT, 4.0 * self.ts)

    def settling(self, angle: float) -> tuple[float, float]:
        """(tolerance in rad, seconds) within which the actuator's *position* reaches zero after
        the command it follows is zero, from ``angle``: 0 and exactly 0 for the ideal actuator
        (it applies the command itself); for a lagging one, its dead time plus the time its
        slowest mode takes from ``angle`` to the DBC's command resolution (docs/faults.md)."""
        cfg = self.actuator_model()
        if cfg.order == 0 and cfg.dead_time_samples == 0:
            return 0.0, 0.0
        dead = cfg.dead_time_samples * self.ts
        if cfg.order == 0:
            return BUS_RESOLUTION, dead
        tau = cfg.time_constant_s if cfg.order == 1 else 1.0 / (
            min(cfg.damping, 1.0) * 2.0 * math.pi * cfg.natural_frequency_hz)
        return BUS_RESOLUTION, dead + tau * math.log(max(abs(angle), BUS_RESOLUTION) / BUS_RESOLUTION)

    def actuator_model(self) -> ActuatorModelConfig:
        """The actuator position model every row's plant runs with."""
        return scenario.load(SCENARIO).with_models(self.plant, self.actuator, self.sensors).actuator

    def calibration(self) -> mr.ControllerConfig:
        """The calibration tuned for this rate."""
        return calibration_for_rate(self.rate_hz)
