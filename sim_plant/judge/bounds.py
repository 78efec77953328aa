"""The bound a sensor fault's error is judged against and the offset its check adds to it:
``sensor_bound``, ``check_offset``, ``speed_pair_bound`` and when the car counts as braking
(``is_braking``, ``braking_of``).  Floats, or arrays per period or per row: a single run is a
batch of one.  Every judge of a detection time (the offline runs, the fault matrix, ``hil run``'s
``error_over_bound_s``, the campaigns and their scalar reference) takes its bound from here."""

from __future__ import annotations

import math

import numpy as np

from firmware_py import plausibility as pl
from sim_plant.car.sensors import dbc_resolution


def sensor_bound(sensor: str, cfg: pl.PlausibilityConfig, r: float | np.ndarray, v: float | np.ndarray,
                 pair: bool | np.ndarray, speed_pair: bool = False,
                 braking: bool | np.ndarray = False) -> float | np.ndarray:
    """The plausibility bound a sensor's error is judged against (floats, or arrays per period
    or per row): the yaw rate's ``yaw_bound + yaw_rel |r|`` (r the true yaw rate), the lateral
    acceleration's the same times v (the kinematic check's residual) plus ``side_accel`` while
    the yaw-rate pair runs (``pair``: the check allows a side force then), a steering channel's
    ``steer_bound``, the yaw-rate sensor's second element's ``yaw_pair_bound`` (only the pair
    check sees it), and on a car with the second speed (``speed_pair``) either speed's
    ``speed_pair_bound`` (wider while the car brakes: ``braking``, see ``speed_pair_bound``).
    Without the second speed a speed has none (its checks bound its
    jumps, not its error): ValueError.  Below the monitor's ``speed_min`` (at the true speed
    ``v``) every bound is infinite: the checks pause there and the law is inactive, so an error
    there is not one the monitor could report (a car braked to a stop with the fault)."""
    bound = _sensor_bound(sensor, cfg, r, v, pair, speed_pair, braking)
    if np.ndim(v) == 0:
        return math.inf if v < cfg.speed_min else bound
    return np.where(np.asarray(v) < cfg.speed_min, np.inf, bound)


def _sensor_bound(sensor: str, cfg: pl.PlausibilityConfig, r: float | np.ndarray, v: float | np.ndarray,
                  pair: bool | np.ndarray, speed_pair: bool, braking: bool | np.ndarray) -> float | np.ndarray:
    if sensor in ("steer", "steer_redundant"):
        return cfg.steer_bound
    if sensor == "yaw_rate_redundant":
        return cfg.yaw_pair_bound
    if sensor in ("speed", "speed_redundant") and speed_pair:
        return speed_pair_bound(cfg, v, braking)
    if sensor not in ("yaw_rate", "lat_accel"):
        raise ValueError(f"no plausibility bound for the sensor {sensor!r}"
                         + (" on a car without the second speed" if sensor.startswith("speed") else ""))
    yaw = cfg.yaw_bound + cfg.yaw_rel * abs(r)
    return yaw if sensor == "yaw_rate" else yaw * v + cfg.side_accel * pair


def check_offset(sensor: str, bias: dict[str, float | np.ndarray], v: float | np.ndarray,
                 after: bool | np.ndarray, by_pair: bool = False) -> float | np.ndarray:
    """What the healthy sensors' constant offsets (``bias``: ``SensorConfig.biases``, by channel,
    floats or arrays per row) add to a fault's error in the residual its check compares with
    the bound, in the faulted sensor's units (``v`` the true speed): the kinematic check reads
    a_y - v r, so an a_y error e shows as e + b_a - v b_r, and a yaw-rate error as e + b_r - b_a / v;
    the yaw-rate pair reads r_2 - r, so the second element's error shows as e + b_2 - b_r (and the
    first's, ``by_pair``, as e + b_r - b_2); 0 where not ``after`` the fault's onset (a bool, or
    one per row: the offsets alone are no fault's error).  A judge compares |e + offset| with
    ``sensor_bound``: the monitor cannot tell a fault from its partner's healthy offset, so a fault opposing that
    offset passes the check's bound only when it has passed it by the offset too (an a_y drift
    against a yaw-rate bias of 0.3 deg/s was judged up to 140 ms late without it).  The steering
    channels and the speeds have no modelled offset: 0."""
    b_r, b_a, b_2 = bias.get("yaw_rate", 0.0), bias.get("lat_accel", 0.0), bias.get("yaw_rate_redundant", 0.0)
    if sensor == "lat_accel":
        offset = b_a - b_r * v
    elif sensor == "yaw_rate_redundant":
        offset = b_2 - b_r
    elif sensor == "yaw_rate":
        # (below the monitor's speed_min every bound is infinite: the 1 m/s floor only avoids 1 / 0)
        offset = b_r - b_2 if by_pair else b_r - b_a / np.maximum(v, 1.0)
    else:
        return 0.0
    return np.where(after, offset, 0.0) if np.ndim(after) else (offset if after else 0.0)


#: What the second speed's rounding (half its LSB) may add to the speed pair's difference.
_SPEED2_HALF_LSB = 0.5 * dbc_resolution("speed_redundant")


def speed_pair_bound(cfg: pl.PlausibilityConfig, v: float | np.ndarray,
                     braking: bool | np.ndarray = False) -> float | np.ndarray:
    """The bound a speed error (either speed's) is judged against on a car with the second
    speed: the speed pair's ``speed_pair_bound + speed_pair_rel v`` at the true speed ``v``, plus
    what the second speed's rounding (half its 0.3 m/s LSB) may add to the difference the
    monitor sees, with its share of the relative term: the monitor compares with the reading,
    not the truth, so a rising error may reach its bound that much later than the truth's.
    While the car brakes (``braking``: ``braking_of``) plus ``speed_slip_rel v``, the slip the
    monitor then allows a second speed below the speed, for an error of either sign: the braked
    wheels' own slip (up to ABS's 10-20 %) moves the difference the monitor sees by as much, and
    which way the fault's error adds to it depends on the slip the judge does not know."""
    bound = cfg.speed_pair_bound + cfg.speed_pair_rel * v + _SPEED2_HALF_LSB * (1.0 + cfg.speed_pair_rel)
    return bound + np.where(braking, cfg.speed_slip_rel * v, 0.0) if np.any(braking) else bound


#: The share of ``speed_brake_decel`` from which a judge counts a period as braking.  The monitor
#: sees the speed in 20 ms frames, so its lag's margin over the speed is a sawtooth that opens the
#: allowance in part from 0.85-0.9 of ``speed_brake_decel`` (0.42-0.45 m/s^2, measured at 500 Hz)
#: and fully from about 1.24: a judge that switched at 1.0 would count the monitor late between.
BRAKING_SHARE = 0.8


def is_braking(v_before: float | np.ndarray, v: float | np.ndarray, ts: float,
               cfg: pl.PlausibilityConfig) -> bool | np.ndarray:
    """Whether the true speed fell from ``v_before`` to ``v`` in one period of ``ts`` s at
    ``BRAKING_SHARE`` of ``speed_brake_decel`` or more: a period in which the monitor may allow
    the second speed the braked wheels' slip."""
    return v_before - v >= BRAKING_SHARE * cfg.speed_brake_decel * ts


def braking_of(v: np.ndarray, ts: float, cfg: pl.PlausibilityConfig) -> np.ndarray:
    """``is_braking`` for each period of ``v`` (a true speed every ``ts`` s, one run, or a column
    per run); the first period is not."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape, dtype=bool)
    out[1:] = is_braking(v[:-1], v[1:], ts, cfg)
    return out
