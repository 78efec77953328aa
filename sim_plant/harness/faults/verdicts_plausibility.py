"""The fault matrix's plausibility verdicts (issue 18): a sensor row's wrong value found, the
command faded and both latched; no alarm in a fault-free row.  Judged from the logged traffic
(``evidence``) like every other verdict (``verdicts.judge`` calls these).

A sensor row (``Row.plausibility`` set) must show, counted from when the fault's error left
the monitor's bound (for a step fault: its onset, the first falsified frame) -- a row whose bit
is DEGRADED (the lateral acceleration's: ``plausibility.OUTSIDE_MODEL``) the status's DEGRADED
within 300 ms plus its cycle instead, latched, every command from then on in state DEGRADED, and
the command faded to zero (``_check_degraded_row``):

* **detection**: the first ``MRS_AuxSteerCmd`` in state FAULT within ``PLAUS_DETECT`` (300 ms;
  in time (the car's, ``evidence.CarClock``) or in controller cycles, as the other rows count on
  a starved machine), or, if
  no command shows it, the first ``MRS_CtrlStatus`` with a fault bit in
  ``CtrlStatus_Plausibility`` within 300 ms plus its cycle (100 ms); or any time after the onset
  but before the error left its bound (early); nothing before the onset;
* **report**: the first status after that command with a fault bit, cause 0x80 and state FAULT,
  and the row's bit (the check watching the faulted signal) by the end;
* **fade**: the command back at exactly zero within ``|u at detection| / PLAUS_FADE`` (30 deg/s)
  plus two cycles (counted in commands on the bus, as the limiter fades once a period), never
  growing on the way;
* **latched**: every later command FAULT at zero, every later status still reporting it, to the
  run's end; the fault window still open when the fade ended.

The error is the falsified signal on the controller's bus less the same frame's value on the
vehicle's (the bridge forwards each frame once, in order, so the n-th frames pair up; a fault
the plant injects, under ``--secoc``, is measured less true in the plant's trace), against
the bound ``judge.bounds.sensor_bound`` states: the yaw rate's ``yaw_bound +
yaw_rel |r|`` (r: the vehicle's yaw-rate frame), the lateral acceleration's the same times v
plus ``side_accel`` when the car has the yaw-rate sensor's second element, a
steering channel's ``steer_bound``, the yaw-rate sensor's second element's ``yaw_pair_bound``
(``PlausibilityConfig``'s defaults, as the controller runs), either speed's the speed pair's
``speed_pair_bound`` at the true speed when the car has the second speed; else the jump check's
``speed_step`` (``row_bound``).
It counts as left the bound when it stays over it for 300 ms or until the fault is reported.
"""

from __future__ import annotations

import bisect
import math

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.plausibility import PLAUS_DEGRADED, PLAUS_FAULT, PlausibilityConfig
from mrsteer_dbc import names
from sim_plant.harness.faults.caused_yaw import caused_yaw
from sim_plant.harness.faults.evidence import Evidence, stall_gaps, stalled
from sim_plant.car.sensors import DBC_SIGNALS
from sim_plant.harness.hil_plausibility import latched_degraded
from sim_plant.harness.faults.settings import BUS_RESOLUTION, PLAUS_DETECT, PLAUS_FADE, STATUS_CYCLE
from sim_plant.nodes.candump_log import Frame
from sim_plant.judge.bounds import sensor_bound
from sim_plant.judge.caused_yaw import CAUSED_YAW_TARGET
from sim_plant.judge.detection import ErrorSample, exceeded_at

_MISSING = names.CAUSE_STEER_MISSING | names.CAUSE_YAW_MISSING | names.CAUSE_SPEED_MISSING

def _series(frames: list[Frame], name: str, *signals: str) -> list[list[tuple[float, float]]]:
    """Each of ``signals`` of the message ``name`` as (t, value), decoded once per frame."""
    c = mrsteer_dbc.load()
    fid = c.frame_id(name)
    out: list[list[tuple[float, float]]] = [[] for _ in signals]
    for t, f, data in frames:
        if f == fid and (d := c.decode(f, data)) is not None:
            for series, signal in zip(out, signals):
                series.append((t, float(d.signals[signal])))
    return out


def _values(frames: list[Frame], name: str, signal: str) -> list[tuple[float, float]]:
    return _series(frames, name, signal)[0]


