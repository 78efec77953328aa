"""The plausibility figures of a HIL run's summary, from synthetic traffic: when the first
plausibility fault was reported (from the command frames leading up to the status that says so),
in scenario time counted in yaw-rate frames, and how long after the sensor fault."""

from __future__ import annotations

import pytest

from firmware_py import model_regulator as mr
from mrsteer_dbc import names
from sim_plant.car import scenario as scn
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.harness.hil_plausibility import plausibility_figures

RATE = 500.0


def _traffic(fault_from: int | None, status_every: int = 50, steps: int = 400, plaus: int = names.PLAUS_YAW,
             wall_scale: float = 0.1) -> list[dict]:
    """One yaw frame and one command per step (a lockstep run whose wall clock runs at
    ``wall_scale`` of simulated time), a status every ``status_every`` steps; from step
    ``fault_from`` on the commands are FAULT and the statuses carry ``plaus``."""
    rows = []
    for k in range(steps):
        t = 1000.0 + k * wall_scale / RATE
        faulted = fault_from is not None and k >= fault_from
        rows.append({"t_s": t, "message": names.MSG_YAW, names.SIG_YAW_RATE: 0.0})
        rows.append({"t_s": t, "message": names.MSG_CMD,
                     names.SIG_CMD_STATE: mr.STATUS_FAULT if faulted else mr.STATUS_ACTIVE})
        if k % status_every == status_every - 1:
            rows.append({"t_s": t, "message": names.MSG_STATUS, names.SIG_STATUS_PLAUS: plaus if faulted else 0})
    return rows


def _scenario(start: float) -> scn.Scenario:
    return scn.load("side-wind").with_sensor_faults((SensorFault("yaw_rate", "stuck", start, 0.01),))


def test_detection_is_the_first_fault_command_before_the_status_in_scenario_time() -> None:
    fig = plausibility_figures(_traffic(fault_from=123), _scenario(0.1), RATE)
    assert fig["fault_detected_s"] == pytest.approx(123 / RATE)  # not the status frame's 149, nor wall time
    assert fig["detection_latency_s"] == pytest.approx(123 / RATE - 0.1)
    assert fig["bits_seen"] == names.PLAUS_YAW and fig["sensor_faults"] == ["yaw_rate:stuck:0.01@0.1"]


def test_fault_commands_for_another_reason_earlier_do_not_count() -> None:
    rows = _traffic(fault_from=200)
    for r in rows[:30]:  # FAULT at start-up (no inputs yet), then healthy
        if r["message"] == names.MSG_CMD:
            r[names.SIG_CMD_STATE] = mr.STATUS_FAULT
    fig = plausibility_figures(rows, _scenario(0.2), RATE)
    assert fig["fault_detected_s"] == pytest.approx(200 / RATE)


def test_a_clean_run_reports_nothing_and_degraded_is_its_own_figure() -> None:
    clean = plausibility_figures(_traffic(fault_from=None), scn.load("side-wind"), RATE)
    assert clean["fault_detected_s"] is None and clean["bits_seen"] == 0 and clean["detection_latency_s"] is None
    degraded = plausibility_figures(_traffic(fault_from=100, plaus=names.PLAUS_DEGRADED), scn.load("side-wind"), RATE)
    assert degraded["fault_detected_s"] is None  # DEGRADED is no fault
    assert degraded["first_degraded_s"] == pytest.approx(149 / RATE)
