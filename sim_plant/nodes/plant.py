"""The plant process: the single-track car, its sensors and the auxiliary actuator on a bus.

The car is the scenario's (``sim_plant.car.scenario``; ``--plant``, ``--actuator``,
``--sensors``, ``--seed`` override it): by default the paper's exact linear plant, an ideal
actuator and exact sensors; on request the nonlinear car, the actuator's position dynamics and
the sensor models of ``docs/realistic-car.md``.  Each plant step (period ``ts``):

1. apply the scenario events due (and any ``MRS_BenchInject`` received), re-discretising the
   model if speed or friction changed, and take the physical disturbances' loads at t
   (``Car.set_loads``: grip now, forces held over the step);
2. the driver model sets the driver's front-wheel angle;
3. the actuator's command handling (``sim_plant.car.actuator``) takes the newest valid
   auxiliary command: only frames the receive link accepts count (``mrsteer_dbc.link.RxLink``:
   length, CRC, range, SecOC when a key is given, alive counter); with no valid command for
   ``cmd_timeout`` it fades to zero at a bounded rate;
4. the sensors (``sim_plant.car.sensors``) measure the driver angle, the speed, the yaw
   rate and, for the plausibility monitor, the lateral acceleration a_y = v (beta' + r) and the
   steering-angle sensor's second channel (``MRS_RedundantSensors``), each with the scenario's
   sensor faults (``sim_plant.car.sensor_faults``: well-formed frames carrying wrong values),
   and the messages due at this step are published (with SecOC, first
   ``MRS_SecOCSync`` at its DBC cycle time: the actuator is the freshness master, and the
   sensor frames are signed for the epoch it announced) (each at its DBC cycle time, never
   faster than the plant step): driver angle, speed, redundant sensors, then yaw rate last, so a controller
   triggered by the yaw-rate frame sees a complete set;
5. the actuator's position (``sim_plant.car.actuator_dynamics.PositionActuator``, when not
   ideal) follows what the command handling gave, once per step, and the car advances with
   front-wheel angle = driver angle + that position.  The ideal actuator applies the handled
   command itself, so the default run is today's exactly.

``lockstep`` mode waits after step 4 for the command that answers this step's yaw-rate frame
(``AuxSteerCmd_MeasCounter``), up to ``lockstep_timeout``, and applies it ``delay_steps``
steps later: a bus run is then the offline ``sim --ts T --delay-steps N`` exactly, up to the
DBC's signal resolution.  ``realtime`` mode runs on absolute deadlines of the monotonic clock
and applies the newest valid command at each step.
"""

from __future__ import annotations

import argparse
import collections
import csv
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import can

import mrsteer_dbc
from firmware_py.platform.bus_open import BusOpenError, open_bus
from firmware_py.platform.cli import (Parser, add_secoc_args, add_slow_motion_arg, check_output_file,
                                      check_slow_motion, fail, secoc_key, slow_motion_suffix)
from firmware_py.platform.lifecycle import run_node
from mrsteer_dbc import secoc
from mrsteer_dbc.link import Rejected, RxLink, TxLink
from mrsteer_dbc.names import (MSG_BENCH, MSG_CMD, MSG_REDUNDANT, MSG_SPEED, MSG_STATUS, MSG_STEER, MSG_SYNC,
                               MSG_YAW, SIG_BENCH_MU, SIG_BENCH_YAW_MOMENT, SIG_CMD_ANGLE, SIG_CMD_MEAS, SIG_LAT_ACCEL,
                               SIG_SPEED, SIG_STATUS_PLAUS, SIG_SPEED_2, SIG_STEER_ANGLE, SIG_STEER_ANGLE_2, SIG_YAW_RATE,
                               SIG_YAW_RATE_2, VEHICLE_SENSORS)
from firmware_py.controller.node import DEFAULT_RATE_HZ  # the plant steps at the controller's rate
from firmware_py.controller.timing import LatenessHistogram
from sim_plant.car import scenario as scn
from sim_plant.car.scenario_play import ScenarioState
from sim_plant.car.actuator import CMD_TIMEOUT_S, FADE_RATE_RAD_S, RATE_LIMIT_RAD_S, Actuator, ActuatorConfig
from sim_plant.car.actuator_dynamics import ActuatorModelConfig, PositionActuator
from sim_plant.car.options import add_car_args, add_sensor_fault_arg
from sim_plant.car.plants import Car
from sim_plant.car.model_files import ModelFileError
from sim_plant.car.sensor_faults import parse_spec
from sim_plant.car.sensors import Sensors

MODES = ("realtime", "lockstep")


