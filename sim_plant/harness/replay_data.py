"""What a log replay works with and finds: how the recorded controller ran, the commands and
status frames (replayed or recorded), one cycle of the replay (``Step``), a mismatch, and the
result (``replay.replay`` makes them; ``replay_report`` reports them)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from firmware_py import model_regulator as mr
from firmware_py.controller.node import DEFAULT_RATE_HZ, TRIGGERS, RuntimeConfig


@dataclass(frozen=True)
class ReplaySettings:
    """How the recorded controller ran: its rate, trigger, timeouts, calibration and key."""

    rate_hz: float = DEFAULT_RATE_HZ
    trigger: str = "sensors"
    timeout_cycles: int = 10
    controller: mr.ControllerConfig = field(default_factory=mr.ControllerConfig)
    secoc_key: bytes | None = None

    def runtime(self) -> RuntimeConfig:
        if self.trigger not in TRIGGERS:
            raise ValueError(f"trigger must be one of {', '.join(TRIGGERS)}")
        return RuntimeConfig(rate_hz=self.rate_hz, timeout_cycles=self.timeout_cycles, trigger=self.trigger,
                             secoc_key=self.secoc_key, controller=self.controller)


@dataclass(frozen=True)
class Out:
    """One command (with its status frame when one was sent in that cycle), replayed or recorded.
    ``None`` in a field: not known for this implementation (the C law has no cause bits)."""

    line: int  # log line of the recorded frame (0: replayed)
    t: float  # bus time, epoch s (replayed: the time of the frame that triggered the cycle)
    angle: float  # rad, as the DBC carries it
    state: int
    meas: int | None
    counter: int | None
    valid: bool = True  # recorded: the frame passed length, CRC and range


@dataclass(frozen=True)
class StatusOut:
    line: int
    t: float
    state: int
    flags: int
    cause: int | None
    rejected: int | None
    valid: bool = True
    plausibility: int | None = None  # CtrlStatus_Plausibility


@dataclass
class Step:
    """One controller cycle of the replay."""

    index: int
    kind: str  # "yaw" (answers an accepted yaw-rate frame), "watchdog", "clock" or "final"
    line: int  # the log line that triggered it (the yaw-rate frame, or the recorded command)
    t: float
    # (delta_driver, yaw_rate, speed) into step(), then (lat_accel, delta_driver_redundant,
    # yaw_rate_redundant, speed_redundant) into the monitor (with the command sent the cycle
    # before); NaN: invalid.
    inputs: tuple[float, float, float, float, float, float, float]
    out: Out
    flags: int = 0  # the firmware's range flags after this step
    status: StatusOut | None = None  # the status frame sent in this cycle
    recorded: Out | None = None
    recorded_status: StatusOut | None = None
    monitor_steps: int = 1  # yaw-rate samples the monitor stepped over (0: its verdict held)
    # the driver's angle of the monitor's first step (``ControllerNode.monitor_driver_angle``: the
    # one that came with a new redundant sample, else delta_driver); the replay sets it every cycle
    monitor_driver: float = math.nan
    starting: bool = False  # the cycle was in the node's start state (``ControllerNode.starting``)
    t_s: float = math.nan  # scenario time of the frame that triggered it (``log_time``)
    late: bool = False  # clock trigger: its command came off its period (``replay_clock.late``)
    groupings: int = 1  # clock trigger: how many prefixes of the sensor frames the log allowed it
    received: int = 0  # clock trigger: the logged sensor frames the node had received by this cycle
    tied: bool = False  # clock trigger: groupings giving the law different inputs all reproduced its command


@dataclass(frozen=True)
class Mismatch:
    line: int  # log line of the frame that disagrees (the recorded one, or the yaw frame left unanswered)
    t: float
    frame_id: int
    what: str  # "angle", "state", "meas", "counter", "missing", "extra", "invalid", status fields
    frame: str = "command"  # which recorded frame kind it concerns: "command" or "status"

    def describe(self) -> str:
        return f"line {self.line} t={self.t:.6f} ID 0x{self.frame_id:03X}: {self.what}"


@dataclass
class ReplayResult:
    log: Path
    settings: ReplaySettings
    frames: int
    sensor_frames: int
    steps: list[Step]
    statuses_recorded: int
    mismatches: list[Mismatch]
    max_abs_dangle: float  # rad, over the steps with a recorded command
    config: mr.ControllerConfig  # the calibration the node ran (effective_config)
    recorded_statuses: list[StatusOut] = field(default_factory=list)
    structural: list[Mismatch] = field(default_factory=list)  # cycles the log has no command for
    # from a late cycle no grouping reproduces on: the mismatches its inputs decide (see the module docstring)
    apart: list[Mismatch] = field(default_factory=list)
    unjudged_from: int | None = None  # the log line of that late cycle's command
    min_answer_s: float | None = None  # clock trigger: the shortest yaw-rate frame to command time in the log
    times: dict[int, float] = field(default_factory=dict)  # scenario time of each log line (``log_time``)

    @property
    def agrees(self) -> bool:
        return not self.mismatches

    @property
    def first(self) -> Mismatch | None:
        return min(self.mismatches, key=lambda m: m.line) if self.mismatches else None

    @property
    def late(self) -> list[Step]:
        return [s for s in self.steps if s.late]

    def count(self, frame: str, *what: str) -> int:
        """Mismatches of ``frame`` ("command" or "status"), of the kinds ``what`` (all if none)."""
        return sum(1 for m in self.mismatches if m.frame == frame and (not what or m.what.split(":")[0] in what))
