"""``mrsteer replay`` of a realtime (``clock`` trigger) log: the sensor frames go to the cycles the
recorded commands show, where neither the frames' order nor their bus times alone would say;
a late cycle that no grouping reproduces is named and does not make the log disagree.

The logs here are built by a real ``ControllerNode`` that drains the frames on a schedule of the
test's own (a late cycle that drained part of the next burst, a cycle that drained before frames
logged well ahead of its command), the way a loaded machine makes them."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import can
import pytest

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.controller.node import ControllerNode, RuntimeConfig
from mrsteer_cli.cli import main
from mrsteer_dbc.link import TxLink
from mrsteer_dbc.names import (MSG_CMD, MSG_REDUNDANT, MSG_SPEED, MSG_STEER, MSG_YAW, SIG_CMD_ANGLE, SIG_LAT_ACCEL,
                               SIG_SPEED, SIG_SPEED_2, SIG_STEER_ANGLE, SIG_STEER_ANGLE_2, SIG_YAW_RATE, SIG_YAW_RATE_2)
from sim_plant.figures import resolution_of, tidy
from sim_plant.harness.replay import ReplaySettings, replay
from sim_plant.harness.replay_clock import RecordingBus
from sim_plant.harness.replay_report import steps_csv, whatif, whatif_series
from sim_plant.nodes.candump_log import format_line

C = mrsteer_dbc.load()
TS = 0.002
T0 = 1_700_000_000.0
STEPS = 200
EARLY = range(40, STEPS - 10, 23)  # cycles that also drained the next step's driver angle (logged before them)
HELD = range(51, STEPS - 10, 23)  # cycles that drained before the next step's frames logged 0.3 ms ahead of them
STALL = range(68, STEPS - 10, 23)  # late cycles: their command 3.1 ms after the one before, the next one's 0.1 ms after
V = 4.0  # m/s: the controller is active (3 m/s) and the plausibility monitor's checks pause (5 m/s)


def _sensors(k: int) -> list[tuple[str, dict[str, float]]]:
    """Step k's frames, in the plant's order (driver angle first, yaw rate last); the driver
    steers all the time, so a cycle that takes the angle a step early commands otherwise."""
    steer = 0.004 * math.sin(2 * math.pi * 3.0 * k * TS)
    r = 0.002 * math.sin(2 * math.pi * 2.0 * k * TS) + 0.001  # small: the command follows, not rate-limited
    out = [(MSG_STEER, {SIG_STEER_ANGLE: steer})]
    for name, values in ((MSG_SPEED, {SIG_SPEED: V}),
                         (MSG_REDUNDANT, {SIG_LAT_ACCEL: V * r, SIG_STEER_ANGLE_2: steer, SIG_SPEED_2: V})):
        if k % max(1, round((C.cycle_time_s(name, TS) or TS) / TS)) == 0:
            out.append((name, values))
    return out + [(MSG_YAW, {SIG_YAW_RATE: r, SIG_YAW_RATE_2: r})]


def _log(path: Path) -> Path:
    """The realtime-like log: plant step k's frames from T0 + k TS; the command of cycle k 0.15 ms
    after them, except in ``EARLY`` (60 us after the next step's driver angle, which the node
    had, its yaw rate 40 us later), ``HELD`` (0.3 ms after the next step's driver angle and
    yaw rate, which it did not have: twice the log's shortest answer) and ``STALL`` (1.5 ms after
    the next step's frames, which it did not have; the next cycle's command 0.1 ms after it)."""
    tx = TxLink(C, (MSG_STEER, MSG_SPEED, MSG_REDUNDANT, MSG_YAW))
    bus = RecordingBus()
    node = ControllerNode(bus, RuntimeConfig(trigger="clock"), C)  # type: ignore[arg-type]
    frames = [[(name, tx.frame(name, values)) for name, values in _sensors(k)] for k in range(STEPS + 1)]
    lines: list[tuple[float, can.Message]] = []
    taken = set()
    for k in range(STEPS):
        t = T0 + k * TS
        for i, (name, msg) in enumerate(frames[k]):
            stamp = t + 1e-5 * i
            if k - 1 in EARLY:
                stamp += 1e-4 if name == MSG_YAW else 0.0
            if id(msg) not in taken:
                node.receive(msg)
            lines.append((stamp, msg))
        send = t + 1.5e-4
        if k in EARLY:
            node.receive(frames[k + 1][0][1])
            taken.add(id(frames[k + 1][0][1]))
            send = t + TS + 6e-5
        elif k in HELD:
            send = t + TS + 3e-4
        elif k - 1 in HELD:
            send = t + 3.5e-4
        elif k in STALL:
            send = t + TS + 1.5e-3
        elif k - 1 in STALL:
            send = t + 1.6e-3
        before = len(bus.sent)
        node.control()
        lines += [(send + 1e-5 * i, msg) for i, msg in enumerate(bus.sent[before:])]
    node.finish()
    lines.append((T0 + STEPS * TS + 0.05, bus.sent[-1]))
    lines.sort(key=lambda x: x[0])
    with path.open("w") as f:
        for stamp, msg in lines:
            msg.timestamp = stamp
            f.write(format_line(msg, "vcan0"))
    return path


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _log(tmp_path_factory.mktemp("clock") / "traffic.log")


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines(keepends=True)


def _command_line(lines: list[str], cycle: int) -> int:
    """Index of the ``cycle``-th command's line."""
    return [i for i, ln in enumerate(lines) if ln.split()[2].startswith(f"{C.frame_id(MSG_CMD):03X}#")][cycle]


