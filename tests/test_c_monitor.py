"""The C port of the plausibility monitor and the authority limiter (ports/c/mrs_monitor.c)
against firmware_py/plausibility.py: the same inputs, bit-identical outputs in double."""

from __future__ import annotations

import dataclasses
import math
import random
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from firmware_py import authority as au
from firmware_py import plausibility as pl
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import SensorConfig
from sim_plant.offline import plausibility_runs as pr

PORT = Path(__file__).resolve().parents[1] / "ports" / "c"
CC = shutil.which("gcc")
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-ffp-contract=off"]

pytestmark = pytest.mark.skipif(CC is None, reason="gcc is not installed (.ci/run installs it)")


@pytest.fixture(scope="module")
def runner(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("monitor") / "monitor_vectors"
    proc = subprocess.run([CC, *CFLAGS, f"-I{PORT}", "-o", str(out), str(PORT / "mrs_monitor.c"),
                           str(PORT / "monitor_vectors.c"), "-lm"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out


def _config_lines(m: pl.PlausibilityConfig, a: au.AuthorityConfig) -> str:
    return ("monitor " + " ".join(repr(float(getattr(m, f.name))) for f in dataclasses.fields(m)) + "\n"
            + "authority " + " ".join(repr(float(getattr(a, f.name))) for f in dataclasses.fields(a)) + "\n")


def _python(m: pl.PlausibilityConfig, a: au.AuthorityConfig, rows: list[tuple[float, ...]]) -> list[tuple]:
    mc, ac = pl.configure(m), au.configure_authority(a)
    ms, ast = pl.MonitorState(), au.AuthorityState()
    out = []
    for dd, dd2, r, ay, v, aux, u, r2, v2 in rows:
        bits = pl.monitor_step(mc, ms, dd, dd2, r, ay, v, aux, r2, v2)
        u_out = au.authority_step(ac, ast, u, bits, ms.flags & pl.CUT_CHECKS, ms.flags & pl.FADE_CHECKS)
        out.append((bits, ms.flags, ms.kin_err, ms.pair_err, ms.model_err, u_out, ast.flags, ms.yaw_pair_err,
                    ms.turn_err, ms.turn_n, int(ms.turn_settled), ms.yaw_hold_n, ms.yaw_clear_n, ms.speed_pair_err,
                    ms.speed_pair_count, int(ms.speed2_seen), ms.steer_hold_n, ms.speed_lag))
    return out


def _c(runner: Path, m: pl.PlausibilityConfig, a: au.AuthorityConfig, rows: list[tuple[float, ...]]) -> list[tuple]:
    text = _config_lines(m, a) + "".join(" ".join(repr(x) for x in row) + "\n" for row in rows)
    proc = subprocess.run([str(runner)], input=text, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("coeffs ")
    out = []
    for line in lines[1:]:
        f = line.split()
        out.append((int(f[0]), int(f[1]), float(f[2]), float(f[3]), float(f[4]), float(f[5]), int(f[6]), float(f[7]),
                    float(f[8]), int(f[9]), int(f[10]), int(f[11]), int(f[12]), float(f[13]), int(f[14]), int(f[15]),
                    int(f[16]), float(f[17])))
    return out


# A row: delta_driver, delta_driver_redundant, yaw_rate, lat_accel, speed, aux_cmd_applied, u_request,
# yaw_rate_redundant, speed_redundant (the last NaN unless a case gives the second speed).
def _rows_of(r: pr.MonitorRun) -> list[tuple[float, ...]]:
    """An offline run's monitor inputs as rows (the second speed NaN where the car has none)."""
    h = r.held
    aux = np.concatenate([[0.0], r.aux[:-1]])  # the angle acting on the car at each period
    return [tuple(float(x) for x in row) for row in zip(h["steer"], h["steer_redundant"], h["yaw_rate"], h["lat_accel"],
                                                        h["speed"], aux, r.aux, h["yaw_rate_redundant"],
                                                        h["speed_redundant"])]


def _run_rows(sc, second_yaw: SensorConfig | None = None) -> list[tuple[float, ...]]:
    return _rows_of(pr.run(sc, second_yaw=second_yaw))


def _random_rows(seed: int, n: int = 3000) -> list[tuple[float, ...]]:
    rng = random.Random(seed)
    rows, held, speed = [], [0.0, 0.0], 20.0
    for k in range(n):
        if k % 25 == 0:
            held = [rng.gauss(0, 2), rng.gauss(0, 0.02)]
        if k % 400 == 0:
            speed = rng.choice((3.0, 12.0, 25.0, 40.0))
        if k % 300 == 0:
            apart = rng.choice((0.0, 0.0, 0.0, 0.05))  # now and then the yaw-rate pair disagrees
        row = [rng.gauss(0, 0.02), held[1], rng.gauss(0, 0.1), held[0], speed, rng.gauss(0, 0.02),
               rng.gauss(0, 0.06)]
        row.append(row[2] + apart + rng.gauss(0, 0.01))
        if 1500 <= k < 1800:
            row[7] = math.nan  # a stretch without the second element: the kinematic check is the yaw rate's
        if rng.random() < 0.002:
            row[rng.randrange(8)] = math.nan
        if rng.random() < 0.001:
            row[rng.randrange(8)] = rng.choice((math.inf, -math.inf))
        rows.append((*row, math.nan))  # no second speed (the random case with one: _random_speed_pair_rows)
    return rows


def _lost_second_element(rows: list[tuple[float, ...]]) -> list[tuple[float, ...]]:
    """The rows with the yaw-rate sensor's second element missing (NaN, SNA on the bus) from
    the middle on, as a car whose element fails."""
    half = len(rows) // 2
    return rows[:half] + [(*row[:7], math.nan, *row[8:]) for row in rows[half:]]


def _lost_edges(rows: list[tuple[float, ...]]) -> list[tuple[float, ...]]:
    """The rows with the second yaw-rate element missing, from the middle on, in every other
    period, the first element in every third (both in every sixth), and the speed below the
    monitor's minimum in the last quarter: where the lost element's rule asks for the first
    element valid, and where every check pauses."""
    half, out = len(rows) // 2, list(rows[:len(rows) // 2])
    for k, row in enumerate(rows[half:], start=half):
        d, d2, r, lat, v, aux, u, r2, v2 = row
        out.append((d, d2, math.nan if k % 3 == 0 else r, lat, 3.0 if k >= 3 * len(rows) // 4 else v, aux, u,
                    math.nan if k % 2 == 0 else r2, v2))
    return out


def _turn_rows(samples: int = 80, r: float = 0.3, v: float = 10.0, measured: float = 11.5) -> list[tuple[float, ...]]:
    """A steady turn whose speed reads 15 % high, with a lost redundant frame (sample 14), the
    yaw rate missing for a frame (sample 40: every check pauses) and an a_y step (sample 60):
    each restarts the steady-turn check's blocks, and its trips latch in between."""
    c = pl.configure(pl.PlausibilityConfig())
    d = r * (c.wheelbase + c.k_us * measured * measured) / measured
    rows = []
    for j in range(samples):
        lat = r * v + (-0.4 if j >= 60 else 0.0) + (1e-3 if j % 2 else 0.0)
        for k in range(25):
            yaw = math.nan if j == 40 else r + (1e-4 if k % 2 else 0.0)
            rows.append((d, d, yaw, math.nan if j == 14 else lat, measured, 0.0, 0.0, yaw, math.nan))
    return rows


SPEED2_EVERY = 25  # periods of 2 ms in MRS_RedundantSensors' 50 ms, which carries the second speed
SPEED2_LSB = 0.3  # m/s: RedundantSensors_Speed2's resolution


def _with_second_speed(rows: list[tuple[float, ...]], seed: int = 3) -> list[tuple[float, ...]]:
    """The rows with a second speed that agrees: the (held) speed plus 0.02 m/s of white noise,
    in 0.3 m/s steps, renewed once per redundant frame."""
    rng = random.Random(seed)
    out, v2 = [], math.nan
    for k, row in enumerate(rows):
        if k % SPEED2_EVERY == 0:
            v2 = round((row[4] + rng.gauss(0.0, 0.02)) / SPEED2_LSB) * SPEED2_LSB
        out.append((*row[:8], v2))
    return out


def _drifting_speed(rows: list[tuple[float, ...]], start: int, rate: float) -> list[tuple[float, ...]]:
    """The rows with the (first) speed drifting by ``rate`` m/s per second from period ``start``
    on, the second speed left as it is: a drift never jumps (check 6 does not see it)."""
    return [(*row[:4], row[4] + rate * (max(0, k - start) * 0.002), *row[5:]) for k, row in enumerate(rows)]


def _lost_second_speed(rows: list[tuple[float, ...]]) -> list[tuple[float, ...]]:
    """The rows (with a second speed) with it missing, from the middle on, in every other period,
    the speed in every third (both in every sixth), and both at 3 m/s (under speed_min) in the
    last quarter: the lost speed's rule asks for the speed valid, at any speed."""
    half, out = len(rows) // 2, list(rows[:len(rows) // 2])
    for k, row in enumerate(rows[half:], start=half):
        slow = k >= 3 * len(rows) // 4
        v = math.nan if k % 3 == 0 else (3.0 if slow else row[4])
        v2 = math.nan if k % 2 == 0 else (3.0 if slow else row[8])
        out.append((*row[:4], v, *row[5:8], v2))
    return out


def _random_speed_pair_rows(seed: int, n: int = 3000) -> list[tuple[float, ...]]:
    """_random_rows with a second speed: the speed plus noise, in spells apart by 0, 1.2 or 3 m/s
    (within, about at and over the pair's bound), now and then NaN, inf or negative; the speed's
    own NaN and inf included (the pair then restarts its count)."""
    rng = random.Random(seed + 1000)
    out, apart = [], 0.0
    for k, row in enumerate(_random_rows(seed, n)):
        if k % 300 == 0:
            apart = rng.choice((0.0, 0.0, 1.2, -1.2, 3.0))
        v2 = row[4] + apart + rng.gauss(0.0, 0.1)
        if rng.random() < 0.005:
            v2 = rng.choice((math.nan, math.inf, -math.inf, -1.0))
        out.append((*row[:8], v2))
    return out


def _stops(slips: tuple[float, ...], seed: int = 9, n: int = 600) -> list[tuple[float, ...]]:
    """Straight-line stops, one after another, from 30 m/s at 1-7 m/s^2 (the speed in 20 ms
    frames), whose second speed (in its 50 ms frame) reads each stop's slip below the speed from
    its onset: the braking allowance opening, holding and closing as the speed's lag follows.
    Between stops the speed is missing for a period (no jump back to 30 m/s: check 6)."""
    rng = random.Random(seed)
    out = []
    for slip in slips:
        out.append((0.0, 0.0, 0.0, 0.0, math.nan, 0.0, 0.0, 0.0, math.nan))
        decel, v, v2 = rng.uniform(1.0, 7.0), 30.0, 30.0
        for k in range(n):
            if k % 10 == 0:
                v = round(max(3.0, 30.0 - decel * 0.002 * max(0, k - 50)) / 0.002) * 0.002
            if k % SPEED2_EVERY == 0:
                v2 = round(v * (1.0 - (slip if k >= 50 else 0.0)) / SPEED2_LSB) * SPEED2_LSB
            out.append((0.0, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v2))
    return out


def _braking_turn_rows() -> list[tuple[float, ...]]:
    """test_speed_pair's braking turn whose speed drifts up: the second speed agrees only through
    the braking allowance, which must not out-vote the steady-turn check."""
    from test_speed_pair import braking_turn_with_a_speed_drift

    return _rows_of(braking_turn_with_a_speed_drift())


CASES = {
    "split-mu, fault-free": lambda: _run_rows(pr.scn.load("split-mu")),
    "yaw bias in a curve": lambda: _run_rows(pr.steady_curve(20.0, 1.0).with_sensor_faults(
        (SensorFault("yaw_rate", "bias", 1.0, math.radians(3.0)),))),
    "frozen second steering channel": lambda: _run_rows(pr.steady_curve(30.0, 0.5).with_sensor_faults(
        (SensorFault("steer_redundant", "frozen", 0.1),))),
    "random inputs with NaN and inf": lambda: _random_rows(7),
    "a steering step at 10 m/s (the family of sensor lags)": lambda: _run_rows(
        pr.steady_curve(10.0, 1.0, a_y=3.4, ramp=0.0, duration=2.0)),
    "second yaw-rate element lost half way (DEGRADED)": lambda: _lost_second_element(
        _run_rows(pr.steady_curve(20.0, 1.0), SensorConfig(seed=5))),
    "a request that persists while DEGRADED (the time rule fades it, its rest does not re-arm)": lambda: [
        (*row[:6], 0.01, *row[7:]) for row in _lost_second_element(
            _run_rows(pr.steady_curve(20.0, 1.0, duration=4.0), SensorConfig(seed=5)))],
    "second element lost with the first missing and below speed_min": lambda: _lost_edges(
        _run_rows(pr.steady_curve(20.0, 1.0), SensorConfig(seed=5))),
    "a side-wind gust at 10 m/s, the pair in the loop (side_accel)": lambda: _run_rows(
        dataclasses.replace(pr.scn.load("side-wind"), v=10.0, mu=0.3), SensorConfig(seed=101)),
    "the speed stuck at another value in a curve": lambda: _run_rows(
        pr.steady_curve(12.5, 0.8, a_y=3.0).with_sensor_faults((SensorFault("speed", "stuck", 1.0, 33.0),)),
        SensorConfig(seed=7)),
    "a steady turn with a wrong speed, its blocks restarted by a gap, a pause and an a_y step": _turn_rows,
    "a speed drifting in a steady turn (the steady-turn check)": lambda: _run_rows(
        pr.steady_curve(10.0, 1.0, a_y=0.45 * 9.81, duration=4.0).with_sensor_faults(
            (SensorFault("speed", "drift", 1.4, -1.0),)), SensorConfig(seed=44)),
    "a yaw-rate offset at the suspicion's threshold (held, re-armed, never confirmed)": lambda: _run_rows(
        pr.steady_curve(20.0, 1.0, a_y=1.0).with_sensor_faults((SensorFault("yaw_rate", "bias", 1.0, 0.02),)),
        SensorConfig(seed=99)),
    "yaw-rate element stuck, the pair in the loop": lambda: _run_rows(
        pr.steady_curve(30.0, 1.0).with_sensor_faults((SensorFault("yaw_rate", "stuck", 1.0, 0.01),)),
        SensorConfig(seed=99)),
    "a second speed that agrees (the speed pair runs and never trips)": lambda: _with_second_speed(
        _run_rows(pr.steady_curve(20.0, 1.0), SensorConfig(seed=5))),
    "the speed drifting down at 20 m/s (the speed pair trips), then under speed_min": lambda: _drifting_speed(
        _with_second_speed(_run_rows(pr.steady_curve(20.0, 1.0, duration=4.0))), 250, -6.0),
    "the speed drifting under speed_min at 6 m/s (the speed pair trips there)": lambda: _drifting_speed(
        _with_second_speed(_run_rows(pr.steady_curve(6.0, 1.0, a_y=1.0))), 100, -2.0),
    "the second speed lost half way (DEGRADED), with the speed missing and under speed_min": lambda: _lost_second_speed(
        _with_second_speed(_run_rows(pr.steady_curve(20.0, 1.0), SensorConfig(seed=5)))),
    "random inputs with a second speed, NaN and inf": lambda: _random_speed_pair_rows(11),
    "stops whose wheels slip 0-20 % then one whose second speed reads high (trips)":
        lambda: _stops((0.15, 0.2, 0.05, 0.0, 0.1, -0.12)),
    "a stop whose second speed reads 35 % low (the pair trips through the allowance)": lambda: _stops((0.35,)),
    "a braking turn whose speed drifts up (found by the turn check)": _braking_turn_rows,
    "the paper's Figure 9 at 30 m/s on mu 0.3, both pairs in the loop (the model and steady-turn checks out-voted)":
        lambda: _with_second_speed(_run_rows(pr.scn.load("paper-fig9").with_overrides(v=30.0, mu=0.3),
                                             SensorConfig(seed=9))),
}


@pytest.mark.parametrize("case", CASES)
def test_the_c_monitor_and_limiter_are_bit_identical_to_python(runner: Path, case: str) -> None:
    m, a = pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5)  # a short window: the time bound acts
    rows = CASES[case]()
    py, c = _python(m, a, rows), _c(runner, m, a, rows)
    assert len(c) == len(py) == len(rows)
    for k, (x, y) in enumerate(zip(py, c)):
        assert x == y, f"period {k}: python {x} != C {y}"


def test_a_persisting_request_stays_faded_after_the_window() -> None:
    rows = CASES["a request that persists while DEGRADED (the time rule fades it, its rest does not re-arm)"]()
    u = [out[5] for out in _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), rows)]
    faded = next(k for k in range(len(u) // 2, len(u)) if u[k] == 0.0)
    assert len(u) - faded > round(1.0 / 0.002) and set(u[faded:]) == {0.0}  # rested over rearm_time: still 0


def test_a_lost_second_element_is_degraded_from_its_first_missing_sample() -> None:
    rows = CASES["second yaw-rate element lost half way (DEGRADED)"]()
    out = _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), rows)
    half = len(rows) // 2
    assert not any(bits & pl.PLAUS_DEGRADED for bits, *_ in out[:half])
    assert all(bits & pl.PLAUS_DEGRADED for bits, *_ in out[half:])


def test_a_lost_element_is_degraded_below_speed_min_too_but_not_while_the_first_is_missing() -> None:
    rows = CASES["second element lost with the first missing and below speed_min"]()
    out = _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), rows)
    half, slow = len(rows) // 2, 3 * len(rows) // 4
    for k in range(half, len(rows)):
        r, v, r2, bits = rows[k][2], rows[k][4], rows[k][7], out[k][0]
        assert (v < pl.PlausibilityConfig().speed_min) == (k >= slow)
        degraded = math.isnan(r2) and not math.isnan(r)  # the first element there, the second lost
        assert bool(bits & pl.PLAUS_DEGRADED) == degraded, (k, r, r2, bits)


