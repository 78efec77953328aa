"""The fault matrix's verdicts (the judge): one row's run, judged from what was logged
(``evidence``).

``judge`` runs every check in turn; each adds what it observed and any failure to the row's
``Verdict``.  Every row is judged safe (``check_applied``, ``check_command_rate``), with nothing
lost (``check_nothing_lost``) and, unless the row kills it, a controller alive to the end
(``check_alive``); the row's flags select the others: no fault, detection and recovery, the
command's fade while the plant is down, rejected frames, SecOC's MAC counts, forgeries, and
the actuator's fade after a controller crash.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import mrsteer_dbc
from firmware_py import model_regulator as mr
from mrsteer_dbc import secoc
from mrsteer_dbc.e2e import COUNTER_MODULO
from mrsteer_dbc import names
from sim_plant.harness.faults.evidence import STATISTICS, Evidence, gather, stalled, stall_gaps
from sim_plant.harness.faults.rows import NOT_KEPT, NOT_RECOVERED, Row
from sim_plant.harness.faults.verdicts_plausibility import check_plausibility, check_quiet_monitor
from sim_plant.harness.hil_steps import state_names
from sim_plant.harness.faults.settings import (ACTUATOR_RATE, BUS_RESOLUTION, COUNTER_WINDOW, E2E_FAIL_MAX,
                                               CUT_RATE, FLOOD_CAPACITY, FORGED_ANGLE, MAC_LUCK, PLANT_FADE,
                                               RATE_LIMIT, TRACE_RESOLUTION, Setup)
from sim_plant.nodes.candump_log import Frame


# The states after a recovery that mean the function is off again.
LOST_STATES = (mr.STATUS_FAULT, mr.STATUS_DEGRADED)


@dataclass
class RowResult:
    name: str
    expected: str
    passed: bool
    observed: str
    worst_applied_deg: float
    worst_step_deg: float
    detection_cycles: int | None
    failures: list[str] = field(default_factory=list)
    known: str = ""  # why, when every failure is the row's known defect (``rows.Known``)

    @property
    def ok(self) -> bool:
        """Passed, or failed only as its known defect: what the matrix's exit status counts."""
        return self.passed or bool(self.known)


@dataclass
class Verdict:
    """What the checks found, in the order they ran."""

    fails: list[str] = field(default_factory=list)
    observed: list[str] = field(default_factory=list)


def judge(row: Row, work: Path, ctl_code: int | None, killed_at: float | None,
          restarted: float | None, setup: Setup = Setup()) -> RowResult:
    missing = [name for name in STATISTICS if not (work / name).exists()]
    if missing:
        # The row cannot be judged; the matrix goes on with the next.  A process that hung at
        # SIGTERM was killed (processes.stop) after writing its threads' stacks to its stderr.
        return RowResult(row.name, row.expected, False, "", 0.0, 0.0, None, [
            f"no {', '.join(missing)} in {work}: a process died, or did not exit after SIGTERM and was "
            f"killed (then its stderr file there has every thread's stack)"])
    e = gather(row, work, ctl_code, killed_at, restarted, setup)
    v = Verdict()
    worst, worst_step = check_applied(e, v)
    check_nothing_lost(e, v)
    check_alive(e, v)
    check_command_rate(e, v)
    check_no_fault(e, v)
    check_quiet_monitor(e, v.fails, v.observed)
    affected0, affected1 = outage(e)
    detection, first_fault = check_detection(e, v, affected0, affected1)
    plausibility = check_plausibility(e, v.fails, v.observed)
    check_fade_while_plant_down(e, v, first_fault, affected1)
    check_rejections(e, v)
    check_secoc(e, v)
    check_forgery(e, v)
    check_controller_kill(e, v)
    return RowResult(row.name, row.expected, not v.fails, "; ".join(v.observed), math.degrees(worst),
                     math.degrees(worst_step), detection if plausibility is None else plausibility, v.fails,
                     known_defect(row, v.fails))


