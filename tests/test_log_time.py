"""Scenario time of logged frames (``sim_plant.harness.log_time``): the plant's steps counted by
the yaw-rate frames' alive counter, and the controller's frames placed at the step they answer."""

from __future__ import annotations

import pytest

import mrsteer_dbc
from mrsteer_dbc import names
from sim_plant.harness.log_time import scenario_times

C = mrsteer_dbc.load()
YAW, CMD, STATUS = (C.frame_id(n) for n in (names.MSG_YAW, names.MSG_CMD, names.MSG_STATUS))
TS = 0.002


def _yaw(counter: int) -> bytes:
    return C.encode(names.MSG_YAW, {"YawRate_YawRate": 0.0}, counter)


def test_the_last_steps_answer_is_at_its_step_however_late_it_came() -> None:
    # two steps; the answer to the last comes 3.7 ms after it (a loaded machine), its cycle's
    # status after it, and the final zero command half a second later
    frames = [(YAW, _yaw(0), 10.000), (CMD, b"", 10.0004), (YAW, _yaw(1), 10.002), (CMD, b"", 10.0057),
              (STATUS, b"", 10.0058), (CMD, b"", 10.502)]
    got = scenario_times(frames, TS, C)
    assert got[:5] == [0.0, 0.0, TS, TS, TS]
    assert got[5] == pytest.approx(TS + 0.5)


def test_a_lost_yaw_rate_frame_counts_its_step() -> None:
    frames = [(YAW, _yaw(0), 1.0), (CMD, b"", 1.0003), (YAW, _yaw(2), 1.004), (CMD, b"", 1.0043)]
    assert scenario_times(frames, TS, C) == [0.0, 0.0, 2 * TS, 2 * TS]
