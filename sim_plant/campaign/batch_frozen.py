"""Check 5 of the plausibility monitor, frozen values, vectorised over a batch: the part of
``BatchMonitor`` (``batch_monitor``) that is ``monitor_step``'s four frozen checks (the yaw rate
against a_y / v, a_y against the yaw rate, each steering channel against the other), on the
monitor's own state arrays, in its two paths: every branch open (``frozen_checks``) and the
shortcut for a period without a new redundant sample (``frozen_steady``).
``tests/test_campaign_engine.py`` holds them equal to the scalar code row by row with the rest
of the monitor.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from firmware_py import plausibility as pl

if TYPE_CHECKING:
    from sim_plant.campaign.batch_monitor import BatchMonitor


def _set(m: BatchMonitor, name: str, rows: np.ndarray, value) -> None:
    setattr(m, name, np.where(rows, value, getattr(m, name)))


def _frozen(same: np.ndarray, moved: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """A frozen-value counter: +1 (held at ``steps``) where the partner ``moved``; trips at steps."""
    same = np.where(moved & (same < steps), same + 1, same)
    return same, moved & (same >= steps)


def _frozen_held(same: np.ndarray, moved: np.ndarray, steps: int, latched: np.ndarray, bit: int) -> np.ndarray:
    """``_frozen`` on a fresh ``same`` (written in place), its trip latched into ``latched``."""
    same += moved & (same < steps)
    np.bitwise_or(latched, bit, out=latched, where=moved & (same >= steps))
    return same


def _fast(m: BatchMonitor, key: str, on, value, partner, partner_ok, new, move: float, bit: int) -> None:
    """A value of every period (``key`` "yaw": the yaw rate, "st": the driver's angle) against
    its partner from the 50 ms frame (a_y / v, the second channel), taken at the first new
    sample after the value last changed, in the rows that are ``on``; checked where
    ``partner_ok``."""
    last, same, ref, ref_ok = f"{key}_last", f"{key}_same", f"{key}_ref", f"{key}_ref_ok"
    changed = on & (value != getattr(m, last))
    take = on & ~changed & new & ~getattr(m, ref_ok)
    check = on & ~changed & ~take & partner_ok & getattr(m, ref_ok)
    _set(m, last, changed, value)
    _set(m, same, changed, 0)
    _set(m, ref_ok, changed, False)
    _set(m, ref, take, partner)
    _set(m, ref_ok, take, True)
    count, trip = _frozen(getattr(m, same), check & (np.abs(partner - getattr(m, ref)) > move), m.c.frozen_steps)
    setattr(m, same, count)
    m.latched |= np.where(trip, bit, 0)


def _sampled(m: BatchMonitor, key: str, on, value, partner, move: float, bit: int) -> None:
    """A value from the 50 ms frame (``key`` "lat": a_y, "st2": the second channel) against its
    partner of every period (the yaw rate, the driver's angle) as it was when the value last
    changed, in the rows that are ``on``."""
    last, same, ref = f"{key}_last", f"{key}_same", f"{key}_ref"
    changed = on & (value != getattr(m, last))
    _set(m, last, changed, value)
    _set(m, same, changed, 0)
    _set(m, ref, changed, partner)
    moved = on & ~changed & (np.abs(partner - getattr(m, ref)) > move)
    count, trip = _frozen(getattr(m, same), moved, m.c.frozen_steps)
    setattr(m, same, count)
    m.latched |= np.where(trip, bit, 0)


def frozen_checks(m: BatchMonitor, act, lat_ok, st2_ok, new, d, d2, r, lat, r_kin) -> None:
    """The four frozen checks in the rows that ``act``, as ``monitor_step`` has them in a period
    with every branch open (``new``: the rows with a new redundant sample; ``r_kin``: a_y / v)."""
    c = m.c
    _fast(m, "yaw", act, r, r_kin, lat_ok, new, c.frozen_move_yaw, pl.FROZEN_YAW)  # the yaw rate against a_y / v
    _sampled(m, "lat", act & lat_ok, lat, r, c.frozen_move_yaw, pl.FROZEN_LAT)  # a_y against the yaw rate
    on = act & st2_ok  # each steering channel against the other
    _fast(m, "st", on, d, d2, True, new, c.frozen_move_steer, pl.FROZEN_STEER)
    _sampled(m, "st2", on, d2, d, c.frozen_move_steer, pl.FROZEN_STEER_2)


def _fast_steady(m: BatchMonitor, key: str, value, partner: Callable[[], np.ndarray], move: float,
                 latched: np.ndarray, bit: int) -> None:
    """``_fast`` in a period without a new sample, every row on: ``partner`` formed only if a row
    checks."""
    last, same, ref, ref_ok = f"{key}_last", f"{key}_same", f"{key}_ref", f"{key}_ref_ok"
    unchanged = value == getattr(m, last)
    check = unchanged & getattr(m, ref_ok)
    setattr(m, last, np.where(unchanged, getattr(m, last), value))
    setattr(m, same, np.where(unchanged, getattr(m, same), 0))
    setattr(m, ref_ok, check)
    if check.any():
        moved = check & (np.abs(partner() - getattr(m, ref)) > move)
        _frozen_held(getattr(m, same), moved, m.c.frozen_steps, latched, bit)


def _sampled_steady(m: BatchMonitor, key: str, partner, move: float, quiet: bool, latched: np.ndarray,
                    bit: int) -> None:
    """``_sampled`` in a period without a new sample (the value held: unchanged), every row on;
    ``quiet``: no row can reach the cap, so the counter only counts."""
    moved = np.abs(partner - getattr(m, f"{key}_ref")) > move
    same = getattr(m, f"{key}_same")  # counted in place
    if quiet:
        same += moved
    else:
        _frozen_held(same, moved, m.c.frozen_steps, latched, bit)


def frozen_steady(m: BatchMonitor, d, d2, r, lat, v, latched: np.ndarray, lat_quiet: bool, st2_quiet: bool) -> None:
    """The four frozen checks in a period without a new redundant sample, every row checking
    (a_y and the second channel held: unchanged), their trips latched into ``latched``.
    ``lat_quiet``, ``st2_quiet``: no row's a_y or second-channel counter can reach its cap this
    period (its largest value at the last full period plus the periods since is below
    ``frozen_steps``), so it only counts."""
    c = m.c
    _fast_steady(m, "yaw", r, lambda: lat * (1.0 / v), c.frozen_move_yaw, latched, pl.FROZEN_YAW)
    _sampled_steady(m, "lat", r, c.frozen_move_yaw, lat_quiet, latched, pl.FROZEN_LAT)
    _fast_steady(m, "st", d, lambda: d2, c.frozen_move_steer, latched, pl.FROZEN_STEER)
    _sampled_steady(m, "st2", d, c.frozen_move_steer, st2_quiet, latched, pl.FROZEN_STEER_2)