def known_defect(row: Row, fails: list[str]) -> str:
    """Why the row failed, when it failed only as its known defect; else ""."""
    if row.known is None or not fails or not all(f.startswith(row.known.failures) for f in fails):
        return ""
    return row.known.why


def check_applied(e: Evidence, v: Verdict) -> tuple[float, float]:
    """The applied angle within the limit, never faster than the actuator's slew: the largest
    angle and step, in rad."""
    applied, ts = e.trace.applied, e.setup.ts
    limit = mr.ControllerConfig().aux_limit
    worst = max(abs(a) for a in applied)
    steps = [abs(b - a) for a, b in zip(applied, applied[1:])]
    worst_step = max(steps) if steps else 0.0
    if worst > limit + BUS_RESOLUTION:  # the command travels rounded to the DBC's 1e-6 rad
        v.fails.append(f"applied {math.degrees(worst):.3f} deg beyond the limit")
    # The actuator (the plant, standing in for its ECU) limits its own slew to ACTUATOR_RATE
    # whatever arrives; this checks that it does, step by step, faults and crashes included.
    # The trace holds 9 significant digits: a step at exactly the limit may read up to ~1e-9 rad over.
    if worst_step > max(ACTUATOR_RATE, PLANT_FADE) * ts + TRACE_RESOLUTION:
        v.fails.append(f"applied angle jumped {math.degrees(worst_step):.4f} deg in one step")
    return worst, worst_step


def check_nothing_lost(e: Evidence, v: Verdict) -> None:
    """Each logger logged every frame on its bus, as the bridge counted them."""
    c, bridge, plant = mrsteer_dbc.load(), e.bridge, e.plant
    plant_tx = plant["tx_frames"]
    if e.row.kill_plant and e.restarted is not None:
        # The killed plant wrote no statistics: its frames are the ones its logger saw.
        own = {c.frame_id(n) for n in (*names.VEHICLE_SENSORS, secoc.SYNC)}  # every frame the plant sends
        plant_tx += sum(1 for t_, fid, _ in e.vehicle_frames if fid in own and t_ < e.restarted)
        v.observed.append("applied angle judged on the restarted plant's trace")
    logged = e.logged
    on_a = bridge["seen_on_vehicle"] + bridge["forwarded_to_vehicle"] + bridge["injected_to_vehicle"]
    on_b = bridge["seen_on_controller"] + bridge["forwarded_to_controller"] + bridge["injected_to_controller"]
    if logged["vehicle"] != on_a or logged["controller"] != on_b:
        v.fails.append(f"logger lost frames: vehicle {logged['vehicle']}/{on_a}, controller {logged['controller']}/{on_b}")
    if bridge["seen_on_vehicle"] != plant_tx:
        v.fails.append(f"bridge saw {bridge['seen_on_vehicle']} of the plant's {plant_tx} frames")
    v.observed.append(f"logged {logged['vehicle']}+{logged['controller']} frames, none lost")
    if plant["overruns"] > 0.1 * plant["steps"]:
        # Every check still holds, but the closed loop's shape is not the one a 100 % on-time
        # plant gives: say so next to the result.
        v.observed.append(f"machine too slow: plant late in {plant['overruns']}/{plant['steps']} steps")


def check_alive(e: Evidence, v: Verdict) -> None:
    """Unless the row kills it, the controller ran to the end, exited cleanly and reported."""
    if not e.row.kill:
        if e.ctl_code != 0:
            v.fails.append(f"controller exit status {e.ctl_code}")
        if e.ctl_stats is None:
            v.fails.append("controller wrote no statistics")


