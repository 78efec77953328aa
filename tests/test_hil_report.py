"""The HIL report without processes: joining the plant's steps with the controller's frames,
the per-step CSV, and the demo's wording."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

import mrsteer_dbc
from mrsteer_cli import hil_demo
from sim_plant.car import scenario as scn
from sim_plant.car.sensor_faults import parse_spec
from sim_plant.harness import hil_plot
from sim_plant.harness.hil_steps import Step, Traffic, read_steps_csv, step_table, steps_csv
from sim_plant.nodes.plant import PlantNode

RATE = 500.0
C = mrsteer_dbc.load()


def _yaw(t: float, counter: int) -> dict[str, Any]:
    return {"t_s": t, "message": "MRS_YawRate", "YawRate_YawRate": 0.01, "YawRate_Counter": counter}


def _cmd(t: float, meas: int, state: int, angle: float = -0.01) -> dict[str, Any]:
    return {"t_s": t, "message": "MRS_AuxSteerCmd", "AuxSteerCmd_Angle": angle, "AuxSteerCmd_MeasCounter": meas,
            "AuxSteerCmd_State": state}


def _status(t: float, cause: int) -> dict[str, Any]:
    return {"t_s": t, "message": "MRS_CtrlStatus", "CtrlStatus_Cause": cause}


def _trace(walls: list[float]) -> list[dict[str, float]]:
    return [{**dict.fromkeys(PlantNode.TRACE_COLUMNS, 0.0), "t_s": k / RATE, "wall_s": w} for k, w in enumerate(walls)]


# Three plant steps.  Step 1's answer (MeasCounter 1) is followed by a status frame and by a
# stray command for an older measurement; after the scenario the controller times out and
# sends zero commands a second later.
ROWS = [
    _yaw(10.0000, 0), _cmd(10.0003, 0, 1),
    _yaw(10.0020, 1), _cmd(10.0023, 1, 1), _status(10.00232, 0x08), _cmd(10.0024, 0, 3),
    _yaw(10.0040, 2), _cmd(10.0043, 2, 2),
    _cmd(11.0043, 2, 0, 0.0), _status(11.00432, 0x02), _cmd(11.0053, 2, 0, 0.0),
]
TRACE = _trace([10.0005, 10.0025, 10.0045])


def test_lockstep_steps_take_the_command_answering_their_measurement() -> None:
    steps = step_table(TRACE, Traffic.of(ROWS, RATE), lockstep=True, contract=C)
    assert [s.ctrl_state for s in steps] == ["ACTIVE", "ACTIVE", "SATURATED"]
    assert [s.ctrl_cause for s in steps] == [None, 0x08, 0x08]  # unknown before the first status


def test_realtime_steps_take_the_newest_command_when_the_plant_recorded_them() -> None:
    steps = step_table(TRACE, Traffic.of(ROWS, RATE), lockstep=False, contract=C)
    assert [s.ctrl_state for s in steps] == ["ACTIVE", "FAULT", "SATURATED"]  # the stray one, for step 1


def test_steps_csv_round_trips_with_microsecond_times(tmp_path: Path) -> None:
    steps = step_table(TRACE, Traffic.of(ROWS, RATE), lockstep=True, contract=C)
    (tmp_path / "steps.csv").write_bytes(steps_csv(steps))
    lines = (tmp_path / "steps.csv").read_text().splitlines()
    wall = lines[0].split(",").index("wall_s")
    assert lines[0].split(",")[:2] == ["t_s", "step"]  # scenario time first
    assert lines[1].split(",")[0] == "0" and lines[2].split(",")[0] == "0.002"
    assert lines[2].split(",")[wall] == "10.0025"
    assert read_steps_csv(tmp_path / "steps.csv") == steps


def _summary(peak: float, final: float, aux_final: float = 0.0) -> dict[str, Any]:
    return {"peak_yaw_rate_rad_s": peak, "final_yaw_rate_rad_s": final, "peak_aux_steer_deg": 2.45,
            "final_aux_steer_deg": aux_final, "m_z": 4000.0, "v": 20.0, "mu": 1.0, "mode": "lockstep",
            "rate_hz": 500.0}


def test_demo_wording_follows_the_scenarios_driver(tmp_path: Path) -> None:
    on, off = _summary(0.02, 0.005, -1.95), _summary(0.228, 0.223)
    held = hil_demo.explain(scn.load("paper-fig9"), on, off, 0.02, tmp_path)
    assert "wheel held" in held and "keeps up its -1.95 deg" in held and "91% less" in held
    assert "driver takes over" not in held and "reaction" not in held
    driven = hil_demo.explain(scn.load("handover"), on, off, 0.02, tmp_path)
    assert "1 s reaction time the driver steers against the rest" in driven and "wheel held" not in driven


def _faulty_steps(n: int = 50) -> list[Step]:
    """A run whose yaw-rate sensor sticks at 0.01 rad/s from step 25 while the car yaws at 0.02."""
    trace = [{**dict.fromkeys(PlantNode.TRACE_COLUMNS, 0.0), "t_s": k / RATE, "wall_s": 10.0 + k / RATE,
              "yaw_rate_rad_s": 0.02, "yaw_rate_measured_rad_s": 0.02 if k < 25 else 0.01,
              "lat_accel_m_s2": 0.5, "lat_accel_measured_m_s2": 0.5 + (k >= 25), "v_m_s": 20.0} for k in range(n)]
    return step_table(trace, Traffic.of([], RATE), lockstep=False, contract=C)


def test_the_plot_marks_a_sensor_fault_and_draws_its_reading_beside_the_truth() -> None:
    sc = scn.load("paper-fig9").with_sensor_faults((parse_spec("yaw_rate:stuck:0.01@0.05"),
                                                    parse_spec("lat_accel:bias:1@0.05")))
    marks = hil_plot.event_marks(sc)
    assert (0.05, "sensor fault: yaw_rate stuck 0.01") in marks and (0.05, "sensor fault: lat_accel bias 1") in marks
    assert marks == sorted(marks, key=lambda m: m[0]) and (0.5, "M_z 4000 Nm") in marks  # the scenario's own too
    steps = _faulty_steps()
    traces = hil_plot.sensor_traces(steps, sc.sensor_config.faults)
    yaw = [t for t in traces if t.axis == hil_plot.YAW]
    assert len(yaw) == 1 and yaw[0].faulty and yaw[0].values == [s.yaw_rate_measured_rad_s for s in steps]
    assert yaw[0].values[-1] == 0.01 and "yaw_rate stuck 0.01 from 0.05 s" in yaw[0].label
    lat = [t for t in traces if t.axis.startswith("lateral")]  # an axis of its own: the truth beside it
    assert [t.faulty for t in lat] == [False, True] and lat[0].values[-1] == 0.5 and lat[1].values[-1] == 1.5
    plt = hil_plot._pyplot()
    fig = hil_plot.run_figure(plt, steps, marks, "t", traces)
    try:
        top = fig.axes[0]
        assert any(list(line.get_ydata()) == yaw[0].values for line in top.get_lines())
        assert any(list(line.get_xdata()) == [0.05, 0.05] for line in top.get_lines())  # the onset's mark
        assert any(ax.get_ylabel() == lat[0].axis for ax in fig.axes)
    finally:
        plt.close(fig)


def test_a_run_without_sensor_faults_draws_no_reading() -> None:
    sc = scn.load("paper-fig9")
    assert hil_plot.sensor_traces(_faulty_steps(), sc.sensor_config.faults) == []
    assert not any(label.startswith("sensor fault") for _, label in hil_plot.event_marks(sc))


def test_steps_csv_writes_round_off_as_zero_and_keeps_nine_digits() -> None:
    step = replace(_faulty_steps(1)[0], aux_applied_rad=-1.16e-164, beta_rad=0.0123456789123, m_z_nm=4000.000000001)
    header, row = steps_csv([step]).decode().splitlines()
    cells = dict(zip(header.split(","), row.split(",")))
    assert cells["aux_applied_rad"] == "0" and cells["beta_rad"] == "0.0123456789" and cells["m_z_nm"] == "4000"


def test_car_figures_are_the_true_cars_up_to_a_spin_and_count_the_reported_saturated_state() -> None:
    """The figures a campaign has for its run (``campaign.engine.METRICS``): the true yaw rate's
    peak, the wrapped side slip's, the steps the controller *reported* SATURATED (not the steps
    the command sat at 3 deg: a faded command at the limit reports DEGRADED or FAULT), all of
    them up to the step whose side slip passed 30 deg (the car spun), which ``spun`` and
    ``spin_time_s`` name."""
    import math

    from firmware_py import model_regulator as mr
    from sim_plant.harness.hil_report import car_figures
    from sim_plant.harness.hil_steps import Step

    limit = mr.ControllerConfig().aux_limit

    def step(k: int, beta_deg: float, r: float, state: str, cmd: float) -> Step:
        return Step(step=k, t_s=k / RATE, driver_angle_rad=0.0, yaw_rate_rad_s=r, yaw_rate_measured_rad_s=min(r, 3.0),
                    v_m_s=20.0 - k, aux_cmd_rad=cmd, aux_applied_rad=cmd, ctrl_state=state, ctrl_cause=0, m_z_nm=0.0,
                    mu=0.5, beta_rad=math.radians(beta_deg), lat_accel_m_s2=0.0, wall_s=0.0)

    sc = scn.load("side-wind")
    calm = [step(0, 1.0, 0.1, "ACTIVE", 0.0), step(1, -5.0, -0.4, "SATURATED", limit),
            step(2, 4.0, 0.2, "FAULT", limit), step(3, 2.0, 0.3, "SATURATED", -limit)]
    f = car_figures(sc, calm)
    assert f["peak_yaw_rate_rad_s"] == 0.4 and f["peak_side_slip_deg"] == pytest.approx(5.0)
    assert f["time_at_limit_s"] == pytest.approx(2 / RATE)  # the two SATURATED steps, not the FAULT at 3 deg
    assert not f["spun"] and f["spin_time_s"] is None and f["final_speed_m_s"] == 17.0
    spin = calm[:3] + [step(3, 29.0, 1.5, "SATURATED", limit), step(4, 31.0, 2.0, "SATURATED", limit),
                       step(5, -170.0, 12.5, "SATURATED", limit)]  # beta past 180 deg reads wrapped
    f = car_figures(sc, spin)
    assert f["spun"] and f["spin_time_s"] == pytest.approx(4 / RATE)
    assert f["peak_yaw_rate_rad_s"] == 2.0 and f["peak_side_slip_deg"] == pytest.approx(31.0)
    assert f["time_at_limit_s"] == pytest.approx(3 / RATE) and f["final_speed_m_s"] == 16.0
