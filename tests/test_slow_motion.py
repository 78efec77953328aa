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


@pytest.mark.parametrize("impl", ["python", pytest.param("c", marks=[pytest.mark.slow, pytest.mark.serial])])
def test_a_row_in_slow_motion_is_judged_as_in_real_time(tmp_path: Path, impl: str) -> None:
    """The burst of lost yaw-rate frames at 2.5x slow motion: the plant took 2.5x its scenario in
    wall time, the controller ran one cycle per car step, and the row's verdict (FAULT within
    the timeout in cycles, the fade, the recovery and its known defect) is the real-time one."""
    slow = 2.5
    setup = replace(Setup(slow_motion=slow), controller_program=launch.controller_program(impl))
    row = ROW["yaw-rate frames lost (burst)"]
    [result] = run_matrix((row,), keep=tmp_path, setup=setup)
    assert result.ok, result.failures  # the burst row's known defect is judged alike
    assert result.detection_cycles is not None and result.detection_cycles <= 12
    plant = json.loads((tmp_path / "01" / "plant.json").read_text())
    assert plant["wall_time_s"] >= 0.9 * slow * DURATION  # it did run slowly
    assert plant["overruns"] <= plant["steps"] // 20
    ctl = json.loads((tmp_path / "01" / "controller.json").read_text())
    assert abs(ctl["cycles"] - plant["steps"]) <= plant["steps"] // 10  # one law step per car step


def test_gather_reads_every_time_of_a_slow_row_in_the_cars_time(tmp_path: Path) -> None:
    """A made-up row directory in 2x slow motion: the frames of both logs, the trace's wall
    column, the kill and restart and the bridge's window all come back as ref + (t - ref) / 2."""
    import can

    import mrsteer_dbc
    from mrsteer_dbc import names
    from sim_plant.harness.faults.evidence import gather
    from sim_plant.nodes.candump_log import format_line

    c = mrsteer_dbc.load()
    ref = 1.7e9 + 0.25  # the vehicle's first frame

    def log(path: Path, frames: list[tuple[float, str, dict[str, float]]]) -> None:
        path.write_text("".join(format_line(can.Message(timestamp=t, arbitration_id=c.frame_id(name),
                                                        data=c.encode(name, values, k % 15), is_extended_id=False), "x")
                                for k, (t, name, values) in enumerate(frames)))

    yaw = (names.MSG_YAW, {names.SIG_YAW_RATE: 0.0})
    log(tmp_path / "vehicle.log", [(ref + 0.002 * k, *yaw) for k in range(6)])
    log(tmp_path / "controller.log", [(ref + 0.004, *yaw), (ref + 0.006, names.MSG_CMD, {
        "AuxSteerCmd_State": 1, "AuxSteerCmd_Angle": 0.0, "AuxSteerCmd_MeasCounter": 0, "AuxSteerCmd_FvEpoch": 0,
        "AuxSteerCmd_FvCounter": 0, "AuxSteerCmd_MAC": 0})])
    (tmp_path / "trace.csv").write_text("t_s,aux_applied_rad,aux_cmd_rad,wall_s\n0,0,0,%.6f\n0.002,0,0,%.6f\n"
                                        % (ref, ref + 0.004))
    times = {"t0": ref, "first_affected": ref + 0.006, "last_affected": ref + 0.01}
    (tmp_path / "bridge.json").write_text(json.dumps({**times, "affected": 2}))
    (tmp_path / "plant.json").write_text("{}")
    for side in ("vehicle", "controller"):
        (tmp_path / f"logger-{side}.json").write_text('{"frames": 6}')
    e = gather(ROW["baseline"], tmp_path, None, ref + 0.008, ref + 0.01, Setup(slow_motion=2.0))
    car = pytest.approx
    assert [f.t for f in e.vehicle_frames] == car([ref + 0.001 * k for k in range(6)], abs=1e-6)
    assert [f.t for f in e.frames] == car([ref + 0.002, ref + 0.003], abs=1e-6)
    assert [t for t, _ in e.cmds] == car([ref + 0.003], abs=1e-6) and e.end == car(ref + 0.005, abs=1e-6)
    assert e.trace.wall == car([ref, ref + 0.002], abs=1e-6) and e.trace.t == [0.0, 0.002]
    assert (e.killed_at, e.restarted) == (car(ref + 0.004, abs=1e-6), car(ref + 0.005, abs=1e-6))
    assert [e.bridge[k] for k in times] == car([ref, ref + 0.003, ref + 0.005], abs=1e-6)
    assert e.bridge["affected"] == 2  # counts are not times
