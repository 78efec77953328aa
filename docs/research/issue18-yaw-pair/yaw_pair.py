"""Issue 18 research: a second yaw-rate channel and a pair check against stuck and scaled yaw-rate
sensors (not product code; README.md beside this file has the results and the plan).

The loop is ``sim_plant.offline.plausibility_runs.run``'s (the realistic car, the default position
actuator, the sensors with noise at their DBC cycles, the shipped law, the monitor and the
authority limiter, one period of command delay), with one addition: a second yaw-rate sensor of
the same model but its own noise stream and bias, sampled with the first (as one frame would
carry both), and a pair check on the two.  The check is what the firmware would get:

    e_k = | mean over the last ``window`` samples of (r_1 - r_2) |,  trip when e_k > ``bound``

On a trip it sets ``PLAUS_YAW``; ``--cut`` (the default) removes the command at the limiter's
rate bound ``rate_max`` instead of the 30 deg/s fault fade, because a stuck channel is found
within tens of ms, while the command it drove is still acting on the car.

The figure is the campaigns' ``fault_yaw_rate`` (since 5 December 2026 ``twin_yaw_rate``): the
largest |r - r of the fault-free twin| after the onset (the fade included).  Each row's twin
runs the same sensors without the fault, so a false alarm shows as a fault bit in the twin.

Run from the repository root with the project's interpreter:

    .venv/bin/python docs/research/issue18-yaw-pair/yaw_pair.py                  # the grid, bound 0.03, 10 ms
    .venv/bin/python docs/research/issue18-yaw-pair/yaw_pair.py --no-pair        # today's product on it
    .venv/bin/python docs/research/issue18-yaw-pair/yaw_pair.py --no-cut         # the pair with the 30 deg/s fade
    .venv/bin/python docs/research/issue18-yaw-pair/yaw_pair.py --bound 0.025 --window 5
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from firmware_py import authority as au
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from sim_plant.car import scenario as scn
from sim_plant.car.actuator_dynamics import ActuatorModelConfig, PositionActuator
from sim_plant.car.plants import Car
from sim_plant.car.scenario_play import ScenarioState
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import CHANNELS, SensorConfig, Sensors, YawRateSensorConfig
from sim_plant.offline.plausibility_runs import cycles, steady_curve

TS = 0.002
ONSET = 1.0  # s
NOISE = 0.028  # deg/s/sqrt(Hz): the top of the campaigns' range (twice the BMG160's)
BIAS = 0.3  # deg/s: +BIAS on channel 1, -BIAS on channel 2, the campaigns' largest offsets apart


@dataclass(frozen=True)
class Pair:
    on: bool = True
    bound: float = 0.03  # rad/s
    window: int = 5  # samples of 2 ms
    cut: bool = True  # remove the command at rate_max on a trip, not at the 30 deg/s fault fade


@dataclass
class Trace:
    r: np.ndarray  # the car's true yaw rate
    bits: np.ndarray  # what the limiter was given
    pair_margin: np.ndarray  # e_k / bound


def run(sc: scn.Scenario, pair: Pair, bias_2: float = -BIAS, seed_2: int = 99) -> Trace:
    """``plausibility_runs.run``'s loop with the second channel and the pair check."""
    every = cycles(TS)
    scene = ScenarioState(sc)
    car = Car(sc.plant, scene.params(), TS)
    actuator = PositionActuator(sc.actuator, TS)
    sensors = Sensors(sc.sensor_config, TS)
    # The second element: the same model, its own noise stream and bias, never faulted.
    second = Sensors(replace(sc.sensors, seed=seed_2, faults=(),
                             yaw_rate=replace(sc.sensors.yaw_rate, bias_deg_s=bias_2)), TS)
    reg = mr.ModelRegulator()
    mon = pl.PlausibilityMonitor(pl.PlausibilityConfig(ts=TS))
    limits = au.AuthorityConfig(ts=TS)
    if pair.cut:
        limits = replace(limits, fault_fade_rate=limits.rate_max)
    ac, ast = au.configure_authority(limits), au.AuthorityState()
    n = int(round(sc.duration / TS)) + 1
    out = Trace(np.zeros(n), np.zeros(n, dtype=int), np.zeros(n))
    held: dict[str, float] = {}
    pipeline: deque[float] = deque([0.0])
    diffs: deque[float] = deque([0.0] * pair.window, maxlen=pair.window)
    applied, tripped = 0.0, False
    for k in range(n):
        t = k * TS
        if scene.advance_to(t):
            car.set_params(scene.params())
        car.set_loads(scene.loads(t))
        driver = scene.driver_angle(t, float(car.x[1]), TS)
        y = car.outputs(driver + applied, scene.m_z)
        truth = {"yaw_rate": float(y[0]), "steer": driver, "speed": scene.v, "lat_accel": float(y[2]),
                 "steer_redundant": driver}
        sensors.at(t)
        second.at(t)
        read = {ch: getattr(sensors, ch)(truth[ch]) for ch in CHANNELS}
        r_2 = second.yaw_rate(truth["yaw_rate"])
        for ch in CHANNELS:
            if k % every[ch] == 0:
                held[ch] = read[ch]
        u = reg.step(held["steer"], held["yaw_rate"], held["speed"])
        bits = mon.step(held["steer"], held["steer_redundant"], held["yaw_rate"], held["lat_accel"],
                        held["speed"], pipeline[0])
        diffs.append(held["yaw_rate"] - r_2)
        e = abs(sum(diffs) / pair.window)
        out.pair_margin[k] = e / pair.bound
        if pair.on and k >= pair.window and e > pair.bound:
            tripped = True
        if tripped:
            bits |= pl.PLAUS_YAW
        u = au.authority_step(ac, ast, u, bits)
        pipeline.append(u)
        applied = actuator.step(pipeline.popleft())
        out.r[k], out.bits[k] = float(y[0]), bits
        car.advance(driver + actuator.mean, scene.m_z)
        if not car.linear:
            scene.v = car.v
    return out