@dataclass
class PlantStats:
    steps: int = 0
    tx_frames: int = 0
    cmd_accepted: int = 0
    cmd_rejected: int = 0  # every rejected command, whatever the reason
    cmd_auth_failed: int = 0  # of which: SecOC verification failed (forged, replayed, stale)
    cmd_unmatched: int = 0  # valid commands that did not answer the awaited measurement (lockstep)
    lockstep_timeouts: int = 0
    actuator_timeouts: int = 0
    actuator_authority_steps: int = 0  # steps in which the actuator's authority limiter changed the command
    bench_injections: int = 0
    rx_before_start: int = 0  # frames queued before the first step, discarded unread
    rx_ignored: int = 0  # frames of other IDs (queued before the kernel filter was installed)
    overruns: int = 0  # realtime: steps started more than a period late (made up, none skipped)
    wall_time_s: float = 0.0
    trace: list[tuple[float, ...]] = field(default_factory=list)
    lateness: LatenessHistogram = field(default_factory=LatenessHistogram)  # realtime: each step's start

    def summary(self) -> dict[str, Any]:
        lat = self.lateness
        return {**{k: v for k, v in self.__dict__.items() if k not in ("trace", "lateness")},
                "lateness_p50_s": lat.percentile(0.5), "lateness_p99_s": lat.percentile(0.99),
                "lateness_max_s": lat.max}


