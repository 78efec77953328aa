"""Check 5 of the plausibility monitor, frozen values, vectorised over a batch: the part of
``BatchMonitor`` (``batch_monitor``) that is ``monitor_step``'s four frozen checks (the yaw rate
against a_y / v, a_y against the yaw rate, each steering channel against the other), on the
monitor's own state arrays, in its two paths: every branch open (``frozen_checks``) and the
shortcut for a period without a new redundant sample (``frozen_steady``).
``tests/test_campaign_engine.py`` holds them equal to the scalar code row by row with the rest
of the monitor.
"""

from __future__ import annotations

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


def frozen_checks(m: BatchMonitor, act, lat_ok, st2_ok, new, d, d2, r, lat, r_kin) -> None:
    """The four frozen checks in the rows that ``act``, as ``monitor_step`` has them in a period
    with every branch open (``new``: the rows with a new redundant sample; ``r_kin``: a_y / v)."""
    c = m.c
    steps, move_yaw, move_st = c.frozen_steps, c.frozen_move_yaw, c.frozen_move_steer
    changed = act & (r != m.yaw_last)  # the yaw rate against a_y / v
    take = act & ~changed & new & ~m.yaw_ref_ok
    check = act & ~changed & ~take & lat_ok & m.yaw_ref_ok
    _set(m, "yaw_last", changed, r)
    _set(m, "yaw_same", changed, 0)
    _set(m, "yaw_ref_ok", changed, False)
    _set(m, "yaw_ref", take, r_kin)
    _set(m, "yaw_ref_ok", take, True)
    m.yaw_same, trip = _frozen(m.yaw_same, check & (np.abs(r_kin - m.yaw_ref) > move_yaw), steps)
    m.latched |= np.where(trip, pl.FROZEN_YAW, 0)
    on = act & lat_ok  # a_y against the yaw rate
    changed = on & (lat != m.lat_last)
    _set(m, "lat_last", changed, lat)
    _set(m, "lat_same", changed, 0)
    _set(m, "lat_ref", changed, r)
    moved = on & ~changed & (np.abs(r - m.lat_ref) > move_yaw)
    m.lat_same, trip = _frozen(m.lat_same, moved, steps)
    m.latched |= np.where(trip, pl.FROZEN_LAT, 0)
    on = act & st2_ok  # each steering channel against the other
    changed = on & (d != m.st_last)
    take = on & ~changed & new & ~m.st_ref_ok
    check = on & ~changed & ~take & m.st_ref_ok
    _set(m, "st_last", changed, d)
    _set(m, "st_same", changed, 0)
    _set(m, "st_ref_ok", changed, False)
    _set(m, "st_ref", take, d2)
    _set(m, "st_ref_ok", take, True)
    m.st_same, trip = _frozen(m.st_same, check & (np.abs(d2 - m.st_ref) > move_st), steps)
    m.latched |= np.where(trip, pl.FROZEN_STEER, 0)
    changed = on & (d2 != m.st2_last)
    _set(m, "st2_last", changed, d2)
    _set(m, "st2_same", changed, 0)
    _set(m, "st2_ref", changed, d)
    moved = on & ~changed & (np.abs(d - m.st2_ref) > move_st)
    m.st2_same, trip = _frozen(m.st2_same, moved, steps)
    m.latched |= np.where(trip, pl.FROZEN_STEER_2, 0)


def frozen_steady(m: BatchMonitor, d, d2, r, lat, v, latched: np.ndarray, lat_quiet: bool, st2_quiet: bool) -> None:
    """The four frozen checks in a period without a new redundant sample, every row checking
    (a_y and the second channel held: unchanged), their trips latched into ``latched``.
    ``lat_quiet``, ``st2_quiet``: no row's a_y or second-channel counter can reach its cap this
    period (its largest value at the last full period plus the periods since is below
    ``frozen_steps``), so it only counts."""
    c = m.c
    steps, move_yaw, move_st = c.frozen_steps, c.frozen_move_yaw, c.frozen_move_steer
    # the yaw rate against a_y / v
    same = r == m.yaw_last
    check = same & m.yaw_ref_ok
    m.yaw_last = np.where(same, m.yaw_last, r)
    m.yaw_same = np.where(same, m.yaw_same, 0)
    m.yaw_ref_ok = check
    if check.any():
        moved = check & (np.abs(lat * (1.0 / v) - m.yaw_ref) > move_yaw)
        _frozen_held(m.yaw_same, moved, steps, latched, pl.FROZEN_YAW)
    # a_y against the yaw rate (a_y held: unchanged)
    moved = np.abs(r - m.lat_ref) > move_yaw
    if lat_quiet:
        m.lat_same += moved
    else:
        _frozen_held(m.lat_same, moved, steps, latched, pl.FROZEN_LAT)
    # each steering channel against the other (the second held: unchanged)
    same = d == m.st_last
    check = same & m.st_ref_ok
    m.st_last = np.where(same, m.st_last, d)
    m.st_same = np.where(same, m.st_same, 0)
    m.st_ref_ok = check
    if check.any():
        moved = check & (np.abs(d2 - m.st_ref) > move_st)
        _frozen_held(m.st_same, moved, steps, latched, pl.FROZEN_STEER)
    moved = np.abs(d - m.st2_ref) > move_st
    if st2_quiet:
        m.st2_same += moved
    else:
        _frozen_held(m.st2_same, moved, steps, latched, pl.FROZEN_STEER_2)