def test_the_speed_drift_case_trips_the_steady_turn_check() -> None:
    rows = CASES["a speed drifting in a steady turn (the steady-turn check)"]()
    out = _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), rows)
    first = next(k for k, (bits, f, *_) in enumerate(out) if f & pl.CHECK_TURN)
    assert 1.4 < first * 0.002 < 3.0 and not any(f & pl.CHECK_TURN for _, f, *_ in out[:first])


def _monitor_out(rows: list[tuple[float, ...]]) -> list[tuple]:
    return _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), rows)


def test_a_second_speed_that_agrees_or_is_absent_changes_nothing() -> None:
    rows = CASES["a second speed that agrees (the speed pair runs and never trips)"]()
    agree, absent = _monitor_out(rows), _monitor_out([(*row[:8], math.nan) for row in rows])
    assert [row[:13] for row in agree] == [row[:13] for row in absent]  # the bits, flags, command, the rest
    assert all(row[15] == 1 for row in agree) and not any(row[15] for row in absent)  # the pair ran, or never
    assert 0.0 < max(row[13] for row in agree) < 0.5 and not any(row[1] & pl.CHECK_SPEED_PAIR for row in agree)


@pytest.mark.parametrize("case, above_speed_min", [
    ("the speed drifting down at 20 m/s (the speed pair trips), then under speed_min", True),
    ("the speed drifting under speed_min at 6 m/s (the speed pair trips there)", False)])
