"""The fault matrix's rows: each a fault the bridge injects (or a process the runner kills) and
what the row must show, judged from the logged traffic (``judge``).  ``secured_rows`` gives
the same rows as ``faults run --secoc`` runs them.

The sensor rows (``SENSOR_ROWS``, issue 18) put a wrong value in well-formed frames; the
plausibility monitor must find it, fade the command and latch (``verdicts_plausibility``).
Their windows are in scenario time and last to the run's end: the fault latches until restart,
so they expect no recovery."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from mrsteer_dbc import names
from sim_plant.harness.faults.settings import (CURVE, E2E_FAIL_MAX, FORGED_ANGLE, PLAUS_DURATION, PLAUS_START,
                                               SCENARIO, TIMEOUT_CYCLES, WINDOW)
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.nodes.fault_bridge import SENSOR_KINDS, Fault


# The recovery verdict's failures: the command never back, or back and then faded to the end.
NOT_RECOVERED = "did not recover after the fault"
NOT_KEPT = "did not stay recovered"


@dataclass(frozen=True)
class Known:
    """A defect a row is known to show, kept in sight rather than hidden: the failures it gives
    (their first words) and why.  The row's result is KNOWN when every failure it has is one of
    these."""

    failures: tuple[str, ...]
    why: str


# An input missing for the fault window during paper-fig9's disturbance: the command is faded
# meanwhile, the car yaws with the disturbance (0.2 rad/s at 20 m/s), and when the input is back
# the kinematic check, the yaw rate confirmed by its second element, latches OUTSIDE_MODEL within
# 40 ms: the command fades again, to the end of the ignition cycle (at 100 Hz before a first
# ACTIVE command, at 500 Hz 40 ms after it).
OUTSIDE_MODEL_AFTER_OUTAGE = Known((NOT_RECOVERED, NOT_KEPT),
                                   "known defect (issue 53): OUTSIDE_MODEL latches when the input comes back "
                                   "while the car, uncontrolled during the outage, yaws with the disturbance")


@dataclass(frozen=True)
class Row:
    """One row: its fault, what the table says it must show, and the verdicts that apply."""

    name: str
    fault: Fault
    expected: str
    detect_within: int | None = None  # controller cycles from the first affected frame to FAULT
    cause: int = 0  # CtrlStatus_Cause bit expected while faulted
    no_fault: bool = False  # the controller must stay ACTIVE/SATURATED throughout
    reject_all: bool = False  # the controller rejects (at least) every affected frame
    plant_rejects: bool = False  # the plant must reject the affected command frames
    kill: bool = False  # the runner kills the controller (SIGKILL) ...
    restart: bool = False  # ... and restarts it
    kill_plant: bool = False  # the runner kills the plant (SIGKILL) and restarts it
    secoc: bool = False  # controller and plant authenticate the commands and the sensor frames
    auth_rejects: bool = False  # the plant's SecOC check must reject the affected command frames
    e2e_only: bool = False  # shows what E2E alone lets through: meaningless with SecOC on
    scenario: str = SCENARIO  # the plant's scenario: paper-fig9, or CURVE (settings.CURVE_SCENARIO)
    duration: float | None = None  # s of scenario; None: settings.DURATION
    # Sensor rows: the CtrlStatus_Plausibility bit the monitor must report (PLAUS_YAW or
    # PLAUS_STEER, with cause 0x80; PLAUS_DEGRADED for the lateral acceleration), the command
    # faded to zero and both latched to the end.
    plausibility: int = 0
    at_plant: bool = False  # the plant injects the sensor fault (``plant_fault``), not the bridge
    known: Known | None = None  # a known defect the row shows


def _f(kind: str, target: str = "MRS_YawRate", param: float = 1.0) -> Fault:
    return Fault(kind, target, *WINDOW, param)


ROWS = (
    Row("baseline", _f("none"), "runs clean", no_fault=True),
    Row("yaw-rate frames lost (burst)", _f("drop"), "FAULT within the timeout, fade, recover",
        detect_within=TIMEOUT_CYCLES + 2, cause=names.CAUSE_YAW_MISSING, known=OUTSIDE_MODEL_AFTER_OUTAGE),
    Row("sensor frames lost (20 % random)", _f("drop", "sensors", 0.2), "tolerated, no fault", no_fault=True),
    Row("yaw-rate payload bit flipped", _f("corrupt_payload"), "rejected (CRC), FAULT after 3, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=names.CAUSE_E2E, reject_all=True,
        known=OUTSIDE_MODEL_AFTER_OUTAGE),
    Row("yaw-rate CRC corrupted", _f("corrupt_crc"), "rejected, FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=names.CAUSE_E2E, reject_all=True,
        known=OUTSIDE_MODEL_AFTER_OUTAGE),
    Row("yaw-rate counter invalid (15)", _f("corrupt_counter"), "rejected, FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=names.CAUSE_E2E, reject_all=True,
        known=OUTSIDE_MODEL_AFTER_OUTAGE),
    Row("driver-angle frame too short", _f("wrong_length", "MRS_DriverSteer"), "rejected, FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=names.CAUSE_E2E, reject_all=True,
        known=OUTSIDE_MODEL_AFTER_OUTAGE),
    Row("yaw-rate frames replayed", _f("replay", param=1.0), "every replayed frame rejected, no fault",
        no_fault=True, reject_all=True),
    Row("yaw rate out of range (3.2 rad/s)", _f("out_of_range", param=3.2), "rejected (range), FAULT, recover",
        detect_within=E2E_FAIL_MAX + 2, cause=names.CAUSE_RANGE, reject_all=True,
        known=OUTSIDE_MODEL_AFTER_OUTAGE),
    Row("sensor frames duplicated", _f("duplicate", "sensors"), "copies rejected as repeated, no fault",
        no_fault=True, reject_all=True),
    Row("yaw-rate frames reordered", _f("reorder"), "out-of-order frames rejected, no fault", no_fault=True),
    Row("sensor frames delayed 4 ms", _f("delay", "sensors", 0.004), "tolerated, no fault", no_fault=True),
    Row("bus flooded with another ID", _f("flood", param=5000.0), "filtered out, no fault, nothing lost",
        no_fault=True),
    Row("command frames lost (burst)", _f("drop", "commands"), "actuator times out, fades, slews back"),
    Row("command CRC corrupted", _f("corrupt_crc", "commands"), "actuator rejects them", plant_rejects=True),
    # The same forger without SecOC: E2E alone takes it (docs/faults.md, "E2E is not security");
    # the actuator's own +-3 deg still bounds what it does.
    Row("commands forged, E2E only", _f("spoof_command", "commands", FORGED_ANGLE),
        "forgeries taken, actuator within 3 deg", e2e_only=True),
    Row("SecOC: baseline", _f("none"), "runs clean, every frame authenticated", no_fault=True, secoc=True),
    # The forger sends the next alive counter with a valid CRC: E2E alone would take it.
    Row("SecOC: commands forged", _f("spoof_command", "commands", FORGED_ANGLE),
        "forgeries rejected (MAC), real ones kept", secoc=True, auth_rejects=True),
    # 13 back lands 2 ahead of the 4-bit alive counter: E2E alone takes every replay and rejects
    # the live frames instead (docs/faults.md); the sensor frames' MAC must refuse them.
    Row("SecOC: yaw-rate replayed 13 back", _f("replay", param=13.0), "every replay rejected (MAC), no fault",
        no_fault=True, reject_all=True, secoc=True),
    # 150 frames (0.3 s) back: counter-aligned, so E2E alone would take them (docs/faults.md).
    Row("SecOC: 0.3 s old commands substituted", _f("substitute", "commands", 150.0),
        "stale freshness rejected, fade, slew back", secoc=True, auth_rejects=True),
    Row("controller killed", _f("none"), "actuator at zero within timeout + fade", kill=True),
    Row("controller killed and restarted", _f("none"), "resumes without a jump", kill=True, restart=True),
    # The vehicle side crashes: every input goes missing at once, then comes back from a fresh
    # plant (its counters from 0, its scenario from the start).
    Row("plant killed and restarted", _f("none"), "FAULT within the timeout, fade, recover",
        detect_within=TIMEOUT_CYCLES + 2, cause=names.CAUSE_YAW_MISSING, kill_plant=True),
)


def _sensor(name: str, kind: str, target: str, param: float, plaus: int, expected: str, *,
            signal: str | None = None, start: float = PLAUS_START, duration: float = PLAUS_DURATION,
            scenario: str = SCENARIO) -> Row:
    """A sensor row: the fault from ``start`` to the run's end (scenario time)."""
    return Row(name, Fault(kind, target, start, duration, param, signal), expected, scenario=scenario,
               duration=duration, plausibility=plaus)


