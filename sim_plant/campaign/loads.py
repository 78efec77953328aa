"""The disturbances' loads and the scenario's yaw-moment step for a batch, a block of steps at a
time: ``disturbances.SplitMuBraking``, ``SideWindGust`` and ``TyreBlowout`` ``.at(t)`` and the
scenario's ``yaw_moment`` event, evaluated as arrays of shape (steps, rows).

The loads depend on time and on the sample only, never on the car's state, so they are computed
ahead in blocks (``BLOCK`` steps) with one numpy operation per block instead of per step.  Each
formula repeats its scalar model's arithmetic; a row of another kind gets exact zeros, which
leave the sums of ``plants.Car`` unchanged.

Once every row's ramps have ended and its events fired, the loads no longer change: a block
from then on is the first such step's values broadcast over the block (computed once), which
the formulas give bitwise (a ramp is exactly 1 from ``start + duration`` on).
"""

from __future__ import annotations

import numpy as np

from sim_plant.car import disturbances as dist
from sim_plant.car.tyres import G, static_axle_loads
from sim_plant.campaign.params import KINDS, SampleSet

BLOCK = 64
#: Events fire when their time is within this of the step's (``ScenarioState.advance_to``).
EVENT_SLACK = 1e-12
YAW, SPLIT, WIND, BLOWOUT = (KINDS.index(k) for k in ("yaw_moment", "split_mu_braking", "side_wind", "blowout"))
_SPLIT, _WIND, _BLOW = dist.SplitMuBraking(), dist.SideWindGust(), dist.TyreBlowout()


def ramp(t: np.ndarray, start: np.ndarray, duration: float) -> np.ndarray:
    """``disturbances._ramp``: 0 up to ``start``, 1 after ``start + duration``, 1 - cos between."""
    if duration <= 0.0:
        return np.where(t <= start, 0.0, 1.0)
    # 0.5 (1 - cos x) = tan^2(x/2) / (1 + tan^2(x/2)): numpy's float64 tan is vectorised, its cos
    # is not; x kept within [0, pi] (the other times take the branches' 0 and 1)
    half = np.tan((0.5 * np.pi) * (np.clip(t - start, 0.0, duration) / duration))
    half *= half
    mid = half / (1.0 + half)
    return np.where(t <= start, 0.0, np.where(t >= start + duration, 1.0, mid))


def ended(t: float, ramps: list[tuple[np.ndarray, float]]) -> bool:
    """Every ``ramp(t', start, duration)`` of ``ramps`` is 1 for every row at every t' >= t
    (``ramp``'s own comparisons: past ``start`` and at or past ``start + duration``)."""
    return all(start.size == 0 or (t > start.max() and (duration <= 0.0 or t >= (start + duration).max()))
               for start, duration in ramps)


class _Settling:
    """A block of loads from the step on which nothing changes any more (``_ended``: every
    ramp ended, every event fired) is that step's values, computed once, broadcast over the
    block (read-only views)."""

    _steady: dict | None = None

    def _ended(self, t: float) -> bool:
        raise NotImplementedError

    def block(self, t: np.ndarray) -> dict:
        if not self._ended(float(t[0, 0])):
            return self._block(t)
        if self._steady is None:
            self._steady = self._block(t[:1])
        steps = t.shape[0]
        return {k: v if v is None else np.broadcast_to(v, (steps,) + v.shape[1:]) for k, v in self._steady.items()}

    def _block(self, t: np.ndarray) -> dict:
        raise NotImplementedError