class PlantNode:
    TRACE_COLUMNS = ("t_s", "driver_angle_rad", "aux_applied_rad", "m_z_nm", "mu", "v_m_s",
                     "yaw_rate_rad_s", "beta_rad", "lat_accel_m_s2", "aux_cmd_rad", "yaw_rate_measured_rad_s",
                     "steer_measured_rad", "lat_accel_measured_m_s2", "steer_redundant_measured_rad",
                     "yaw_rate_redundant_measured_rad_s", "speed_measured_m_s", "speed_redundant_measured_m_s",
                     "wall_s")  # wall_s last: written to the microsecond

    def __init__(self, bus: can.BusABC, sc: scn.Scenario, mode: str = "lockstep", ts: float = 1e-3,
                 delay_steps: int = 1, cmd_timeout: float = CMD_TIMEOUT_S, lockstep_timeout: float = 1.0,
                 fade_rate: float = FADE_RATE_RAD_S, contract: mrsteer_dbc.Contract | None = None,
                 expect_controller: bool = True, actuator_rate: float = RATE_LIMIT_RAD_S,
                 secoc_key: bytes | None = None, slow_motion: float = 1.0) -> None:
        if mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}")
        self.bus, self.sc, self.mode, self.ts = bus, sc, mode, ts
        self.wall_period = ts * slow_motion  # realtime: a slow machine's bench stretches the wall clock only
        self.delay_steps = delay_steps
        self.contract = c = contract or mrsteer_dbc.load()
        self.scene = ScenarioState(sc)
        self.plant = Car(sc.plant, self.scene.params(), ts)
        # The ideal actuator is the command handling alone (today's plant, exactly).
        self.position = None if sc.actuator == ActuatorModelConfig.ideal() else PositionActuator(sc.actuator, ts)
        self.sensors = Sensors(sc.sensor_config, ts)
        # The actuator's own range, not the signal's: the DBC's +-0.0524 rad is 3.0023 deg, so a
        # command at the signal's edge (a forgery, on a bus without SecOC) would pass +-3 deg.
        limit = min(ActuatorConfig().limit, c.signal_range(MSG_CMD, SIG_CMD_ANGLE)[1])
        self.actuator = Actuator(ActuatorConfig(cmd_timeout, fade_rate, actuator_rate, limit), ts)
        self.cmd_id = c.frame_id(MSG_CMD)
        self.verifier = secoc.CommandVerifier(c, secoc_key) if secoc_key is not None else None
        self.sensor_signer = secoc.SensorSigner(c, secoc_key) if secoc_key is not None else None
        self.sync_every = max(1, int(round((c.cycle_time_s(MSG_SYNC) or 0.1) / ts)))
        # The controller's status tells the actuator's authority limiter whether the inputs are checked.
        self.rx = RxLink(c, (MSG_CMD, MSG_BENCH, MSG_STATUS),
                         {MSG_CMD: self.verifier} if self.verifier is not None else None)
        bus.set_filters(self.rx.filters())
        # The sensors saturate at their signals' DBC ranges (``Sensors``): a spinning car's yaw
        # rate reads 3 rad/s in a valid frame (which the monitor judges), not a value the frame
        # cannot carry.  strict=False lets an out-of-range value through (a bench's injection;
        # the controller range-checks).
        self.tx = TxLink(c, (MSG_SYNC, *VEHICLE_SENSORS), self.sensor_signer, strict=False)
        self.every = {name: max(1, int(round((c.cycle_time_s(name, ts) or ts) / ts))) for name in VEHICLE_SENSORS}
        self.lockstep_timeout = lockstep_timeout
        self.expect_controller = expect_controller
        self.stats = PlantStats()
        self.pipeline: collections.deque[float] = collections.deque([0.0] * delay_steps)
        self.latest_cmd = 0.0
        self.bench_m_z: float | None = None
        self._running = True
        self.record_trace = False

    def stop(self, *_: Any) -> None:
        self._running = False

    # ---------------------------------------------------------------- receive

    def receive(self, msg: can.Message, await_counter: int | None = None) -> bool:
        """Handle one frame through the link; True if it is the valid command answering
        ``await_counter``."""
        got = self.rx.accept(msg)
        if type(got) is Rejected:
            if got is Rejected.IGNORED:
                self.stats.rx_ignored += 1
            elif msg.arbitration_id == self.cmd_id:  # a rejected bench injection is dropped uncounted
                self.stats.cmd_rejected += 1
                if got is Rejected.MAC:
                    self.stats.cmd_auth_failed += 1
            return False
        if got.name == MSG_STATUS:
            self.actuator.status_received(int(got.signals[SIG_STATUS_PLAUS]))
            return False
        if got.name == MSG_BENCH:
            self.bench_m_z = got.signals[SIG_BENCH_YAW_MOMENT]
            self.scene.mu = got.signals[SIG_BENCH_MU]
            self.plant.set_params(self.scene.params())
            self.stats.bench_injections += 1
            return False
        self.stats.cmd_accepted += 1
        self.latest_cmd = got.signals[SIG_CMD_ANGLE]
        self.actuator.command_received()
        if await_counter is None:
            return False
        if int(got.signals[SIG_CMD_MEAS]) == await_counter:
            return True
        self.stats.cmd_unmatched += 1
        return False

    # ---------------------------------------------------------------- step

    def _publish(self, k: int, m: dict[str, float]) -> int:
        """Send this step's frames (``m``: the measured values by signal); the yaw-rate frame's
        alive counter, or -1 if none was due."""
        send = self.bus.send
        if self.verifier is not None and k % self.sync_every == 0:
            send(self.tx.frame(MSG_SYNC, self.verifier.new_epoch()))
            self.stats.tx_frames += 1
            assert self.sensor_signer is not None
            self.sensor_signer.adopt(self.verifier.current)
        sends = []
        if k % self.every[MSG_STEER] == 0:
            sends.append((MSG_STEER, {SIG_STEER_ANGLE: m[SIG_STEER_ANGLE]}))
        if k % self.every[MSG_SPEED] == 0:
            sends.append((MSG_SPEED, {SIG_SPEED: m[SIG_SPEED]}))
        if k % self.every[MSG_REDUNDANT] == 0:
            sends.append((MSG_REDUNDANT, {SIG_LAT_ACCEL: m[SIG_LAT_ACCEL], SIG_STEER_ANGLE_2: m[SIG_STEER_ANGLE_2],
                                          SIG_SPEED_2: m[SIG_SPEED_2]}))
        yaw_counter = -1
        if k % self.every[MSG_YAW] == 0:
            sends.append((MSG_YAW, {SIG_YAW_RATE: m[SIG_YAW_RATE], SIG_YAW_RATE_2: m[SIG_YAW_RATE_2]}))
        for name, values in sends:
            send(self.tx.frame(name, values))
            self.stats.tx_frames += 1
            if name == MSG_YAW:
                yaw_counter = self.tx.counter(MSG_YAW)
        return yaw_counter

    def step(self, k: int) -> None:
        t = k * self.ts
        if self.scene.advance_to(t):
            self.plant.set_params(self.scene.params())
        self.plant.set_loads(self.scene.loads(t))
        m_z = self.bench_m_z if self.bench_m_z is not None else self.scene.m_z
        r_now = float(self.plant.x[1])
        driver = self.scene.driver_angle(t, r_now, self.ts)
        if self.mode == "lockstep":
            pending = self.pipeline.popleft() if self.delay_steps else None
        else:
            # Commands that arrived while we slept take effect over this step.
            while (msg := self.bus.recv(0.0)) is not None:
                self.receive(msg)
            pending = self.latest_cmd
        actuator = self.actuator
        # Outputs at this step use the front-wheel angle being applied over it (a lagging
        # actuator's: its position as the step begins).
        actuator.apply(pending)
        position = self.position
        y = self.plant.outputs(driver + (actuator.applied if position is None else position.position), m_z)
        sensors = self.sensors
        sensors.at(t)
        # Every channel is read at every step (their filters and faults run at the plant step);
        # a frame carries the reading of the step it is sent at.
        measured = {SIG_STEER_ANGLE: sensors.steer(driver), SIG_SPEED: sensors.speed(self.scene.v),
                    SIG_LAT_ACCEL: sensors.lat_accel(float(y[2])), SIG_STEER_ANGLE_2: sensors.steer_redundant(driver),
                    SIG_YAW_RATE: sensors.yaw_rate(float(y[0])), SIG_YAW_RATE_2: sensors.yaw_rate_redundant(float(y[0])),
                    SIG_SPEED_2: sensors.speed_redundant(self.scene.v * (1.0 - self.plant.loads.wheel_slip))}
        measured_yaw = measured[SIG_YAW_RATE]
        yaw_counter = self._publish(k, measured)

        if self.mode == "lockstep":
            answer = self._await_command(yaw_counter)
            if self.delay_steps:
                self.pipeline.append(answer)
            else:
                actuator.apply(answer)
        actuator.tick()
        self.stats.actuator_timeouts = actuator.timeouts
        self.stats.actuator_authority_steps = actuator.authority_steps
        applied = actuator.applied if position is None else position.step(actuator.applied)
        if self.record_trace:
            # m_z: the whole yaw moment on the car, the physical disturbances' included.
            self.stats.trace.append((t, driver, applied, m_z + self.plant.loads.m_z, self.scene.mu, self.scene.v, float(y[0]), float(y[1]),
                                     float(y[2]), self.latest_cmd, measured_yaw, measured[SIG_STEER_ANGLE],
                                     measured[SIG_LAT_ACCEL], measured[SIG_STEER_ANGLE_2], measured[SIG_YAW_RATE_2],
                                     measured[SIG_SPEED], measured[SIG_SPEED_2], time.time()))
        # A lagging actuator moves within the step: the car gets the position's mean over it.
        self.plant.advance(driver + (applied if position is None else position.mean), m_z)
        if not self.plant.linear:
            self.scene.v = self.plant.v  # braking slows the car: the speed frames carry it
        self.stats.steps += 1

    def _await_command(self, yaw_counter: int) -> float | None:
        if not self.expect_controller:
            return None
        if yaw_counter < 0:
            return self.latest_cmd if self.actuator.fresh else None
        deadline = time.monotonic() + self.lockstep_timeout
        while self._running:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            msg = self.bus.recv(left)
            if msg is None:
                break
            if self.receive(msg, yaw_counter):
                return self.latest_cmd
        self.stats.lockstep_timeouts += 1
        return None

    def run(self) -> PlantStats:
        n = int(round(self.sc.duration / self.ts)) + 1
        # The actuator powers up at the first step: what the bus queued while this process set up
        # was sent to an ECU that was not there (with SecOC, commands for a freshness it never issued).
        while self.bus.recv(0.0) is not None:
            self.stats.rx_before_start += 1
        start = time.monotonic()
        deadline = start
        for k in range(n):
            if not self._running:
                break
            if self.mode == "realtime":
                now = time.monotonic()
                if now < deadline:
                    time.sleep(deadline - now)
                    now = time.monotonic()
                self.stats.lateness.add(now - deadline)
                if now - deadline > self.wall_period:
                    self.stats.overruns += 1
                deadline += self.wall_period
            self.step(k)
        self.stats.wall_time_s = time.monotonic() - start
        return self.stats

    def trace_csv(self) -> str:
        f = io.StringIO(newline="")
        w = csv.writer(f)
        w.writerow(self.TRACE_COLUMNS)
        for row in self.stats.trace:
            # The wall clock (epoch s, for aligning with bus logs) needs microseconds, not 9 digits.
            w.writerow([*(f"{x:.9g}" for x in row[:-1]), f"{row[-1]:.6f}"])
        return f.getvalue()