_LATCH = "fade, latch"
_YAW, _STEER = names.PLAUS_YAW, names.PLAUS_STEER
#: The sensor rows.  paper-fig9 from 1.0 s: the car in its steady state (r 0.020 rad/s, a_y
#: 0.41 m/s^2, aux -1.81 deg) with the driver's wheel held straight; the curve: r 0.168 rad/s.
SENSOR_ROWS = (
    _sensor("yaw rate stuck at 0.01 rad/s", "sensor_stuck", names.MSG_YAW, 0.01, _YAW,
            f"FAULT <= 300 ms, {_LATCH}"),
    _sensor("yaw-rate offset +3 deg/s", "sensor_bias", names.MSG_YAW, math.radians(3.0), _YAW,
            f"FAULT <= 300 ms, {_LATCH}"),
    # 1 deg/s per s leaves the 2 deg/s bound after about 2 s: the target counts from then.
    _sensor("yaw-rate drift 1 deg/s per s", "sensor_drift", names.MSG_YAW, math.radians(1.0), _YAW,
            f"FAULT <= 300 ms past bound, {_LATCH}", duration=4.2),
    # During the yaw moment's transient, so that the truth moves away from the held value.
    _sensor("yaw rate frozen (value, counter runs)", "sensor_frozen", names.MSG_YAW, 0.0, _YAW,
            f"FAULT <= 300 ms past bound, {_LATCH}", start=0.55),
    # paper-fig9's driver holds the wheel straight: an angle stuck at 0 would be the truth.
    _sensor("wheel held, angle stuck at 0.57 deg", "sensor_stuck", names.MSG_STEER, 0.01, _STEER,
            f"FAULT <= 300 ms, {_LATCH}"),
    # +2: the bound is 0.74 m/s^2 here plus side_accel 0.6 (the car has the second yaw-rate element,
    # which confirms the yaw rate: the disagreement is the lateral acceleration's, DEGRADED)
    _sensor("lateral acceleration offset +2 m/s^2", "sensor_bias", names.MSG_REDUNDANT, 2.0, names.PLAUS_DEGRADED,
            f"DEGRADED <= 300+100 ms, {_LATCH}", signal=names.SIG_LAT_ACCEL),
    Row("baseline, driver steers into a curve", Fault("none", names.MSG_YAW, *WINDOW, 1.0),
        "no plausibility alarm", no_fault=True, scenario=CURVE, duration=PLAUS_DURATION),
    _sensor("curve: driver angle stuck at 0", "sensor_stuck", names.MSG_STEER, 0.0, _STEER,
            f"steering: FAULT <= 300 ms, {_LATCH}", scenario=CURVE),
    _sensor("curve: steering channel 2 stuck at 0", "sensor_stuck", names.MSG_REDUNDANT, 0.0, _STEER,
            f"FAULT <= 300 ms, {_LATCH}", signal=names.SIG_STEER_ANGLE_2, scenario=CURVE),
    _sensor("curve: yaw-rate gain 1.5", "sensor_scale", names.MSG_YAW, 1.5, _YAW,
            f"FAULT <= 300 ms, {_LATCH}", scenario=CURVE),
    _sensor("curve: yaw-rate gain 0.5", "sensor_scale", names.MSG_YAW, 0.5, _YAW,
            f"FAULT <= 300 ms, {_LATCH}", scenario=CURVE),
    # A speed the car cannot have changed to: the jump check finds it at its onset.  Where the
    # driver steers the law follows K_n(v) of the wrong speed; reported as the yaw rate's bit.
    _sensor("curve: speed gain 0.5", "sensor_scale", names.MSG_SPEED, 0.5, _YAW,
            f"FAULT <= 300 ms, {_LATCH}", scenario=CURVE),
    # A drift never jumps: the speed pair (the car's second speed) finds it once it has carried
    # the reading past 1.0 m/s + 5 % (2 m/s here, 1 s after the onset).
    _sensor("curve: speed drift -2 m/s per s", "sensor_drift", names.MSG_SPEED, -2.0, _YAW,
            f"FAULT <= 300 ms past bound, {_LATCH}", scenario=CURVE, duration=3.4),
    # The element the law does not use: only the pair check can see it.
    _sensor("curve: yaw-rate element 2 stuck at 0", "sensor_stuck", names.MSG_YAW, 0.0, _YAW,
            f"FAULT <= 300 ms, {_LATCH}", signal=names.SIG_YAW_RATE_2, scenario=CURVE),
)