def _latest(series: list[tuple[float, float]], times: list[float], t: float, default: float) -> float:
    i = bisect.bisect_right(times, t) - 1
    return series[i][1] if i >= 0 else default


#: A signal's (measured, true) columns in the plant's trace.
_TRACE_COLUMNS = {names.SIG_YAW_RATE: ("yaw_rate_measured_rad_s", "yaw_rate_rad_s"),
                  names.SIG_STEER_ANGLE: ("steer_measured_rad", "driver_angle_rad"),
                  names.SIG_LAT_ACCEL: ("lat_accel_measured_m_s2", "lat_accel_m_s2"),
                  names.SIG_STEER_ANGLE_2: ("steer_redundant_measured_rad", "driver_angle_rad"),
                  names.SIG_YAW_RATE_2: ("yaw_rate_redundant_measured_rad_s", "yaw_rate_rad_s"),
                  names.SIG_SPEED: ("speed_measured_m_s", "v_m_s"),
                  names.SIG_SPEED_2: ("speed_redundant_measured_m_s", "v_m_s")}


#: The sensor (``sensor_bound``'s name) each falsified signal carries.
_SENSOR = {signal: sensor for sensor, (_, signal) in DBC_SIGNALS.items()}


def onset(e: Evidence) -> float | None:
    """When the fault first made a value wrong (epoch s): the bridge's first falsified frame, or
    for a fault the plant injects, the first plant step at its start (the trace's wall clock), both as the car's time (``evidence.CarClock``)."""
    if not e.row.at_plant:
        return e.bridge["first_affected"]
    tr = e.trace
    return next((w for t, w in zip(tr.t, tr.wall) if t >= e.row.fault.start - 1e-9), None)


def row_bound(sensor: str, cfg: PlausibilityConfig, r: float, v: float, pair: bool,
              speed_pair: bool = False) -> float:
    """``sensor_bound``; for a speed on a car without the second speed (``speed_pair`` False),
    which has no bound on its error, the largest change the jump check lets pass between two
    samples (``speed_step``), which bounds only a step fault's error (without the pair a
    drifting speed has no error bound outside a steady turn: docs/decisions/0006-speed-checks.md)."""
    if sensor in ("speed", "speed_redundant") and not speed_pair:
        return cfg.speed_step
    return float(sensor_bound(sensor, cfg, r, v, pair, speed_pair))


def error_series(e: Evidence, cfg: PlausibilityConfig = PlausibilityConfig()) -> list[ErrorSample]:
    """The falsified signal's error and its bound (``row_bound``) at each frame the controller got
    (for a fault the plant injects: at each plant step, measured less true, from its trace)."""
    fault = e.row.fault
    signal = fault.signal or names.SENSOR_SIGNAL[fault.target]
    sensor = _SENSOR[signal]
    if e.row.at_plant:
        cols = e.trace.columns
        measured, true = (cols[c] for c in _TRACE_COLUMNS[signal])
        pair = signal == names.SIG_LAT_ACCEL and any(
            math.isfinite(x) for x in cols.get(_TRACE_COLUMNS[names.SIG_YAW_RATE_2][0], ()))
        speed_pair = any(math.isfinite(x) for x in cols.get(_TRACE_COLUMNS[names.SIG_SPEED_2][0], ()))
        return [(w, m - x, row_bound(sensor, cfg, r, v, pair, speed_pair)) for w, m, x, r, v in
                zip(e.trace.wall, measured, true, cols["yaw_rate_rad_s"], cols["v_m_s"])]
    truth = _values(e.vehicle_frames, fault.target, signal)
    seen = _values(e.frames, fault.target, signal)
    yaw, yaw2 = _series(e.vehicle_frames, names.MSG_YAW, names.SIG_YAW_RATE, names.SIG_YAW_RATE_2)
    speed = _values(e.vehicle_frames, names.MSG_SPEED, names.SIG_SPEED)
    yaw_t, speed_t = [t for t, _ in yaw], [t for t, _ in speed]
    pair = signal == names.SIG_LAT_ACCEL and any(math.isfinite(x) for _, x in yaw2)
    speed_pair = any(math.isfinite(x) for _, x in _values(e.vehicle_frames, names.MSG_REDUNDANT, names.SIG_SPEED_2))
    return [(tc, got - x, row_bound(sensor, cfg, _latest(yaw, yaw_t, tv, 0.0), _latest(speed, speed_t, tv, 0.0), pair,
                                    speed_pair))
            for (tv, x), (tc, got) in zip(truth, seen)]