def test_a_drifting_speed_trips_the_speed_pair_after_speed_pair_time(case: str, above_speed_min: bool) -> None:
    rows = CASES[case]()
    out = _monitor_out(rows)
    cfg, steps = pl.PlausibilityConfig(), pl.configure(pl.PlausibilityConfig()).speed_pair_steps
    over = [abs(v - v2) > cfg.speed_pair_bound + cfg.speed_pair_rel * min(v, v2) for *_, v, _a, _u, _r2, v2 in rows]
    first_over = over.index(True)
    assert all(over[first_over:])  # the drift only grows: the count rises by one a period
    trip = next(k for k, row in enumerate(out) if row[1] & pl.CHECK_SPEED_PAIR)
    assert trip == first_over + steps - 1
    assert all(row[0] & pl.PLAUS_YAW and row[1] & pl.CHECK_SPEED_PAIR for row in out[trip:])  # latched
    assert (rows[trip][4] >= cfg.speed_min) == above_speed_min
    assert not any(row[1] & pl.CHECK_SPEED for row in out)  # a drift, not a jump
    assert min(row[4] for row in rows) < cfg.speed_min  # and the speed ends under speed_min


def test_a_lost_second_speed_is_degraded_while_the_speed_is_valid() -> None:
    rows = CASES["the second speed lost half way (DEGRADED), with the speed missing and under speed_min"]()
    out = _monitor_out(rows)
    half = len(rows) // 2
    assert not any(row[0] & pl.PLAUS_DEGRADED for row in out[:half])
    for k in range(half, len(rows)):
        v, v2, bits = rows[k][4], rows[k][8], out[k][0]
        assert bool(bits & pl.PLAUS_DEGRADED) == (math.isnan(v2) and not math.isnan(v)), (k, v, v2, bits)
    assert any(rows[k][4] < pl.PlausibilityConfig().speed_min and out[k][0] & pl.PLAUS_DEGRADED
               for k in range(half, len(rows)))
    assert not any(row[1] & pl.CHECK_SPEED_PAIR for row in out)