ROWS = ROWS + SENSOR_ROWS


#: ``faults run --quick``: one row of each kind (clean, a bus fault, a sensor fault) as a smoke run.
QUICK_ROWS = ("baseline", "yaw-rate frames lost (burst)", "yaw rate stuck at 0.01 rad/s")

#: The bridge's sensor-fault kinds as the plant's (``sim_plant.car.sensor_faults``).
_PLANT_KIND = {"sensor_stuck": "stuck", "sensor_frozen": "frozen", "sensor_bias": "bias", "sensor_scale": "scale",
               "sensor_drift": "drift", "sensor_noise": "noise"}
_PLANT_SENSOR = {(names.MSG_YAW, None): "yaw_rate", (names.MSG_YAW, names.SIG_YAW_RATE): "yaw_rate",
                 (names.MSG_STEER, None): "steer", (names.MSG_STEER, names.SIG_STEER_ANGLE): "steer",
                 (names.MSG_SPEED, None): "speed", (names.MSG_SPEED, names.SIG_SPEED): "speed",
                 (names.MSG_REDUNDANT, names.SIG_LAT_ACCEL): "lat_accel",
                 (names.MSG_REDUNDANT, names.SIG_STEER_ANGLE_2): "steer_redundant",
                 (names.MSG_YAW, names.SIG_YAW_RATE_2): "yaw_rate_redundant",
                 (names.MSG_REDUNDANT, names.SIG_SPEED_2): "speed_redundant"}


