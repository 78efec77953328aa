"""The per-step table of a HIL run: one row per plant step, on the scenario's own time base.

The plant writes its true states at every step (``PlantNode.TRACE_COLUMNS``); the bus log
holds what the controller said about each step (``MRS_AuxSteerCmd`` state and the cause bits
of ``MRS_CtrlStatus``).  This module joins the two:

* lockstep: the command of step k is the one answering step k's yaw-rate frame
  (``AuxSteerCmd_MeasCounter``; the plant publishes ``MRS_YawRate``, a control-loop message,
  once per step, so the k-th yaw-rate frame on the bus is step k's);
* realtime (or a log that lost a yaw-rate frame): the newest command on the bus when the
  plant recorded step k (its ``wall_s`` against the log's timestamps, both epoch seconds).

A command's cause is that of the newest ``MRS_CtrlStatus`` the controller sent before its
next command: it sends the status of a cycle right after that cycle's command, and one
sender's frames keep their order on the bus.  Only the plant's steps are rows, so whatever
the controller sends after the scenario ends (its input timeout, its final zero command) is
in no row.
"""

from __future__ import annotations

import bisect
import csv
import io
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import mrsteer_dbc
from mrsteer_dbc import names
from sim_plant import figures
from sim_plant.harness.processes import RunError
from sim_plant.nodes.plant import PlantNode

YAW, CMD, STATUS = names.MSG_YAW, names.MSG_CMD, names.MSG_STATUS


@dataclass(frozen=True)
class Step:
    """One plant step: the plant's truth, and what the controller reported for it."""

    step: int
    t_s: float  # scenario time, step x Ts
    driver_angle_rad: float
    yaw_rate_rad_s: float
    yaw_rate_measured_rad_s: float  # what the yaw-rate sensor gave (the true rate with ideal sensors)
    v_m_s: float
    aux_cmd_rad: float  # the newest valid command the actuator had received
    aux_applied_rad: float  # what the actuator applied over this step
    # AuxSteerCmd_State by its DBC name (STARTING, INACTIVE, ACTIVE, SATURATED, DEGRADED, FAULT);
    # "" when no command belongs to the step
    ctrl_state: str
    ctrl_cause: int | None  # CtrlStatus_Cause bits (see the DBC); None before the first status
    m_z_nm: float
    mu: float
    beta_rad: float
    lat_accel_m_s2: float
    wall_s: float  # epoch s when the plant recorded the step, for aligning with traffic.log
    # What the other sensors gave (NaN: a steps.csv written before they were kept; the second
    # yaw-rate element NaN also when the sensor has none); each measures the truth above (the
    # steering channels' truth is driver_angle_rad), and a fault's error is the reading less the
    # same sensor's without the fault (``hil_plausibility.error_over_bound``).
    steer_measured_rad: float = math.nan
    lat_accel_measured_m_s2: float = math.nan
    steer_redundant_measured_rad: float = math.nan
    yaw_rate_redundant_measured_rad_s: float = math.nan
    speed_measured_m_s: float = math.nan  # the speed sensor's reading at the step (v_m_s: the truth)
    speed_redundant_measured_m_s: float = math.nan  # the second speed's (NaN also for a car without one)


# steps.csv's columns: scenario time first, then the step and the rest in Step's order
STEP_COLUMNS = ("t_s", *(f.name for f in fields(Step) if f.name != "t_s"))
_FROM_TRACE = tuple(name for name in STEP_COLUMNS if name in PlantNode.TRACE_COLUMNS)
_TIME_COLUMNS = ("t_s", "wall_s")  # to the log's microsecond


@dataclass
class Traffic:
    """The decoded frames a report needs, in log order."""

    yaw: list[dict[str, Any]]
    commands: list[dict[str, Any]]
    answers: list[int | None]  # per yaw-rate frame: index into commands of the answer, or None
    causes: list[int | None]  # per command: the controller's cause bits for its cycle

    @classmethod
    def of(cls, rows: list[dict[str, Any]], rate_hz: float) -> "Traffic":
        yaw, commands, causes = [], [], []
        cause: int | None = None
        for r in rows:
            if r["message"] == YAW and "YawRate_YawRate" in r:
                yaw.append(r)
            elif r["message"] == CMD and "AuxSteerCmd_Angle" in r:
                commands.append(r)
                causes.append(cause)
            elif r["message"] == STATUS and "CtrlStatus_Cause" in r:
                cause = int(r["CtrlStatus_Cause"])
                if causes:
                    causes[-1] = cause  # the status that follows a command reports its cycle
        return cls(yaw, commands, answering_commands(yaw, commands, rate_hz), causes)