def test_the_random_second_speed_case_counts_up_and_down_and_trips() -> None:
    rows = _random_speed_pair_rows(11)
    out = _monitor_out(rows)
    counts = [row[14] for row in out]
    assert any(b < a for a, b in zip(counts, counts[1:]) if 0 < b) and max(counts) == 50
    assert any(row[1] & pl.CHECK_SPEED_PAIR for row in out)
    assert any(not 0.0 <= row[8] < 1e3 and math.isfinite(row[4]) for row in rows)  # the second speed invalid


def test_the_random_case_exercises_every_branch(runner: Path) -> None:
    rows = _random_rows(7)
    out = _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), rows)
    flags = 0
    auth = 0
    for row in out:
        flags |= row[1]
        auth |= row[6]
    assert flags & pl.MISSING and flags & pl.CHECK_STEER_PAIR and flags & pl.CHECK_KINEMATIC
    assert flags & pl.CHECK_YAW_PAIR and flags & pl.OUTSIDE_MODEL
    assert auth & au.AUTH_FAULT and auth & au.AUTH_RATE


def test_the_unconfirmed_offset_case_holds_re_arms_and_never_faults() -> None:
    rows = CASES["a yaw-rate offset at the suspicion's threshold (held, re-armed, never confirmed)"]()
    out = _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), rows)
    held = [bool(row[1] & pl.SUSPECT_YAW_PAIR) for row in out]
    starts = sum(1 for k in range(1, len(held)) if held[k] and not held[k - 1])
    assert not any(bits & pl.PLAUS_FAULT for bits, *_ in out)
    assert starts >= 2 and max(row[11] for row in out) == pl.YAW_PAIR_WINDOW  # capped, then re-armed