def build_parser(prog: str = "mrsteer plant") -> argparse.ArgumentParser:
    p = Parser(prog=prog, description="Run the simulated car (single-track model, sensors, auxiliary actuator) "
               "on a CAN bus, playing a scenario.")
    p.add_argument("--interface", help="python-can interface (default: python-can config, else SocketCAN vcan0 "
                   "if present, else the mrsteer fallback bus)")
    p.add_argument("--channel", help="channel for the interface")
    p.add_argument("--scenario", default="paper-fig9",
                   help=f"built-in ({', '.join(scn.BUILTINS)}) or a TOML file (default paper-fig9)")
    p.add_argument("--mode", choices=MODES, default="realtime",
                   help="realtime: free-running on the wall clock (default); lockstep: advance when the "
                   "controller has answered")
    p.add_argument("--rate-hz", type=float, default=DEFAULT_RATE_HZ,
                   help=f"plant step rate in Hz (default {DEFAULT_RATE_HZ:g}, the controller's default)")
    p.add_argument("--delay-steps", type=int, default=1,
                   help="lockstep: steps between a measurement and the application of its command (default 1)")
    p.add_argument("--v", type=float, help="override the scenario's speed, m/s")
    p.add_argument("--mu", type=float, help="override the scenario's friction")
    p.add_argument("--mz", type=float, help="override every yaw-moment step, Nm")
    p.add_argument("--mass", type=float, help="override the vehicle mass, kg")
    p.add_argument("--duration", type=float, metavar="S", help="override the scenario's duration, s")
    add_car_args(p)  # each overrides the scenario's car
    add_sensor_fault_arg(p)
    p.add_argument("--actuator-rate", type=float, default=RATE_LIMIT_RAD_S, metavar="RAD_S",
                   help="the actuator's own slew-rate limit in rad/s, applied to whatever command arrives "
                   "(default 0: follows the command at once)")
    p.add_argument("--cmd-timeout", type=float, default=CMD_TIMEOUT_S, metavar="S",
                   help=f"no valid command for this long: the actuator fades to zero (default {CMD_TIMEOUT_S:g})")
    p.add_argument("--lockstep-timeout", type=float, default=1.0, metavar="S",
                   help="lockstep: longest wait for the controller's answer (default 1)")
    p.add_argument("--no-controller", action="store_true",
                   help="lockstep without a controller on the bus: do not wait for commands")
    add_secoc_args(p)
    add_slow_motion_arg(p)
    p.add_argument("--stats-out", type=Path, metavar="FILE", help="write plant statistics as JSON here")
    p.add_argument("--trace-out", type=Path, metavar="FILE", help="write the true states as CSV here")
    return p


