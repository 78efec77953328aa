"""What a HIL run's logged traffic says about the plausibility monitor (issue 18): which bits the
controller reported, when it first reported a plausibility fault (``fault_detected_s``) or the
degraded state (``first_degraded_s``; ``latched_degraded_s``: from the sensor fault's onset on,
in every status to the end, as OUTSIDE_MODEL's is and a missing input's is not, timed from the
first of the DEGRADED commands leading up to its first status when they began at or after the
onset), the earlier of the fault and the latched degraded state (``reported_s``, ``reported_as``:
issue 18's report), how long after the scenario's first sensor fault that was, and where the
command was at the end.  Part of ``summary.json``.

The detection time is read from the command frames, which come every control period: the first
of the unbroken run of FAULT commands that leads up to the first ``MRS_CtrlStatus`` with a
plausibility fault bit (``CtrlStatus_Plausibility`` 1 or 2; the status frame itself comes only
every 100 ms); ``first_degraded_s`` likewise the first of the run of DEGRADED commands that leads
up to the first status with the degraded bit (4), or that status's time when the command there
was not DEGRADED (a FAULT outranks it).  The plant's trace also gives when the faulted
sensor's error (its reading less the same sensor's without the fault, at the trace's true values: the fault's own; plus the
healthy sensors' biases its check sees with it, ``judge.bounds.check_offset``) first
exceeded the bound the monitor checks it against, the moment from which issue 18
counts its 300 ms (``error_over_bound_s``; ``yaw_error_over_bound_s`` the same for a yaw-rate
fault): for the yaw rate the kinematic check's ``yaw_bound``, or the yaw-rate pair's
``yaw_pair_bound`` when the car has the sensor's second element (a stuck element is found as its
error passes 0.03 rad/s, and may never reach the kinematic 0.035); for the lateral acceleration
the kinematic bound times v, plus ``side_accel`` when the car has the second element; for a
steering channel ``steer_bound``; for the second yaw-rate element ``yaw_pair_bound``; for either
speed the speed pair's ``speed_pair_bound + speed_pair_rel v`` when the car has the second speed
(plus ``speed_slip_rel v`` in a step where the car slows at ``speed_brake_decel`` or near it: the
braked wheels' slip, which the second speed reads and the monitor allows; the second speed's
own error is against the braked wheels' speed), else none (the speed's other checks look at its
jumps, ``speed_step``, and in a steady turn at a_y / r over half-second blocks, ``CHECK_TURN``,
not at its error); none of these while the
true speed is below the monitor's ``speed_min`` (5 m/s: its checks pause, the law is off).
Times are the scenario's, counted in yaw-rate frames (one per plant step): in lockstep the log's
wall-clock stamps are not simulated time."""

from __future__ import annotations

import math
from typing import Any

from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from mrsteer_dbc import names
from sim_plant.car import scenario as scn
from sim_plant.car.disturbances import sum_loads
from sim_plant.car.sensors import Sensors, dormant_faults
from sim_plant.harness.hil_steps import Step
from sim_plant.judge.bounds import check_offset, is_braking, sensor_bound

_FAULT_BITS = names.PLAUS_YAW | names.PLAUS_STEER


def plausibility_figures(rows: list[dict[str, Any]], sc: scn.Scenario, rate_hz: float,
                         steps: list[Step] | None = None) -> dict[str, Any]:
    """The ``plausibility`` entry of a run's summary, from its decoded frames (``hil_report.decode``),
    times in s of the scenario (the k-th yaw-rate frame is sent at (k - 1) / ``rate_hz``)."""
    ts = 1.0 / rate_hz
    seen = 0
    yaw_frames = 0
    degraded_s: float | None = None
    run_start: float | None = None  # the current unbroken run of FAULT commands began here
    degraded_run: float | None = None  # the current unbroken run of DEGRADED commands began here
    detected_s: float | None = None
    statuses: list[tuple[float, int]] = []
    degraded_since: dict[float, float] = {}  # a status's time: where the DEGRADED commands leading to it began
    for r in rows:
        msg = r["message"]
        if msg == names.MSG_YAW:
            yaw_frames += 1
        elif msg == names.MSG_CMD and names.SIG_CMD_STATE in r and yaw_frames:
            state = int(r[names.SIG_CMD_STATE])
            t = (yaw_frames - 1) * ts
            run_start = (run_start if run_start is not None else t) if state == mr.STATUS_FAULT else None
            degraded_run = (degraded_run if degraded_run is not None else t) if state == mr.STATUS_DEGRADED else None
        elif msg == names.MSG_STATUS and names.SIG_STATUS_PLAUS in r and yaw_frames:
            bits = int(r[names.SIG_STATUS_PLAUS])
            statuses.append(((yaw_frames - 1) * ts, bits))
            if degraded_run is not None:
                degraded_since[(yaw_frames - 1) * ts] = degraded_run
            seen |= bits
            if bits & names.PLAUS_DEGRADED and degraded_s is None:
                degraded_s = degraded_run if degraded_run is not None else (yaw_frames - 1) * ts
            if bits & _FAULT_BITS and detected_s is None:
                detected_s = run_start if run_start is not None else (yaw_frames - 1) * ts
    onset = min((f.start for f in sc.sensor_config.faults), default=None)
    over = error_over_bound(steps, sc, 1.0 / rate_hz) if steps and sc.sensor_config.faults else None
    # Issue 18's report is the fault or the degraded state, whichever came first: a lateral
    # acceleration that disagrees with a yaw rate its second element confirms is DEGRADED
    # (plausibility.OUTSIDE_MODEL), as is a car past its grip.  Only the latched DEGRADED counts
    # (in every status from there to the end, from the sensor fault's onset on): a missing
    # input's comes and goes.
    latched = latched_degraded(statuses, onset or 0.0)
    if latched is not None and degraded_since.get(latched, -math.inf) >= (onset or 0.0):
        latched = degraded_since[latched]  # the command said it first (every period; the status every 100 ms)
    reported = min((t for t in (detected_s, latched) if t is not None), default=None)
    return {
        "bits_seen": seen,
        "fault_detected_s": detected_s,
        "first_degraded_s": degraded_s,
        "reported_s": reported,
        "reported_as": None if reported is None else "fault" if reported == detected_s else "degraded",
        "latched_degraded_s": latched,
        "sensor_fault_onset_s": onset,
        "detection_latency_s": None if reported is None or onset is None else reported - onset,
        "error_over_bound_s": over,
        "yaw_error_over_bound_s": over if any(f.sensor == "yaw_rate" for f in sc.sensor_config.faults) else None,
        "latency_from_bound_s": None if reported is None or over is None else reported - over,
        "sensor_faults": [f"{f.sensor}:{f.kind}" + ("" if f.value is None else f":{f.value:g}") + f"@{f.start:g}"
                          for f in sc.sensor_config.faults],
    }