def test_the_defaults_and_coefficients_agree(runner: Path) -> None:
    proc = subprocess.run([str(runner)], input="defaults\n", capture_output=True, text=True, check=True)
    monitor, authority = proc.stdout.splitlines()
    m, a = pl.PlausibilityConfig(), au.AuthorityConfig()
    assert [float(x) for x in monitor.split()[1:]] == [float(getattr(m, f.name)) for f in dataclasses.fields(m)]
    assert [float(x) for x in authority.split()[1:]] == [float(getattr(a, f.name)) for f in dataclasses.fields(a)]
    first = subprocess.run([str(runner)], input=_config_lines(m, a), capture_output=True, text=True,
                           check=True).stdout.split()
    mc, ac = pl.configure(m), au.configure_authority(a)
    expected = [mc.model_alpha, mc.k_us, mc.model_steps, mc.frozen_steps, mc.yaw_count, mc.inv_cs_m, mc.moment_m,
                mc.cf_m, ac.du_max, ac.fade_step, ac.fault_fade_step, ac.engage, ac.window_steps, ac.rearm_steps,
                mc.kin_gap_steps, mc.lat_span, mc.aux_alpha, mc.inv_yaw_pair_bound, mc.delta_alpha, mc.side_accel, mc.speed_step,
                mc.turn_yaw_min, mc.turn_yaw_tol, mc.turn_lat_tol, mc.turn_lat_rel, mc.turn_speed_rel, mc.turn_yaw_bias,
                mc.turn_lat_bias, mc.yaw_pair_hold, mc.speed_pair_bound, mc.speed_pair_rel, mc.speed_pair_steps,
                mc.steer_jump, mc.lat_span_paired, mc.speed_brake_alpha, mc.speed_brake_lag, mc.speed_slip_rel]
    assert [float(x) for x in first[1:]] == [float(x) for x in expected]