def check_quiet_monitor(e: Evidence, fails: list[str], observed: list[str]) -> None:
    """A fault-free row: no status ever reports a plausibility fault, nor DEGRADED in every
    status of its last 0.3 s or more (latched: OUTSIDE_MODEL; a stalled machine's missing frame
    comes and goes)."""
    if not e.row.no_fault:
        return
    alarms = [s for s in e.statuses if s.plausibility & PLAUS_FAULT]
    # DEGRADED to the end is the monitor's latched OUTSIDE_MODEL (a missing frame's comes and goes)
    since = latched_degraded([(s.t, s.plausibility) for s in e.statuses], e.statuses[0].t) if e.statuses else None
    latched = since is not None and e.statuses[-1].t - since >= 0.3
    if alarms:
        fails.append(f"false plausibility alarm: {len(alarms)} status frames with bits "
                 f"{sorted({s.plausibility for s in alarms})}, first {alarms[0].t - e.statuses[0].t:.2f} s in")
    elif latched:
        fails.append(f"false plausibility alarm: DEGRADED latched from {since - e.statuses[0].t:.2f} s in "
                     f"to the end (the monitor's OUTSIDE_MODEL)")
    else:
        degraded = sum(1 for s in e.statuses if s.plausibility)
        observed.append("monitor quiet" + (f" ({degraded} status frames degraded)" if degraded else ""))


def _first_fault(e: Evidence, start: float) -> tuple[float | None, float | None, list[str]]:
    """The latched FAULT (the first command of the FAULT run that lasts to the end, else the
    first FAULT) and the first status reporting a plausibility fault, at or after ``start``;
    and what says the monitor did not latch or alarmed early.  A FAULT explained by a machine
    stall (an input timed out) is no plausibility fault."""
    fails = []
    if any(s.t < start and s.plausibility & PLAUS_FAULT for s in e.statuses):
        fails.append("plausibility fault reported before the fault's onset")
    after = [(t, s) for t, s in e.cmds if t >= start]
    i = len(after)
    while i > 0 and after[i - 1][1] == mr.STATUS_FAULT:
        i -= 1
    t_latch = after[i][0] if i < len(after) else None
    found = stall_gaps(e)
    episodes = [t for t, s in after[:i] if s == mr.STATUS_FAULT and not stalled(t, found)]
    if episodes:
        fails.append(f"not latched: FAULT {1e3 * (episodes[0] - start):.0f} ms after onset, then not")
    t_cmd = episodes[0] if episodes else t_latch
    t_st = next((s.t for s in e.statuses if s.t >= start and s.plausibility & PLAUS_FAULT), None)
    return t_cmd, t_st, fails


def check_plausibility(e: Evidence, fails: list[str], observed: list[str]) -> int | None:
    """A sensor row: detection, report, fade and latch (the module's docstring), then the yaw
    rate its command caused, detected or not (``judge_caused_yaw``).  Returns the detection in
    controller cycles from the error leaving its bound (``None``: not a sensor row, or not
    detected)."""
    if not e.row.plausibility:
        return None
    start = onset(e)
    cycles = _check_sensor_row(e, start, fails, observed)
    if start is not None:
        judge_caused_yaw(e, start, fails, observed)
    return cycles