def check_command_rate(e: Evidence, v: Verdict) -> None:
    # The controller's own commands respect its rate limit, faults and restarts included
    # (bus resolution 1e-6 rad); across a kill the next instance starts again from zero.
    # Per controller cycle, counted by the commands' alive counter: a command the log's decode
    # does not accept (around a SecOC epoch change) leaves two cycles between its neighbours.
    # Fifteen or more missing in a row alias to fewer (the counter runs 0..14), which only makes
    # the check stricter there.
    # One exception, by design: a command in FAULT moving toward zero may move at the authority
    # limiter's rate bound, which is how the limiter removes a command a pair check (yaw rate or
    # steering) found wrong while it was still building (authority_step's cut); the actuator's own slew
    # limit still bounds the wheels (the applied-angle checks).
    killed_at, restarted = e.killed_at, e.restarted
    steps = zip(e.angles, e.angles[1:], e.cmd_counters, e.cmd_counters[1:], e.cmds[1:])
    for (ta, a), (tb, b), ca, cb, (_, state) in steps:
        crash = killed_at is not None and ta <= killed_at and (restarted is None or tb >= restarted)
        cycles = max(1, (cb - ca) % COUNTER_MODULO)
        cut = state == mr.STATUS_FAULT and a * b >= 0.0 and abs(b) <= abs(a)
        rate = CUT_RATE if cut else RATE_LIMIT
        if not crash and abs(b - a) > cycles * rate * e.setup.ts + 2e-6:
            v.fails.append(f"command stepped {math.degrees(abs(b - a)):.4f} deg in one cycle")
            break


def check_no_fault(e: Evidence, v: Verdict) -> None:
    """A row that must not fault: every FAULT explained by a machine stall."""
    if not (e.row.no_fault and e.faults_after):
        return
    # A FAULT is the right answer when the machine stalled the plant past the timeout: judge
    # only those without such a gap in the sensor frames the controller was given.
    found = stall_gaps(e)
    unexplained = [t_ for t_ in e.faults_after if not stalled(t_, found)]
    if unexplained:
        v.fails.append(f"controller faulted without a cause {len(unexplained)} times")
    else:
        v.observed.append(f"{len(found)} sensor gap(s) from machine stalls, each detected")


def outage(e: Evidence) -> tuple[float | None, float | None]:
    """When the fault hit the controller's inputs, first to last (epoch s)."""
    affected0, affected1 = e.bridge["first_affected"], e.bridge["last_affected"]
    if e.row.kill_plant and e.killed_at is not None:
        c, ts = mrsteer_dbc.load(), e.setup.ts
        # The outage, as the controller saw it: from when the dead plant's next yaw-rate frame
        # was due to the restarted plant's first one.  The dead plant's last frame is the last
        # before the restart, not before the kill: a frame it sent just before dying can reach
        # the bus after the kill on a loaded machine, and the controller's timeout runs from it.
        yaws = [t_ for t_, fid, _ in e.frames if fid == c.frame_id(names.MSG_YAW)]
        end = e.restarted if e.restarted is not None else float("inf")
        last = max((t_ for t_ in yaws if t_ < end), default=None)
        affected0 = None if last is None else last + (c.cycle_time_s(names.MSG_YAW, ts) or ts)
        affected1 = min((t_ for t_ in yaws if e.restarted is not None and t_ >= e.restarted), default=e.killed_at)
    return affected0, affected1


def faulted_after_bad_frames(frames: list[Frame], cmds: list[tuple[float, float]], row: Row,
                             first_affected: float, first_fault: float) -> bool:
    """The controller's own rule, for rejected-frame faults: FAULT in the first cycle after
    the ``E2E_FAIL_MAX``-th bad frame reached its bus (or the next, if that frame came while
    the cycle was under way).  Detection in cycles equals this when frames come once a cycle;
    when the machine stalls the sender, the cycles run on without frames and the count grows.
    ``frames`` are the controller bus's, ``cmds`` its commands (time first), ``first_affected``
    when the fault first hit a frame."""
    c = mrsteer_dbc.load()
    ids = {c.frame_id(n) for n in row.fault.targets()}
    bad = [t_ for t_, fid, _ in frames if fid in ids and t_ >= first_affected]
    if len(bad) < E2E_FAIL_MAX:
        return False
    nth = bad[E2E_FAIL_MAX - 1]
    return sum(1 for t_, _ in cmds if nth < t_ < first_fault) <= 1