# A time in periods rounds half up in both (Python's round() would take 12.5 to 12, C's floor(x + 0.5)
# to 13), and a time too long for a C int32 saturates in both.
@pytest.mark.parametrize("changed, steps", [({"ts": 0.001, "speed_pair_time": 0.25}, 250),
                                            ({"speed_pair_time": 0.0007}, 1), ({"speed_pair_time": 0.0011}, 1),
                                            ({"ts": 0.01, "speed_pair_time": 0.37}, 37), ({"ts": 0.008}, 13),
                                            ({"speed_pair_time": 0.005}, 3), ({"speed_pair_time": 1e12}, 2**31 - 1)])
def test_the_speed_pair_s_steps_round_as_python(runner: Path, changed: dict[str, float], steps: int) -> None:
    m, a = dataclasses.replace(pl.PlausibilityConfig(), **changed), au.AuthorityConfig()
    first = subprocess.run([str(runner)], input=_config_lines(m, a), capture_output=True, text=True,
                           check=True).stdout.split()
    assert int(first[32]) == pl.configure(m).speed_pair_steps == steps


@pytest.mark.parametrize("bad", [{"yaw_bound": -1.0}, {"turn_yaw_tol": 0.2}, {"turn_lat_bias": -0.01},
                                 {"yaw_pair_hold": 0.031}, {"yaw_pair_hold": 0.0}, {"speed_pair_bound": 0.0},
                                 {"speed_pair_time": -0.1}, {"speed_pair_time": math.inf},
                                 {"speed_pair_rel": -0.01}, {"speed_pair_rel": 1e3}, {"speed_pair_rel": math.nan},
                                 {"steer_jump": 0.0}, {"steer_jump": math.inf}, {"mu_min_paired": 0.04},
                                 {"mu_min_paired": 1.01}, {"mu_min_paired": math.nan}, {"speed_brake_decel": 0.0},
                                 {"speed_brake_decel": math.nan}, {"speed_brake_tau": 0.0}, {"speed_brake_tau": 10.5},
                                 {"speed_brake_tau": 1e16}, {"speed_brake_tau": math.inf}, {"speed_slip_rel": -0.1},
                                 {"speed_slip_rel": 1e3}, {"speed_slip_rel": math.nan}])