def _with_angle(line: str, delta: float) -> str:
    stamp, iface, body = line.split()
    data = bytes.fromhex(body.split("#")[1])
    d = C.decode(C.frame_id(MSG_CMD), data)
    assert d is not None
    values = {k: v for k, v in d.signals.items() if k in ("AuxSteerCmd_State", "AuxSteerCmd_MeasCounter")}
    new = C.encode(MSG_CMD, {**values, SIG_CMD_ANGLE: d.signals[SIG_CMD_ANGLE] + delta}, d.counter)
    return f"{stamp} {iface} {body.split('#')[0]}#{new.hex().upper()}\n"


def _replay(capsys: pytest.CaptureFixture[str], path: Path) -> tuple[int, dict]:
    code = main(["replay", str(path), "--trigger", "clock", "--json"])
    return code, json.loads(capsys.readouterr().out)["replays"][0]


def test_the_commands_group_the_frames_where_order_and_times_do_not(log: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    code, s = _replay(capsys, log)
    assert code == 0 and s["agrees"] and s["mismatches"] == 0, s["all_mismatches"][:3]
    assert s["max_abs_dangle_rad"] == 0.0 and s["mismatches_apart"] == 0
    assert s["commands_recorded"] == STEPS + 1 and s["cycles_grouped_by_their_commands"] >= len(EARLY) + len(HELD)
    # the late cycles are named: each schedule's (its command 1.5 periods after the one before or
    # more) and those catching up after it (half a period after the one before or less); none else
    lines = _lines(log)
    late = {_command_line(lines, k + d) + 1 for ks, ds in ((EARLY, 2), (HELD, 2), (STALL, 3)) for k in ks
            for d in range(ds)}
    assert set(s["late_cycle_lines"]) == late and s["late_cycles"] == len(late)
    # the grouping is the one the node had: the early driver angle went to the early cycle
    r = replay(log, ReplaySettings(trigger="clock"))
    for k in EARLY:
        nxt = _sensors(k + 1)[0][1][SIG_STEER_ANGLE]
        assert r.steps[k].inputs[0] == pytest.approx(nxt, abs=2.5e-5)
    for k in HELD:
        assert r.steps[k].inputs[0] == pytest.approx(_sensors(k)[0][1][SIG_STEER_ANGLE], abs=2.5e-5)


def test_a_late_cycle_no_grouping_reproduces_is_named_and_not_the_firmwares(
        log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lines = _lines(log)
    i = _command_line(lines, STALL[1])
    lines[i] = _with_angle(lines[i], 1e-5)
    (tmp_path / "late.log").write_text("".join(lines))
    code, s = _replay(capsys, tmp_path / "late.log")
    assert code == 0 and s["agrees"] and s["mismatches"] == 0
    assert s["apart_from_line"] == i + 1 and s["mismatches_apart"] == 1 and s["apart_mismatches"][0]["line"] == i + 1
    main(["replay", str(tmp_path / "late.log"), "--trigger", "clock"])
    text = capsys.readouterr().out
    assert f"from line {i + 1} on, a late cycle" in text and "not the firmware's" in text
    assert "{" not in text and "}" not in text  # no dict reprs in the printed report
    floats = [(k, v) for k, v in s["apart_mismatches"][0].items() if isinstance(v, float)]
    assert floats and all(tidy(v, resolution_of(k)) == v for k, v in floats)  # JSON: no float noise


def test_an_on_time_cycle_that_disagrees_still_fails(log: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    lines = _lines(log)
    i = _command_line(lines, EARLY[0] - 5)
    lines[i] = _with_angle(lines[i], 1e-4)
    (tmp_path / "wrong.log").write_text("".join(lines))
    code, s = _replay(capsys, tmp_path / "wrong.log")
    assert code == 1 and not s["agrees"] and s["first_mismatch"]["line"] == i + 1 and s["apart_from_line"] is None


def test_replay_csv_starts_at_scenario_time(log: Path) -> None:
    r = replay(log, ReplaySettings(trigger="clock"))
    rows = steps_csv(r.steps).splitlines()
    assert rows[0].split(",")[:2] == ["t_s", "step"] and rows[0].split(",")[4] == "bus_time_s"
    t = [float(row.split(",")[0]) for row in rows[1:]]
    assert abs(t[0]) <= TS and t[EARLY[0]] == pytest.approx(EARLY[0] * TS, abs=TS)
    assert all(b >= a for a, b in zip(t, t[1:]))  # the final zero command after the last step too


def test_whatif_traces_run_on_scenario_time_and_stop_before_the_shutdown(log: Path) -> None:
    settings = ReplaySettings(trigger="clock")
    r = replay(log, settings)
    d = mr.ControllerConfig()
    half = replay(log, replace(settings, controller=replace(d, schedule_k=tuple(0.5 * k for k in d.schedule_k))),
                  like=r)
    t, rec, new = whatif_series(whatif(half))
    assert len(t) == len(rec) == len(new) == STEPS  # every cycle but the final zero command
    assert t[0] == 0.0 and t[-1] == pytest.approx((STEPS - 1) * TS) and all(b >= a for a, b in zip(t, t[1:]))
    last = [s for s in r.steps if s.kind != "final"][-1]
    assert rec[-1] == pytest.approx(math.degrees(last.out.angle)) and abs(rec[-1]) > 0.01  # no jump to 0
    assert abs(new[-1]) > 0.005 and new[-1] != pytest.approx(rec[-1], abs=1e-3)  # the new calibration's own