def _check_sensor_row(e: Evidence, start: float | None, fails: list[str], observed: list[str]) -> int | None:
    ts = e.setup.ts
    if start is None:
        fails.append("the fault never hit a frame")
        return None
    if e.row.plausibility == PLAUS_DEGRADED:
        return _check_degraded_row(e, start, fails, observed)
    t_cmd, t_st, early = _first_fault(e, start)
    fails.extend(early)
    series = error_series(e)
    worst = max((abs(err) / bound for _, err, bound in series if _ >= start), default=0.0)
    seen = [t_ for t_ in (t_cmd, t_st) if t_ is not None]
    t_det = min(seen) if seen else None
    over = exceeded_at([s for s in series if s[0] >= start], t_det)
    if t_det is None:
        fails.append("no plausibility fault reported" + ("" if over is not None else
                     f" (the error reached {worst:.2f} of its bound: the row does not test the monitor)"))
        return None
    ref = over if over is not None else start  # counted from the onset when reported before that
    if over is not None:
        observed.append(f"error over its bound {1e3 * (ref - start):.0f} ms after onset (peak {worst:.1f}x)")
    else:
        # Early: say how large the error was then, so that a report the fault cannot explain
        # (another disturbance tripped the monitor) shows.
        then = max((abs(err) / bound for t_, err, bound in series if start <= t_ <= t_det), default=0.0)
        observed.append(f"reported before the error stayed over its bound (it was {then:.2f}x of it), so after "
                        f"the onset:")
    # The command shows the state every cycle: it is the measure, in time or, as the other
    # rows count (a starved controller runs its cycles late), in its cycles.  Only without it
    # does the status (every STATUS_CYCLE) count, with its cycle allowed.
    cycles = None if t_cmd is None else sum(1 for t_, _ in e.cmds if ref <= t_ <= t_cmd)
    cmd_ok = t_cmd is not None and (t_cmd - ref <= PLAUS_DETECT + 2 * ts or
                                    cycles is not None and cycles <= math.ceil(PLAUS_DETECT / ts - 1e-9) + 2)
    st_ok = t_cmd is None and t_st is not None and t_st - ref <= PLAUS_DETECT + STATUS_CYCLE + 2 * ts
    shown = "; ".join(f"{what} {1e3 * (t_ - ref):.0f} ms" for what, t_ in (("FAULT", t_cmd), ("status", t_st))
                      if t_ is not None)
    observed.append(shown + " after" + ("" if cycles is None else f" ({cycles} cycles)"))
    if (trouble := redundancy_trouble(e, start, t_det)) is not None:
        observed.append(trouble)
    if over is None:
        pass  # reported before the error left its bound (a growing error, a frozen value): early
    elif not (cmd_ok or st_ok):
        fails.append(f"plausibility fault reported late ({shown}; allowed {1e3 * PLAUS_DETECT:.0f} ms)")
    elif t_cmd is not None and t_cmd - ref > PLAUS_DETECT + 2 * ts:
        observed.append(f"late in time only: the controller ran {cycles} cycles in {1e3 * (t_cmd - ref):.0f} ms")
    check_report(e, fails, t_cmd, t_st)
    if t_cmd is None:
        fails.append("no command ever in state FAULT")
        return None
    check_fade(e, fails, observed, t_cmd)
    return cycles


