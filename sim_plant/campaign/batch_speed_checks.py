"""The plausibility monitor's two checks on the speed, vectorised over a batch: check 6 (the
speed's jump) and check 8 (the speed pair, the speed against ``RedundantSensors_Speed2``).

They are apart from ``batch_monitor`` because ``monitor_step`` runs them before everything else,
in every row and every period, before its pause below ``speed_min`` (a drifting or stuck speed
must not pause the checks that would find it), so none of the monitor's paths (the full one, the
shortcut between redundant samples, the one with rows paused) shares any of their arithmetic.
``BatchMonitor.step`` calls ``SpeedChecks.step`` first; ``tests/test_campaign_engine.py`` holds
both equal to the scalar code row by row.
"""

from __future__ import annotations

import numpy as np

from firmware_py import plausibility as pl


class SpeedChecks:
    """``MonitorState``'s speed slots for N rows (``speed_seen``, ``speed_last``, ``speed_lag``,
    ``speed2_seen``, ``speed_pair_count``, ``speed_pair_err``) and the two checks on them."""

    def __init__(self, c: pl.MonitorCoefficients, n: int) -> None:
        self.c = c
        self.speed_last, self.speed_pair_err, self.speed_lag = np.zeros(n), np.zeros(n), np.zeros(n)
        self.speed_seen, self.speed2_seen = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        self.speed_pair_count = np.zeros(n, dtype=np.int64)
        self._v_checked: np.ndarray | None = None  # the speed array the jump check last saw
        self._pair_of: tuple[np.ndarray | None, np.ndarray | None] = (None, None)  # (v, v2) the pair's masks are of
        self._both = self._over = self._low = self._over_braking = np.zeros(n, dtype=bool)
        self._err = self._err_braking = np.zeros(n)
        self._slipped = False  # some row's allowance acted in the period before
        self._lost: np.ndarray | bool = False
        self._has_pair = False  # this period's second speed was an array (not None)

    def step(self, v: np.ndarray, v2: np.ndarray | None, latched: np.ndarray) -> np.ndarray | bool:
        """Checks 6 and 8 for this period's speed ``v`` and second speed ``v2`` (None: NaN in
        every row, a car without it), their trips OR-ed into ``latched`` in place; returns the
        rows whose second speed is lost (``monitor_step``'s MISSING: it was received since the
        reset, it is missing now, the speed is valid), or False for none."""
        braking = self._lag(v)
        self._jump(v, latched)
        return self._pair(v, v2, latched, braking)

    def _lag(self, v: np.ndarray) -> np.ndarray:
        """The speed through ``speed_brake_tau``'s lag, every period (it moves while the speed is
        held); returns the rows where it stays above the speed by a fall at ``speed_brake_decel``
        or more (``monitor_step``'s braking)."""
        with np.errstate(invalid="ignore"):
            ok = (0.0 <= v) & (v < 1e3)
            lag = self.speed_lag
            moved = lag + self.c.speed_brake_alpha * (v - lag)
            self.speed_lag = np.where(ok, np.where(self.speed_seen, moved, v), lag)
            return ok & (self.speed_lag - v > self.c.speed_brake_lag)

    def _jump(self, v: np.ndarray, latched: np.ndarray) -> None:
        """Check 6, the speed's jump; nothing to do for the very array it last saw (the speed held)."""
        if v is self._v_checked:
            return
        self._v_checked = v
        with np.errstate(invalid="ignore"):
            ok = (0.0 <= v) & (v < 1e3)
            jump = ok & self.speed_seen & (v != self.speed_last) & (np.abs(v - self.speed_last) > self.c.speed_step)
        np.bitwise_or(latched, pl.CHECK_SPEED, out=latched, where=jump)
        self.speed_last = np.where(ok, v, self.speed_last)
        self.speed_seen = ok

    def _pair(self, v: np.ndarray, v2: np.ndarray | None, latched: np.ndarray,
              braking: np.ndarray) -> np.ndarray | bool:
        """Check 8: |v - v2| over ``speed_pair_bound + speed_pair_rel min(v, v2)`` (plus
        ``speed_slip_rel min(v, v2)`` in the ``braking`` rows whose second speed is the lower)
        counted up, else down, per period (trips at ``speed_pair_steps``); the count 0 where
        either speed is missing.  Both speeds are held for several periods: their masks are
        formed once per pair of arrays (with and without the braking allowance), the count
        moves every period."""
        c = self.c
        self._has_pair = v2 is not None
        if v2 is None:
            self.speed_pair_count.fill(0)
            if not self.speed2_seen.any():
                return False
            with np.errstate(invalid="ignore"):
                return self.speed2_seen & (0.0 <= v) & (v < 1e3)
        if self._pair_of[0] is not v or self._pair_of[1] is not v2:
            self._pair_of = (v, v2)
            with np.errstate(invalid="ignore"):
                ok2 = (0.0 <= v2) & (v2 < 1e3)
                ok = (0.0 <= v) & (v < 1e3)
                self._lost = (~ok2 & self.speed2_seen & ok) if (~ok2).any() else False
                self.speed2_seen = self.speed2_seen | ok2
                both = ok2 & ok
                e = np.abs(v - v2)
                x = np.where(v < v2, v, v2)
                bound = c.speed_pair_bound + c.speed_pair_rel * x
                wide = bound + c.speed_slip_rel * x  # monitor_step's bound += speed_slip_rel x
                self._err, self._err_braking = e / bound, e / wide
                self.speed_pair_err = np.where(both, self._err, self.speed_pair_err)
                self._both, self._over = both, both & (e > bound)
                self._low, self._over_braking = both & (v2 < v), both & (e > wide)
        over = self._over
        slipping = braking & self._low
        if slipping.any():
            over = np.where(slipping, self._over_braking, over)
            err = np.where(slipping, self._err_braking, self._err)
            self.speed_pair_err = np.where(self._both, err, self.speed_pair_err)
            self._slipped = True
        elif self._slipped:  # the allowance ended: the plain bound's fractions again
            self.speed_pair_err = np.where(self._both, self._err, self.speed_pair_err)
            self._slipped = False
        count = self.speed_pair_count
        if over.any():
            count = np.where(over, count + 1, np.where(count > 0, count - 1, count))
            trip = over & (count >= c.speed_pair_steps)
            count = np.where(trip, c.speed_pair_steps, count)
            np.bitwise_or(latched, pl.CHECK_SPEED_PAIR, out=latched, where=trip)
        elif count.any():
            count = np.maximum(count - 1, 0)
        self.speed_pair_count = count if self._both.all() else np.where(self._both, count, 0)
        return self._lost

    def vouched(self) -> np.ndarray | bool:
        """The rows where this period's second speed is there and agrees with the speed (both
        valid, the pair's count at 0, the difference within the plain bound, whatever the
        braking allowance): ``monitor_step``'s ``speed_vouched``, which out-votes the
        steady-turn check."""
        return self._has_pair and self._both & (self.speed_pair_count == 0) & ~self._over