def test_an_invalid_calibration_is_refused(runner: Path, bad: dict[str, float]) -> None:
    cfg = dataclasses.replace(pl.PlausibilityConfig(), **bad)
    assert subprocess.run([str(runner)], input=_config_lines(cfg, au.AuthorityConfig()), capture_output=True,
                          text=True).returncode == 3
    with pytest.raises(ValueError, match=next(iter(bad))):
        pl.configure(cfg)


def test_the_turn_case_settles_trips_and_restarts_its_blocks() -> None:
    out = _python(pl.PlausibilityConfig(), au.AuthorityConfig(panic_window=0.5), _turn_rows())
    settled = [bool(row[10]) for row in out]
    assert settled.count(False) > 0 and settled.count(True) > 0
    # settled, then reset by each of the three (the gap, the pause, the a_y step)
    falls = [k // 25 for k in range(1, len(out)) if settled[k - 1] and not settled[k]]
    assert [j for j in falls if j in (14, 40, 60)] == [14, 40, 60]
    assert any(f & pl.CHECK_TURN for _, f, *_ in out)


def test_the_step_functions_call_nothing(tmp_path: Path) -> None:
    obj = tmp_path / "mrs_monitor.o"
    subprocess.run([CC, *CFLAGS, "-c", "-o", str(obj), str(PORT / "mrs_monitor.c")], check=True)
    undefined = set(subprocess.run(["nm", "-u", str(obj)], capture_output=True, text=True,
                                   check=True).stdout.split()) - {"U"}
    assert undefined <= {"exp", "floor"}  # in the configure functions only
    dis = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(obj)], capture_output=True, text=True,
                         check=True).stdout
    for fn in ("mrs_monitor_step", "mrs_authority_step"):
        body = dis.split(f"<{fn}>:")[1].split("\n\n")[0]
        assert "call" not in body, fn