def _check_degraded_row(e: Evidence, start: float, fails: list[str], observed: list[str]) -> int | None:
    """A row whose report is DEGRADED (a lateral acceleration that disagrees with the yaw rate
    its second element confirms: ``plausibility.OUTSIDE_MODEL``): the first status with the bit
    within 300 ms plus its cycle of the error leaving its bound, every later status with it, no
    plausibility bit before the onset (but in the leading statuses that name a missing input:
    a node started ahead of the plant), and the redundant frame arriving on its cycle over the
    status's cycle before the report (else the DEGRADED may be a missing frame's, which the
    bus does not tell apart); the command faded as on a fault (from the status's cycle before
    it, where the monitor may have tripped) and at zero to the end."""
    ts = e.setup.ts
    # The leading statuses that name a missing input were sent before the plant's first frames (a
    # node started ahead of it): their DEGRADED is the missing inputs', which their cause says.
    first = next((i for i, s in enumerate(e.statuses) if not s.cause & _MISSING), len(e.statuses))
    if any(s.t < start and s.plausibility for s in e.statuses[first:]):
        fails.append("plausibility bits reported before the fault's onset")
    t_st = next((s.t for s in e.statuses if s.t >= start and s.plausibility & PLAUS_DEGRADED), None)
    series = [x for x in error_series(e) if x[0] >= start]
    over = exceeded_at(series, t_st)
    if t_st is None:
        fails.append("no status frame reported DEGRADED")
        return None
    gap, cycle = redundant_gap(e, max(start, t_st - STATUS_CYCLE), t_st)
    if gap > 1.5 * cycle:
        fails.append(f"the redundant frame had a {1e3 * gap:.0f} ms gap before the DEGRADED status: "
                     f"a missing input's DEGRADED, not the monitor's report")
    ref = over if over is not None else start
    observed.append(f"DEGRADED in the status {1e3 * (t_st - ref):.0f} ms after "
                    + ("its error left the bound" if over is not None else "the onset (before the error left it)"))
    if over is not None and t_st - ref > PLAUS_DETECT + STATUS_CYCLE + 2 * ts:
        fails.append(f"DEGRADED reported late ({1e3 * (t_st - ref):.0f} ms; allowed "
                     f"{1e3 * (PLAUS_DETECT + STATUS_CYCLE):.0f} ms with the status's cycle)")
    after = [s for s in e.statuses if s.t >= t_st]
    if lost := [s for s in after if not s.plausibility & PLAUS_DEGRADED]:
        fails.append(f"{len(lost)} of {len(after)} status frames after the report lack DEGRADED")
    # On the wire, every period: the command's state DEGRADED from the status's cycle before the
    # report (where the monitor may have tripped) to the end (FAULT too, should a fault follow).
    t_cmd = next((t_ for t_, s in e.cmds if t_ >= max(start, t_st - STATUS_CYCLE) and s == mr.STATUS_DEGRADED), None)
    if t_cmd is None:
        fails.append("no command in state DEGRADED")
    else:
        observed.append(f"DEGRADED on the command {1e3 * (t_cmd - ref):.0f} ms after")
        if wrong := [s for t_, s in e.cmds if t_ >= t_st and s not in (mr.STATUS_DEGRADED, mr.STATUS_FAULT)]:
            fails.append(f"{len(wrong)} commands after the report not DEGRADED (first state {int(wrong[0])})")
    if faults := sorted({s.plausibility for s in after if s.plausibility & PLAUS_FAULT}):
        observed.append(f"fault bits too: {faults}")
    window = [abs(a) for t_, a in e.angles if t_st - STATUS_CYCLE <= t_ < t_st] or [0.0]
    allowed = math.ceil(max(window) / (PLAUS_FADE * ts) - 1e-9) + 2
    later = [(t_, abs(a)) for t_, a in e.angles if t_ >= t_st]
    i_zero = next((i for i, (_, m) in enumerate(later) if m <= BUS_RESOLUTION / 2), None)
    if i_zero is None or any(m > BUS_RESOLUTION / 2 for _, m in later[i_zero:]):
        fails.append("the command did not fade to zero and stay there after DEGRADED")
    elif i_zero > allowed:
        fails.append(f"the command reached zero {i_zero} cycles after the status, allowed {allowed}")
    else:
        observed.append(f"command at zero {i_zero} cycles after the status (allowed {allowed})")
    return round((t_st - ref) / ts)


def judge_caused_yaw(e: Evidence, start: float, fails: list[str], observed: list[str]) -> None:
    """The yaw rate the row's command caused (``caused_yaw``) against issue 18's target, judged
    on every sensor row at every rate: the yaw-rate pair finds a yaw-rate fault within a few
    cycles, and a steering channel that sticks or jumps holds the law's command (the steering
    pair's suspicion) until the pair judges it at the next 50 ms redundant frame (offline, every
    onset phase, the curve's angle stuck at 0: 0.0000 rad/s at 100, 200 and 500 Hz, against
    0.074, 0.106 and 0.028 without the suspicion).  A row whose figure cannot be estimated
    says why."""
    caused = caused_yaw(e, start)
    if caused.value is None:
        observed.append(f"caused yaw not estimated: {caused.reason}")
        return
    met = "met" if caused.value <= CAUSED_YAW_TARGET else "NOT met"
    observed.append(f"the command caused at most {caused.value:.4f} rad/s of yaw (target {CAUSED_YAW_TARGET:g}: {met})")
    if caused.value > CAUSED_YAW_TARGET:
        fails.append(f"the command caused {caused.value:.4f} rad/s of yaw, over issue 18's {CAUSED_YAW_TARGET:g}")


def redundancy_trouble(e: Evidence, start: float, until: float) -> str | None:
    """What the redundant frame did between the onset and the report when it could have slowed
    the detection (a sample missing costs the kinematic check 50 ms, a long gap a window):
    status frames DEGRADED (a sample withheld or timed out) and its largest gap on the
    controller's bus over 1.5 of its cycles; ``None`` when neither happened."""
    gap, cycle = redundant_gap(e, start, until)
    degraded = sum(1 for s in e.statuses if start <= s.t <= until and s.plausibility & PLAUS_DEGRADED)
    if not degraded and gap <= 1.5 * cycle:
        return None
    return f"redundant frame before the report: {degraded} status frames DEGRADED, largest gap {1e3 * gap:.0f} ms"