def plant_fault(row: Row) -> SensorFault | None:
    """The row's sensor fault as the plant injects it (``at_plant`` rows): the same sensor,
    kind, value and onset (scenario time), lasting to the end; ``None`` for any other row."""
    f = row.fault
    if not row.at_plant:
        return None
    kind = _PLANT_KIND[f.kind]
    return SensorFault(_PLANT_SENSOR[(f.target, f.signal)], kind, f.start, None if kind == "frozen" else f.param)


def secured_rows(rows: tuple[Row, ...] = ROWS) -> tuple[Row, ...]:
    """The rows as they run with SecOC on (``faults run --secoc``): every row authenticates,
    the E2E-only rows are left out, and a row that became the same run as an earlier one (the
    baseline and "SecOC: baseline") appears once.  The sensor rows' faults move into the plant:
    the bridge cannot give a frame it falsifies a valid MAC (SecOC would refuse it, and the row
    would test SecOC, not the monitor); the plant signs what its faulty sensor measures."""
    out: list[Row] = []
    seen: set[Row] = set()
    for row in rows:
        if row.e2e_only:
            continue
        row = replace(row, secoc=True, at_plant=row.fault.kind in SENSOR_KINDS)
        key = replace(row, name="", expected="")
        if key not in seen:
            seen.add(key)
            out.append(row)
    return tuple(out)