def test_the_c_law_s_hold_is_bit_identical_to_python_through_the_replay_driver(tmp_path: Path) -> None:
    """``mrs_replay`` (the monitor, ``mrs_step`` with the suspicion's hold, the limiter) against
    the same three in Python, per period to the last bit: a second element that now agrees, now
    sits between the hold and the bound (suspected, never confirmed), commands of both signs
    held, the car slowed below the activation speed and back (the law re-initialised and
    recovering while held)."""
    from firmware_py import calibration_file
    from firmware_py import model_regulator as mr
    from sim_plant.harness import replay_c

    exe = replay_c.build()
    cfg = mr.ControllerConfig()
    rng = random.Random(18)
    rows = []
    apart = 0.0
    for k in range(4000):
        if k % 20 == 0:  # each spell of agreement re-arms the suspicion for the next
            apart = rng.choice((0.0, 0.025, -0.025, 0.0))
        v = 3.0 if 1500 <= k < 1600 else 20.0
        r = 0.05 * math.sin(k / 60.0) + rng.gauss(0.0, 0.002)
        d = 0.01 * math.sin(k / 90.0)
        rows.append((d, r, v, v * r, d, 1, r - apart + rng.gauss(0.0, 0.001)))
    path = tmp_path / "replay.cfg"
    path.write_text(calibration_file.dumps(cfg))
    text = "".join(" ".join(repr(float(x)) for x in row) + "\n" for row in rows)
    proc = subprocess.run([str(exe), str(path)], input=text, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    c_u = [float(line.split()[0]) for line in proc.stdout.splitlines()]

    c, st = mr.configure(cfg), mr.State()
    mc, ms = pl.configure(pl.PlausibilityConfig(ts=cfg.ts)), pl.MonitorState()
    ac, ast = au.configure_authority(au.AuthorityConfig(ts=cfg.ts, u_max=cfg.aux_limit)), au.AuthorityState()
    u_prev, py_u, held = 0.0, [], {1: 0, -1: 0}
    for d, r, v, lat, d2, _steps, r2 in rows:
        bits = pl.monitor_step(mc, ms, d, d2, r, lat, v, u_prev, r2)
        hold = (ms.flags & pl.SUSPECT_YAW_PAIR) != 0
        if hold and st.u_prev != 0.0:
            held[1 if st.u_prev > 0.0 else -1] += 1
        u_prev = au.authority_step(ac, ast, mr.step(c, st, d, r, v, hold), bits, ms.flags & pl.CUT_CHECKS,
                                   ms.flags & pl.FADE_CHECKS)
        py_u.append(u_prev)
    assert c_u == py_u
    assert held[1] > 0 and held[-1] > 0  # both branches of the hold compared


def test_the_replay_driver_s_ninth_number_is_the_angle_of_the_monitor_s_first_step(tmp_path: Path) -> None:
    """``mrs_replay``'s ``DELTA_DRIVER_MONITOR``: the steering pair judges a redundant sample
    against it (the driver's angle that came with the sample, ``monitor_driver_angle``), later
    steps and ``mrs_step`` take ``DELTA_DRIVER``; the tenth, STARTING, reports the start state
    (0 or 1); more than ten numbers is an error."""
    from firmware_py import calibration_file
    from firmware_py import model_regulator as mr
    from sim_plant.harness import replay_c

    exe = replay_c.build()
    path = tmp_path / "replay.cfg"
    path.write_text(calibration_file.dumps(mr.ControllerConfig()))
    v, d = 20.0, 0.01
    r = v / (2.54 + 0.0023 * v * v) * d  # about the nominal car's steady state: no other check moves

    def run(ninth: bool) -> set[int]:
        lines = []
        for k in range(200):
            moved = d + (0.008 if k >= 150 else 0.0)  # the newest angle, 2 pair bounds on from line 150
            lat = v * r + (0.001 if (k // 25) % 2 else 0.0)  # a new redundant sample every 25 lines
            d2 = d if k <= 150 else moved  # line 150's sample was taken before the driver moved
            tail = f" {d!r}" if ninth and k == 150 else ""
            lines.append(f"{moved!r} {r!r} {v!r} {lat!r} {d2!r} 1 nan nan{tail}\n")
        proc = subprocess.run([str(exe), str(path)], input="".join(lines), capture_output=True, text=True,
                              timeout=60)
        assert proc.returncode == 0, proc.stderr
        return {int(line.split()[3]) for line in proc.stdout.splitlines()}

    assert run(ninth=False) == {0, pl.PLAUS_STEER}  # paired with the newest angle: a steering fault
    assert run(ninth=True) == {0}
    for bad in ("0.01 0.1 20 1 0.01 1 nan nan 0.01 0 5\n", "0.01 0.1 20 x\n"):
        proc = subprocess.run([str(exe), str(path)], input=bad, capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2 and "text after the numbers" in proc.stderr
    # STARTING: in place of the law's FAULT on a missing input, not of a healthy line's state
    lines = f"nan {r!r} {v!r} nan nan 1 nan nan nan 1\n{d!r} {r!r} {v!r} {v * r!r} {d!r} 1 nan nan {d!r} 0\n"
    proc = subprocess.run([str(exe), str(path)], input=lines, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and [int(ln.split()[1]) for ln in proc.stdout.splitlines()] == [
        mr.STATUS_STARTING, mr.STATUS_ACTIVE]
    proc = subprocess.run([str(exe), str(path)], input="0.01 0.1 20 1 0.01 1 nan nan 0.01 5\n", capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and "the tenth 0 or 1" in proc.stderr