def off_to_the_end(cmds: list[tuple[float, float]]) -> tuple[float, float] | None:
    """The first command (t, state) of the run of FAULT or DEGRADED commands that ends the log,
    ``None`` when the last command is in another state."""
    first = None
    for t_, state in reversed(cmds):
        if state not in LOST_STATES:
            break
        first = (t_, state)
    return first


def check_detection(e: Evidence, v: Verdict, affected0: float | None,
                    affected1: float | None) -> tuple[int | None, float | None]:
    """A row that must fault: FAULT within its cycles, with its cause, then recovery.  The
    detection in controller cycles and the first FAULT's time (``None`` if none)."""
    row, cmds = e.row, e.cmds
    if row.detect_within is None:
        return None, None
    if affected0 is None:
        v.fails.append("the fault never hit a frame")
        return None, None
    detection = None
    first_fault = next((t_ for t_ in e.faults_after if t_ >= affected0), None)
    if first_fault is None:
        v.fails.append("fault not detected")
    else:
        detection = sum(1 for t_, _ in cmds if affected0 <= t_ <= first_fault)
        v.observed.append(f"FAULT after {detection} cycles")
        if detection > row.detect_within:
            stalled = row.reject_all and faulted_after_bad_frames(e.frames, cmds, row, e.bridge["first_affected"],
                                                                  first_fault)
            if stalled:
                v.observed.append(f"bad frames came slower than cycles (machine stall); FAULT in the cycle "
                                  f"after the {E2E_FAIL_MAX}th")
            else:
                v.fails.append(f"detected after {detection} cycles, allowed {row.detect_within}")
        seen = [cause for t_, cause in e.causes if first_fault <= t_ <= affected1 + 0.05]
        if row.cause and not any(cause & row.cause for cause in seen):
            v.fails.append(f"status never gave cause 0x{row.cause:02X} (saw {sorted(set(seen))})")
    back = next((t_ for t_, s in cmds if t_ > affected1 and s in (mr.STATUS_ACTIVE, mr.STATUS_SATURATED)), None)
    if back is None:
        v.fails.append(NOT_RECOVERED)
    else:
        v.observed.append(f"recovered {1e3 * (back - affected1):.0f} ms after")
        # Recovered means for good: FAULT or DEGRADED from some command to the last (a latched
        # monitor's) is the function off, however briefly it was ACTIVE before.  A missing
        # frame's DEGRADED comes and goes.
        lost = off_to_the_end([(t_, s) for t_, s in cmds if t_ > back])
        if lost is not None:
            v.fails.append(f"{NOT_KEPT}: {state_names()[int(lost[1])]} from {1e3 * (lost[0] - affected1):.0f} ms "
                           f"after the fault to the end")
    return detection, first_fault


def check_fade_while_plant_down(e: Evidence, v: Verdict, first_fault: float | None, affected1: float | None) -> None:
    if not (e.row.kill_plant and first_fault is not None):
        return
    # With every input gone the controller fades its command: it never grows meanwhile.
    fading = [abs(a) for t_, a in e.angles if first_fault <= t_ <= affected1]
    if any(b > a + 2e-6 for a, b in zip(fading, fading[1:])):
        v.fails.append("the command grew while the inputs were missing")
    elif fading:
        v.observed.append(f"command faded {math.degrees(fading[0]):.2f}° to {math.degrees(fading[-1]):.2f}° "
                          f"while the plant was down")


