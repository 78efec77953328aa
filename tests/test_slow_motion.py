"""Slow motion: a row of the fault matrix run with every node's period stretched in wall time
(``--slow-motion``, for machines too slow for the loop) is the same car and law, judged in the
car's time."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from sim_plant.harness import launch
from sim_plant.harness.faults import ROWS, Setup, run_matrix
from sim_plant.harness.faults.evidence import CarClock, Trace
from sim_plant.harness.faults.run import bridge_fault
from sim_plant.harness.faults.settings import DURATION
from sim_plant.nodes.candump_log import Frame

ROW = {r.name: r for r in ROWS}


def test_the_bridge_gets_the_fault_in_wall_time() -> None:
    setup = Setup(time_scale=2.0, slow_motion=4.0)
    lost = ROW["yaw-rate frames lost (burst)"]
    f = bridge_fault(lost, setup)
    assert (f.start, f.stop) == (lost.fault.start * 8.0, lost.fault.stop * 8.0)
    assert f.param == lost.fault.param  # a probability is not a time
    delayed = bridge_fault(ROW["sensor frames delayed 4 ms"], setup)
    assert delayed.param == pytest.approx(0.016)
    flood = ROW["bus flooded with another ID"]
    assert bridge_fault(flood, setup).param == flood.fault.param / 4.0
    drift = next(r for r in ROWS if r.fault.kind == "sensor_drift")
    f = bridge_fault(drift, setup)
    assert f.param == drift.fault.param / 4.0  # per wall second
    assert f.start == drift.fault.start * 4.0  # a point of the car's motion: not time-scaled
    assert bridge_fault(drift, Setup()) == drift.fault  # real time: the row's own fault


def test_a_fault_the_plant_injects_leaves_the_bridge_forwarding() -> None:
    from sim_plant.harness.faults.rows import secured_rows

    row = next(r for r in secured_rows() if r.at_plant)
    f = bridge_fault(row, Setup(slow_motion=3.0))
    assert f.kind == "none" and f.signal is None


def test_the_car_clock_is_exactly_the_wall_clock_in_real_time() -> None:
    frames = [Frame(1.7e9 + 0.1 * k + 1e-7, 0x100, b"") for k in range(5)]
    clock = CarClock(1.0, frames[0].t)
    assert clock.frames(frames) is frames and all(clock(f.t) == f.t for f in frames)


def test_the_car_clock_divides_wall_time_from_one_reference() -> None:
    ref = 1.7e9
    clock = CarClock(5.0, ref)
    assert clock(ref) == ref and clock(ref + 10.0) == pytest.approx(ref + 2.0, abs=1e-6)
    assert clock.maybe(None) is None
    tr = clock.trace(Trace([0.0, 0.002], [0.0, 0.0], [0.0, 0.0], [ref, ref + 0.01], {"wall_s": [ref, ref + 0.01]}))
    assert tr.wall == pytest.approx([ref, ref + 0.002], abs=1e-6) and tr.columns["wall_s"] == tr.wall
    assert clock.frames([Frame(ref + 1.0, 7, b"x")]) == [Frame(pytest.approx(ref + 0.2), 7, b"x")]


@pytest.mark.parametrize("impl", ["python", "c"])
def test_a_row_in_slow_motion_is_judged_as_in_real_time(tmp_path: Path, impl: str) -> None:
    """The burst of lost yaw-rate frames at 2.5x slow motion: the plant took 2.5x its scenario in
    wall time, the controller ran one cycle per car step, and the row's verdict (FAULT within
    the timeout in cycles, the fade, the recovery) is the real-time one."""
    slow = 2.5
    setup = replace(Setup(slow_motion=slow), controller_program=launch.controller_program(impl))
    row = ROW["yaw-rate frames lost (burst)"]
    [result] = run_matrix((row,), keep=tmp_path, setup=setup)
    assert result.passed, result.failures
    assert result.detection_cycles is not None and result.detection_cycles <= 12
    plant = json.loads((tmp_path / "01" / "plant.json").read_text())
    assert plant["wall_time_s"] >= 0.9 * slow * DURATION  # it did run slowly
    assert plant["overruns"] <= plant["steps"] // 20
    ctl = json.loads((tmp_path / "01" / "controller.json").read_text())
    assert abs(ctl["cycles"] - plant["steps"]) <= plant["steps"] // 10  # one law step per car step
