"""Scenario time of logged frames: the plant's steps, counted on the bus.

The plant sends one ``MRS_YawRate`` frame per step (a control-loop message), so its alive
counter counts the steps (a lost frame by the counter's jump, up to the receivers' 3); that is
the scenario's clock in a lockstep run, whose wall time is the machine's and not the car's, as in
a realtime one.  A frame's scenario time (s from the plant's first frame) is:

* a yaw-rate frame: its step x period;
* another of the plant's frames (driver angle, speed, redundant sensors, SecOC sync; the
  plant sends them before the step's yaw rate): the step after the newest yaw-rate frame's;
* a controller frame (command, status): the newest yaw-rate frame's step, the measurement it
  answers or followed; before the plant's first yaw-rate frame, its bus time less the plant's
  first frame's (negative: a realtime controller runs before the plant starts).  After the
  plant's last frame, the first command (and the status of its cycle) answers the last step,
  however late a loaded machine sent it; a later frame more than a period after the plant's
  last is at the last step's time plus the bus time since (the plant has stopped: the final zero
  command).
"""

from __future__ import annotations

from typing import Sequence

import mrsteer_dbc
from mrsteer_dbc.e2e import COUNTER_MODULO, E2EStatus
from mrsteer_dbc.names import MSG_CMD, MSG_STATUS, MSG_YAW

MAX_STEP_JUMP = 3  # a counter jump counted as lost frames (the receivers' max_counter_delta); more: one step


def scenario_times(frames: Sequence[tuple[int, bytes, float]], period: float,
                   contract: mrsteer_dbc.Contract | None = None) -> list[float]:
    """Each frame's scenario time (s), for frames given as (ID, payload, bus time) in log order."""
    c = contract or mrsteer_dbc.load()
    yaw_id = c.frame_id(MSG_YAW)
    controller = {c.frame_id(MSG_CMD), c.frame_id(MSG_STATUS)}
    plant = [i for i, (fid, _, _) in enumerate(frames) if fid not in controller]
    if not plant:
        return [t - frames[0][2] for _, _, t in frames]
    t0, last = frames[plant[0]][2], plant[-1]
    step: int | None = None
    counter = 0
    commands_after = 0  # commands since the plant's last frame
    cmd_id = c.frame_id(MSG_CMD)
    out = []
    for i, (fid, data, t) in enumerate(frames):
        if fid == yaw_id:
            d = c.decode(fid, data)
            if d is not None and d.status is E2EStatus.OK and d.counter is not None:
                jump = (d.counter - counter) % COUNTER_MODULO
                step = 0 if step is None else step + (jump if 1 <= jump <= MAX_STEP_JUMP else min(jump, 1))
                counter = d.counter
                out.append(step * period)
                continue
        if fid not in controller:
            out.append(0.0 if step is None else (step + 1) * period)
        elif step is None:
            out.append(t - t0)
        else:
            if i > last and fid == cmd_id:
                commands_after += 1
            answer = commands_after <= 1  # the last step's answer, or its cycle's status
            since = t - frames[last][2] if i > last and not answer else 0.0
            out.append(step * period + (since if since > period else 0.0))
    return out