class IntactLoads(_Settling):
    """Rows of the yaw-moment step and the side-wind gust: all wheels keep their grip, v its value."""

    def __init__(self, s: SampleSet) -> None:
        kind = s["disturbance"]
        self.onset = s["onset"]
        self.m_step = np.where(kind == YAW, s["yaw_moment"], 0.0)
        self.is_yaw = kind == YAW
        self.wind = np.where(kind == WIND, s["wind_force"], 0.0)
        self.any_wind = bool((kind == WIND).any())
        g = _WIND
        self._last_event = float(self.onset.max()) if self.onset.size else 0.0
        self._ramps = [(self.onset, g.rise_time), (self.onset + g.rise_time + g.hold_time, g.fall_time)]

    def _ended(self, t: float) -> bool:
        return t + EVENT_SLACK >= self._last_event and (not self.any_wind or ended(t, self._ramps))

    def _block(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """m_z (scene's step plus the loads'), f_y (or None) at times t (column)."""
        g = _WIND
        fired = self.onset <= t + EVENT_SLACK
        m_scene = np.where(fired & self.is_yaw, self.m_step, 0.0)
        if not self.any_wind:
            return {"m_z": m_scene + 0.0, "f_y": None}
        rise = ramp(t, self.onset, g.rise_time)
        fall = ramp(t, self.onset + g.rise_time + g.hold_time, g.fall_time)
        f = self.wind * (rise - fall)
        return {"m_z": m_scene + (0.0 + g.cp_ahead * f), "f_y": 0.0 + f}


class GripLoads(_Settling):
    """Rows of split-mu braking and the tyre blow-out: wheels' grip, a deceleration, a yaw moment."""

    def __init__(self, s: SampleSet, car) -> None:
        kind = s["disturbance"]
        self.split, self.blow = kind == SPLIT, kind == BLOWOUT
        self.onset, self.mu, self.mass = s["onset"], s["mu"], s["mass"]
        self.mu_right = np.where(self.split, s["mu_split"], self.mu)
        self.decel = np.where(self.split, s["deceleration"], 0.0)
        wheel = np.where(self.blow, s["blowout_wheel"], -1)
        self.blown_rows = [np.flatnonzero(wheel == w) for w in range(4)]  # fl, fr, rl, rr
        f_zf, f_zr = static_axle_loads(self.mass, _BLOW.l_f, _BLOW.l_r)
        self.wheel_load = np.where(wheel <= 1, 0.5 * f_zf, 0.5 * f_zr)  # TyreBlowout.wheel_load
        self.side = np.where((wheel == 0) | (wheel == 2), 1.0, -1.0)
        self.car = car
        #: Only split-mu rows: each axle's wheels keep one B (only their mu differs), so they share
        #: the formula's sine (``BatchCar``).
        self.shared = not bool(self.blow.any())
        self._ramps = [(self.onset, _SPLIT.ramp), (self.onset, _BLOW.deflation_time)]
        self._kept: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # _wheels' arrays by block length

    def _ended(self, t: float) -> bool:
        return ended(t, self._ramps)  # (past every onset: SplitMuBraking.at's t >= t_start too)

    def _block(self, t: np.ndarray) -> dict[str, object]:
        sp, bl = _SPLIT, _BLOW
        on = t >= self.onset  # SplitMuBraking.at: nothing before t_start
        demand = 0.5 * self.mass * self.decel * ramp(t, self.onset, sp.ramp)
        side_load = 0.5 * self.mass * G
        f_l = np.minimum(demand, self.mu * side_load)
        f_r = np.minimum(demand, self.mu_right * side_load)
        split_on = on & self.split
        # SplitMuBraking.wheel_slip: ABS's slip on a side it caps, else the tyre's stiffness
        rolling = sp.slip_per_force * demand / side_load
        slip_l = np.where(demand > self.mu * side_load, sp.abs_slip, rolling)
        slip_r = np.where(demand > self.mu_right * side_load, sp.abs_slip, rolling)
        wheel_slip = np.where(split_on, 0.5 * (slip_l + slip_r), 0.0)
        m_split = np.where(split_on, (f_l - f_r) * sp.track_width / 2.0, 0.0)
        a_split = np.where(split_on, (f_l + f_r) / self.mass, 0.0)
        k = np.where(self.blow, ramp(t, self.onset, bl.deflation_time), 0.0)
        drag = k * bl.rolling_resistance * self.wheel_load
        blow_on = k != 0.0
        m_blow = np.where(blow_on, self.side * drag * bl.track_width / 2.0, 0.0)
        a_blow = np.where(blow_on, drag / self.mass, 0.0)
        stiffness = 1.0 - k * bl.stiffness_loss
        peak = 1.0 - k * bl.peak_loss
        mu_left = np.broadcast_to(self.mu, t.shape[:1] + self.mu.shape)
        mu_right = np.where(split_on, self.mu_right, self.mu)
        car, steps = self.car, t.shape[0]
        common = {"m_z": 0.0 + (m_split + m_blow), "f_y": None, "a_x": 0.0 + (a_split + a_blow),
                  "mu_max": np.maximum(self.mu, mu_right), "wheel_slip": wheel_slip}
        if self.shared:  # B stiffness / peak with both fractions 1 is B itself
            b = np.stack([car.b_f, car.b_r])[None, :, None]  # (1, axle, 1, rows)
            d = np.empty((steps, 2, 2, self.mu.size))  # (step, axle, wheel, rows)
            for a, f_z in enumerate((car.f_zf, car.f_zr)):
                d[:, a, 0] = 0.5 * 1.0 * mu_left * f_z
                d[:, a, 1] = 0.5 * 1.0 * mu_right * f_z
            return {**common, "b": b, "d": d}
        b, d = self._wheels(steps)
        for a, f_z in enumerate((car.f_zf, car.f_zr)):  # the right wheels (split mu from the onset)
            np.multiply(0.5 * 1.0 * mu_right, f_z, out=d[:, a, 1])
        for w, rows in enumerate(self.blown_rows):  # fl, fr, rl, rr: the blown wheel's B and peak
            if rows.size == 0:
                continue
            # tyres.wheel_tyres' B stiffness / peak and 0.5 peak mu F_z (before the onset,
            # k = 0 makes both fractions exactly 1: the intact wheel's values)
            a, side = (0 if w <= 1 else 1), w % 2
            b_axle, f_z = (car.b_f, car.f_zf) if a == 0 else (car.b_r, car.f_zr)
            st, pk = stiffness[:, rows], peak[:, rows]
            b[:, a, side, rows] = b_axle[rows] * st / pk
            d[:, a, side, rows] = 0.5 * pk * (mu_left if side == 0 else mu_right)[:, rows] * f_z[rows]
        return {**common, "b": b, "d": d}

    def _wheels(self, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """(steps, axle, wheel, rows) arrays of B and the peak, kept from block to block: every
        wheel's values but the right wheels' peaks and the blown wheel's are constant, written
        once (a block's arrays are read only while it runs)."""
        if steps not in self._kept:
            car, n = self.car, self.mu.size
            b, d = np.empty((steps, 2, 2, n)), np.empty((steps, 2, 2, n))
            for a, (b_axle, f_z) in enumerate(((car.b_f, car.f_zf), (car.b_r, car.f_zr))):
                b[:, a] = b_axle  # B stiffness / peak with both fractions 1 is B itself
                d[:, a, 0] = 0.5 * 1.0 * self.mu * f_z
            self._kept[steps] = (b, d)
        return self._kept[steps]