def check_rejections(e: Evidence, v: Verdict) -> None:
    """Frames refused by the controller (every bad one, no foreign one let in) and by the plant;
    the flood's rate."""
    row, bridge, plant, ctl_stats = e.row, e.bridge, e.plant, e.ctl_stats
    if (row.fault.kind != "none" and not row.at_plant and not bridge["affected"] and row.detect_within is None
            and not row.plausibility):
        v.fails.append("the fault never hit a frame")  # the rows that must fault say so themselves
    if ctl_stats is not None:
        rejected = ctl_stats["rx_rejected"]
        v.observed.append(f"controller rejected {rejected}")
        if row.reject_all and rejected < bridge["affected"]:
            v.fails.append(f"controller rejected {rejected} of {bridge['affected']} bad frames")
        if ctl_stats["rx_ignored"]:
            v.fails.append(f"{ctl_stats['rx_ignored']} foreign frames reached the controller process")
    if row.fault.kind == "flood":
        rate = bridge["injected_to_controller"] / ((row.fault.stop - row.fault.start) * e.setup.time_scale)
        # The bus's load is a wall-time figure: in slow motion the flood is that much thinner.
        wall = rate / e.setup.slow_motion
        slow = "" if e.setup.slow_motion == 1.0 else f" of the car's time ({wall:.0f} per wall second)"
        v.observed.append(f"flood {rate:.0f} frames/s{slow}, {100.0 * wall / FLOOD_CAPACITY:.0f} % of a 500 kbit/s bus")
    if row.plant_rejects:
        if plant["cmd_rejected"] < bridge["affected"]:
            v.fails.append(f"plant rejected {plant['cmd_rejected']} of {bridge['affected']} corrupted commands")
        v.observed.append(f"plant rejected {plant['cmd_rejected']}")


def check_secoc(e: Evidence, v: Verdict) -> None:
    """SecOC rows: the MAC failures on both sides; replays refused by the MAC itself; the
    plant refusing every bad command but a lucky few."""
    row, bridge, plant, ctl_stats = e.row, e.bridge, e.plant, e.ctl_stats
    if row.secoc:
        # Real commands fail too: in flight with the old epoch when the actuator restarts, and
        # when they reach it an epoch too late (a stalled machine).  Both are right; shown, not
        # judged.  (Before its first sync the controller sends none.)
        v.observed.append(f"plant: {plant['cmd_auth_failed']} failed SecOC")
        if ctl_stats is not None:
            sensor_failed = ctl_stats.get("rx_auth_failed", 0)
            unsynced = ctl_stats.get("rx_unsynced", 0)
            v.observed.append(f"controller: {sensor_failed} sensor frames failed SecOC"
                              + (f", {unsynced} unverifiable before its first sync" if unsynced else ""))
            # With E2E alone an aliased replay is accepted and the live frame rejected instead, so
            # the count of rejections proves nothing here: the MAC must be what refused them.
            # (Corrupted frames are refused earlier, by their CRC, length or range.)
            if row.fault.kind == "replay" and sensor_failed < bridge["affected"]:
                v.fails.append(f"the controller's SecOC refused {sensor_failed} of {bridge['affected']} "
                               f"replayed frames")
    if row.auth_rejects:
        failed = plant["cmd_auth_failed"]
        if failed < bridge["affected"] - MAC_LUCK:
            v.fails.append(f"plant's SecOC rejected {failed} of {bridge['affected']} bad commands")