def base(v: float, mu: float, curve: bool) -> scn.Scenario:
    sensors = SensorConfig(seed=1, yaw_rate=YawRateSensorConfig(noise_density=NOISE, bias_deg_s=BIAS))
    if curve:
        return replace(steady_curve(v, mu, duration=2.0), sensors=sensors)
    return scn.Scenario("straight", 2.0, v=v, mu=mu, plant="nonlinear", actuator=ActuatorModelConfig.default(),
                        sensors=sensors)


def grid() -> list[tuple[str, float, float, str, float]]:
    """(road, v, mu, kind, value): stuck at a constant (rad/s) on a straight road and in a 2 m/s^2
    curve, and gains 0.5 / 1.5 in the curve; onset 1.0 s."""
    stuck = itertools.product(("straight", "curve"), (10.0, 20.0, 30.0, 40.0), (0.3, 1.0),
                              ("stuck",), (-0.05, -0.02, 0.0, 0.01, 0.03))
    scale = itertools.product(("curve",), (10.0, 20.0, 40.0), (0.3, 1.0), ("scale",), (0.5, 1.5))
    return [*stuck, *scale]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--no-pair", action="store_true", help="without the pair check: today's product")
    p.add_argument("--no-cut", action="store_true", help="fade at the 30 deg/s fault fade, not at rate_max")
    p.add_argument("--bound", type=float, default=0.03, help="rad/s (default 0.03)")
    p.add_argument("--window", type=int, default=5, help="samples of 2 ms averaged (default 5)")
    a = p.parse_args(argv)
    if not (0.0 < a.bound < 1.0 and 1 <= a.window <= 100):
        p.error("--bound must be in (0, 1) rad/s and --window in [1, 100]")
    pair = Pair(not a.no_pair, a.bound, a.window, not a.no_cut)
    start = time.monotonic()
    caused, margins, alarms = [], [], 0
    for road, v, mu, kind, value in grid():
        sc0 = base(v, mu, road == "curve")
        twin = run(sc0, pair)
        hit = run(replace(sc0, sensor_faults=(SensorFault("yaw_rate", kind, ONSET, value),)), pair)
        k = int(round(ONSET / TS))
        c = float(np.max(np.abs(hit.r[k:] - twin.r[k:])))
        found = np.flatnonzero(hit.bits[k:] & pl.PLAUS_FAULT)
        alarms += bool(np.any(twin.bits & pl.PLAUS_FAULT))
        caused.append(c)
        margins.append(float(twin.pair_margin[pair.window:].max()))
        det = f"{found[0] * TS * 1e3:4.0f} ms" if found.size else "  never"
        print(f"{road:8} v {v:4.0f} mu {mu:.1f} {kind} {value:+.2f}: caused {c:.4f} rad/s, reported {det} "
              f"after onset", flush=True)
    for name in ("split-mu", "side-wind", "blow-out"):
        sc = scn.load(name)
        t = run(replace(sc, sensors=replace(sc.sensors, yaw_rate=replace(sc.sensors.yaw_rate, noise_density=NOISE,
                                                                          bias_deg_s=BIAS))), pair)
        alarms += bool(np.any(t.bits & pl.PLAUS_FAULT))
        margins.append(float(t.pair_margin[pair.window:].max()))
        print(f"{name:9} fault-free: pair residual at most {margins[-1]:.2f} of its bound, "
              f"fault bits {'SET' if np.any(t.bits & pl.PLAUS_FAULT) else 'none'}", flush=True)
    arr = np.array(caused)
    print(f"pair {'on' if pair.on else 'off'} (bound {pair.bound:g} rad/s, {pair.window} samples, "
          f"{'cut at rate_max' if pair.cut else '30 deg/s fade'}): caused <= 0.05 rad/s in "
          f"{np.sum(arr <= 0.05)}/{arr.size}, the largest {arr.max():.3f}; fault-free runs with a fault bit: "
          f"{alarms}; largest fault-free pair residual {max(margins):.2f} of the bound; {time.monotonic() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