def main(argv: Sequence[str] | None = None, prog: str = "mrsteer plant") -> int:
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    if not (math.isfinite(args.rate_hz) and 1.0 <= args.rate_hz <= 10000.0):
        parser.error(f"--rate-hz must be in [1, 10000], got {args.rate_hz}")
    if not 0 <= args.delay_steps <= 100:
        parser.error("--delay-steps must be in [0, 100]")
    if not (math.isfinite(args.actuator_rate) and args.actuator_rate >= 0.0):
        parser.error(f"--actuator-rate must be >= 0, got {args.actuator_rate}")
    for name in ("cmd_timeout", "lockstep_timeout"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            parser.error(f"--{name.replace('_', '-')} must be positive")
    check_slow_motion(parser, args.slow_motion)
    if args.slow_motion != 1.0 and args.mode != "realtime":
        parser.error("--slow-motion is for --mode realtime (lockstep already waits for the controller)")
    try:
        sc = scn.load(args.scenario).with_overrides(v=args.v, mu=args.mu, mz=args.mz, mass=args.mass,
                                                   duration=args.duration).with_models(
            args.plant, args.actuator, args.sensors, args.seed)
        sc = sc.with_sensor_faults(tuple(parse_spec(spec) for spec in args.sensor_fault))
    except (scn.ScenarioError, ModelFileError) as exc:
        parser.error(str(exc))
    key = secoc_key(args, parser)
    check_output_file(parser, "--stats-out", args.stats_out)
    check_output_file(parser, "--trace-out", args.trace_out)
    try:
        bus = open_bus(args.interface, args.channel)
    except BusOpenError as exc:
        return fail(prog, str(exc))
    node = PlantNode(bus, sc, args.mode, 1.0 / args.rate_hz, args.delay_steps, args.cmd_timeout,
                     args.lockstep_timeout, expect_controller=not args.no_controller,
                     actuator_rate=args.actuator_rate, secoc_key=key, slow_motion=args.slow_motion)
    node.record_trace = args.trace_out is not None
    slow = slow_motion_suffix(args.slow_motion)
    return run_node(prog, bus, node.run, node.stop,
                    [(args.stats_out, lambda: json.dumps(node.stats.summary(), indent=2)),
                     (args.trace_out, node.trace_csv)],
                    ready=f"{sc.name} ({sc.duration:g} s, {args.mode}) on {bus.channel_info}{slow}")