def check_forgery(e: Evidence, v: Verdict) -> None:
    """Forged commands: with SecOC the actuator takes none (but a lucky few) and keeps the real
    ones; with E2E alone it takes them."""
    row, bridge, plant, held = e.row, e.bridge, e.plant, e.trace.held
    if row.fault.kind != "spoof_command":
        return
    if row.secoc:
        # Each forgery the actuator took would show as its marker angle in the held command.
        taken = sum(1 for a, b in zip([0.0, *held], held) if abs(b - FORGED_ANGLE) < 5e-7 <= abs(a - FORGED_ANGLE))
        v.observed.append(f"{taken} of {bridge['affected']} forgeries taken")
        if taken > MAC_LUCK:
            v.fails.append(f"the actuator took {taken} forged commands")
        # Authentication comes before the counter check, so forgeries cannot push the real
        # commands out of the alive-counter sequence.
        # Real commands that fail authentication (an epoch late when the machine stalls) leave
        # gaps in the sequence the actuator saw, and a gap wider than the counter window (3)
        # costs the next command: only those are allowed.
        e2e_rejected = plant["cmd_rejected"] - plant["cmd_auth_failed"]
        real_lost = max(0, plant["cmd_auth_failed"] - bridge["affected"])
        allowed = MAC_LUCK + real_lost // (COUNTER_WINDOW + 1)
        if e2e_rejected > allowed:
            v.fails.append(f"{e2e_rejected} real commands rejected by the counter check after forgeries "
                           f"({allowed} explained by {real_lost} real commands that failed SecOC)")
    else:
        # Without SecOC the same forger must get through (else the SecOC row proves nothing);
        # the actuator's own range still holds (the "safe" check above).
        steps = sum(1 for b in held if abs(b - FORGED_ANGLE) < 5e-7)
        v.observed.append(f"the actuator held a forged command in {steps} steps; real ones pushed out of sequence: "
                          f"{plant['cmd_rejected']}")
        if steps == 0:
            v.fails.append("no forgery was taken: the forger is not the threat the SecOC row claims to stop")


def check_controller_kill(e: Evidence, v: Verdict) -> None:
    """A killed controller: the actuator at zero within its timeout and fade; a restarted one
    active again."""
    row, killed_at, restarted = e.row, e.killed_at, e.restarted
    if not (row.kill and killed_at is not None):
        return
    t, applied, wall, ts = e.trace.t, e.trace.applied, e.trace.wall, e.setup.ts
    cmd_id = mrsteer_dbc.load().frame_id(names.MSG_CMD)
    # The actuator's timeout runs from the last command it was given: the dead controller's
    # last one as it reached the vehicle's bus (the bridge forwards in order, and late when
    # the machine stalls it).
    sent = sum(1 for t_, fid, _ in e.frames if fid == cmd_id and t_ <= killed_at)
    delivered = [t_ for t_, fid, _ in e.vehicle_frames if fid == cmd_id]
    last_cmd = delivered[sent - 1] if 0 < sent <= len(delivered) else killed_at
    # The step that first ran after that command was on the bus: a plant that lags the wall
    # clock (a slow machine) gets there late, and its timeout counts its own steps from there.
    i_kill = next((i for i, w in enumerate(wall) if w >= last_cmd), len(t) - 1)
    a_kill = abs(applied[i_kill])
    # A lagging actuator's position follows the faded command to zero asymptotically: "at zero"
    # is then within the DBC's command resolution, after its settling time (docs/faults.md).
    tol, settle = e.setup.settling(a_kill)
    allowed = e.setup.cmd_timeout + a_kill / PLANT_FADE + 3 * ts + 0.05 + settle
    i_zero = next((i for i in range(i_kill, len(t)) if abs(applied[i]) <= tol), None)
    end = next((t[i] for i, w in enumerate(wall) if w >= restarted), t[-1]) if restarted is not None else t[-1]
    if i_zero is None or t[i_zero] - t[i_kill] > allowed or t[i_zero] > end:
        v.fails.append(f"actuator not at zero within {allowed * 1e3:.0f} ms of the controller's death")
    else:
        v.observed.append(f"actuator at 0 {1e3 * (t[i_zero] - t[i_kill]):.0f} ms after the last command")
    if row.restart:
        back = [t_ for t_, s in e.cmds if restarted is not None and t_ > restarted and s == mr.STATUS_ACTIVE]
        if not back:
            v.fails.append("the restarted controller never became active")
        else:
            v.observed.append("restarted controller active again")