def answering_commands(yaw: list[dict[str, Any]], commands: list[dict[str, Any]],
                       rate_hz: float) -> list[int | None]:
    """For each yaw-rate frame, the index of the command that answers it (its
    ``AuxSteerCmd_MeasCounter`` is the frame's alive counter, and it was sent after the frame
    and before the next one, give or take half a step), or None."""
    out: list[int | None] = []
    j = 0
    for i, y in enumerate(yaw):
        nxt = yaw[i + 1]["t_s"] if i + 1 < len(yaw) else math.inf
        while j < len(commands) and commands[j]["t_s"] < y["t_s"]:
            j += 1
        k, found = j, None
        while k < len(commands) and commands[k]["t_s"] < nxt + 0.5 / rate_hz:
            if int(commands[k]["AuxSteerCmd_MeasCounter"]) == int(y["YawRate_Counter"]):
                found = k
                break
            k += 1
        out.append(found)
    return out


def state_names(contract: mrsteer_dbc.Contract | None = None) -> dict[int, str]:
    """The names of ``AuxSteerCmd_State`` by value, in value order (the DBC's value table)."""
    choices = (contract or mrsteer_dbc.load()).message(CMD).get_signal_by_name("AuxSteerCmd_State").choices or {}
    return {int(v): str(choices[v]) for v in sorted(choices)}


def read_plant_trace(path: Path) -> list[dict[str, float]]:
    """The plant's ``--trace-out`` CSV, one dict of floats per step."""
    try:
        with path.open(newline="") as f:
            reader = csv.DictReader(f)
            if tuple(reader.fieldnames or ()) != PlantNode.TRACE_COLUMNS:
                raise RunError(f"{path.name}: unexpected columns {reader.fieldnames}")
            return [{k: float(v) for k, v in row.items()} for row in reader]
    except OSError as exc:
        raise RunError(f"the plant wrote no trace ({path.name}: {exc.strerror})") from None


def step_table(trace: list[dict[str, float]], traffic: Traffic, lockstep: bool,
               contract: mrsteer_dbc.Contract) -> list[Step]:
    """Join the plant's trace with the controller's reports (see the module docstring)."""
    names = state_names(contract)
    if lockstep and len(traffic.yaw) == len(trace):
        chosen = traffic.answers
    else:
        stamps = [c["t_s"] for c in traffic.commands]
        chosen = [(n - 1 if (n := bisect.bisect_right(stamps, row["wall_s"])) else None) for row in trace]
    steps = []
    for k, (row, c) in enumerate(zip(trace, chosen)):
        state = "" if c is None else names.get(int(traffic.commands[c]["AuxSteerCmd_State"]), "")
        steps.append(Step(step=k, ctrl_state=state, ctrl_cause=None if c is None else traffic.causes[c],
                          **{name: row[name] for name in _FROM_TRACE}))
    return steps


def steps_csv(steps: list[Step]) -> bytes:
    """The rows: times to the log's microsecond, the states to 9 digits, round-off written 0
    (``sim_plant.figures``)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(STEP_COLUMNS)
    for s in steps:
        w.writerow([_cell(name, getattr(s, name)) for name in STEP_COLUMNS])
    return buf.getvalue().encode()


def _cell(name: str, value: object) -> str:
    if value is None:
        return ""
    if not isinstance(value, float):
        return str(value)
    tidy = figures.tidy(value, figures.LOG_TIME) if name in _TIME_COLUMNS else figures.tidy_datum(value)
    return figures.written(tidy)


_PARSE = {"step": int, "ctrl_state": str, "ctrl_cause": lambda text: int(text) if text else None}


def read_steps_csv(path: Path) -> list[Step]:
    """A ``steps.csv`` back as rows (to analyse or re-plot a run)."""
    with path.open(newline="") as f:
        return [Step(**{name: _PARSE.get(name, float)(text) for name, text in row.items()})  # type: ignore[operator]
                for row in csv.DictReader(f)]