def redundant_gap(e: Evidence, start: float, until: float) -> tuple[float, float]:
    """(the largest gap between ``MRS_RedundantSensors`` frames on the controller's bus from
    ``start`` to ``until``, the ends counting as frames; the frame's cycle), in s."""
    c = mrsteer_dbc.load()
    cycle = c.cycle_time_s(names.MSG_REDUNDANT, e.setup.ts) or e.setup.ts
    fid = c.frame_id(names.MSG_REDUNDANT)
    times = [start] + [t for t, f, _ in e.frames if f == fid and start < t <= until] + [until]
    return max(b - a for a, b in zip(times, times[1:])), cycle


def check_report(e: Evidence, fails: list[str], t_cmd: float | None, t_st: float | None) -> None:
    """The status: the row's bit, cause 0x80 and FAULT, soon after the command, then to the end."""
    row = e.row
    if t_st is None:
        fails.append("no status frame reported the plausibility fault")
        return
    # Counted in frames, not time: the first status sent after the first FAULT command.
    first_after = next((s for s in e.statuses if t_cmd is not None and s.t >= t_cmd), None)
    if first_after is not None and first_after.t < t_st:
        fails.append(f"the first status after the FAULT command did not report it "
                     f"(it came {1e3 * (t_st - first_after.t):.0f} ms later)")
    after = [s for s in e.statuses if s.t >= t_st]
    wrong = [s for s in after if not (s.plausibility & PLAUS_FAULT and s.cause & names.CAUSE_PLAUSIBILITY
                                      and s.state == mr.STATUS_FAULT)]
    if wrong:
        s = wrong[0]
        fails.append(f"{len(wrong)} of {len(after)} status frames after the report lack a fault bit, cause 0x80 "
                     f"or FAULT (first: bits {s.plausibility}, cause 0x{s.cause:02X}, state {s.state})")
    # Another check may trip first (a stuck steering angle also moves the model's yaw rate),
    # but the one that watches the faulted signal must trip too: it says which sensor it was.
    if not any(s.plausibility & row.plausibility for s in after):
        bits = sorted({s.plausibility for s in after})
        fails.append(f"the status never gave bit 0x{row.plausibility:X} (saw {bits})")


def check_fade(e: Evidence, fails: list[str], observed: list[str], t_cmd: float) -> None:
    """The command faded to exactly zero at the limiter's rate, then held there in FAULT."""
    ts = e.setup.ts
    before = [abs(a) for t_, a in e.angles if t_ < t_cmd]
    after = [(t_, a) for t_, a in e.angles if t_ >= t_cmd]
    u_det = max(([before[-1]] if before else []) + ([abs(after[0][1])] if after else []), default=0.0)
    allowed = math.ceil(u_det / (PLAUS_FADE * ts) - 1e-9) + 2
    mags = [abs(a) for _, a in after]
    if any(b > a + 2e-6 for a, b in zip(mags, mags[1:])):
        fails.append("the command grew after the plausibility fault")
    i_zero = next((i for i, m in enumerate(mags) if m <= BUS_RESOLUTION / 2), None)
    if i_zero is None:
        fails.append(f"the command never reached zero (from {math.degrees(u_det):.2f} deg)")
        return
    t_zero = after[i_zero][0]
    observed.append(f"faded {math.degrees(u_det):.2f} deg to 0 in {i_zero} cycles, {1e3 * (t_zero - t_cmd):.0f} ms "
                    f"(allowed {allowed} cycles)")
    if i_zero > allowed:
        fails.append(f"faded in {i_zero} cycles, allowed {allowed} ({math.degrees(u_det):.2f} deg at "
                     f"{math.degrees(PLAUS_FADE):g} deg/s)")
    if any(m > BUS_RESOLUTION / 2 for m in mags[i_zero:]):
        fails.append("the command left zero again after the fade")
    last = e.end if e.row.at_plant else e.bridge["last_affected"]  # the plant's fault lasts to the end
    if last is None or last < t_zero:
        fails.append("the fault window ended before the fade did: the latch is not shown")
    else:
        observed.append(f"latched for {e.end - t_zero:.2f} s to the end")