def latched_degraded(statuses: list[tuple[float, int]], start: float) -> float | None:
    """The first of ``statuses`` ((t, CtrlStatus_Plausibility), in order) at or after ``start``
    from which every status to the end reports DEGRADED; None if the last does not."""
    first = None
    for t, bits in reversed(statuses):
        if t < start or not bits & names.PLAUS_DEGRADED:
            break
        first = t
    return first


def error_over_bound(steps: list[Step], sc: scn.Scenario, ts: float) -> float | None:
    """When the scenario's first sensor fault's error first exceeded the bound the monitor checks
    it against (the module's docstring); None if it never did, or for a fault of the speed on a
    car without the second speed (its check then bounds its jumps, not its error; with it, the
    speed pair's ``speed_pair_bound``).  The error is the fault's own: the reading the plant sent
    less what the same sensor (its noise, filter, quantisation and bias; ``sensors.dormant_faults``)
    reads of the trace's true value at each step of ``ts`` s without the fault, plus the healthy
    sensors' offsets its check sees with it (``judge.bounds.check_offset``: the yaw rate's
    by the pair's when the car has the second element).  A sensor's filter lag in a fast
    transient, or its noise, is not the fault's."""
    cfg = pl.PlausibilityConfig()
    first = min(sc.sensor_config.faults, key=lambda f: f.start)
    sensor = first.sensor
    pair = sc.sensor_config.yaw_rate_redundant_present and not any(
        f.sensor == "yaw_rate_redundant" for f in sc.sensor_config.faults)
    speed_pair = sc.sensor_config.speed_redundant_present

    def bound(s: Step, v_before: float) -> float:
        if sensor == "yaw_rate":  # the constant bounds of the module's docstring
            if s.v_m_s < cfg.speed_min:
                return math.inf
            return min(cfg.yaw_bound, cfg.yaw_pair_bound) if pair else cfg.yaw_bound
        braking = is_braking(v_before, s.v_m_s, ts, cfg)
        return float(sensor_bound(sensor, cfg, s.yaw_rate_rad_s, s.v_m_s, pair, speed_pair, braking))

    if sensor in ("speed", "speed_redundant") and not speed_pair:
        return None
    measured, truth = _READINGS[sensor]
    clean = Sensors(dormant_faults(sc.sensor_config), ts)
    read = getattr(clean, sensor)
    v_before = steps[0].v_m_s if steps else 0.0
    disturbances = sc.disturbances  # (a property that builds its tuple each time)
    bias = sc.sensor_config.biases()
    for s in steps:
        clean.at(s.t_s)
        true_value = getattr(s, truth)
        if sensor == "speed_redundant":  # the second speed reads the braked wheels, slip and all
            true_value *= 1.0 - sum_loads(disturbances, s.t_s).wheel_slip
        offset = check_offset(sensor, bias, s.v_m_s, s.t_s >= first.start, by_pair=pair)
        if abs(getattr(s, measured) - read(true_value) + offset) > bound(s, v_before):
            return s.t_s
        v_before = s.v_m_s
    return None


#: Each sensor's reading in a step (``Step``'s field) and the true value the sensor measures.
_READINGS = {"yaw_rate": ("yaw_rate_measured_rad_s", "yaw_rate_rad_s"),
             "yaw_rate_redundant": ("yaw_rate_redundant_measured_rad_s", "yaw_rate_rad_s"),
             "lat_accel": ("lat_accel_measured_m_s2", "lat_accel_m_s2"),
             "steer": ("steer_measured_rad", "driver_angle_rad"),
             "steer_redundant": ("steer_redundant_measured_rad", "driver_angle_rad"),
             "speed": ("speed_measured_m_s", "v_m_s"),
             "speed_redundant": ("speed_redundant_measured_m_s", "v_m_s")}
