"""Issue 18's plausibility monitor vectorised over a batch, for the batch engine:
``firmware_py.plausibility.monitor_step`` for N rows at once (its authority limiter is
``batch_authority``).

``BatchMonitor.step`` is the scalar function statement for statement on arrays: each branch of
the scalar code a mask in its order, the counters and the latched bits int arrays, the state one
array per slot of ``MonitorState``.  The coefficients are the firmware's own
(``plausibility.configure``).  ``tests/test_campaign_engine.py`` holds it equal to the scalar
code row by row and period by period: the bits, the flags, the counters, the residuals.

``engine`` runs it before the law, as the controller node does (its suspicion of the yaw rate
holds the law), with the yaw-rate sensor's second element (``yaw_rate_redundant``) every
period and the second speed held at the redundant frame.  The two checks on the speed, which
run before the pause in every row (6 and 8, the speed pair), are ``batch_speed_checks``', the
frozen checks (5) ``batch_frozen``'s.
``step`` has a shortcut for the periods between redundant samples (the scalar's branches for
such a period, checked by the same tests).
"""

from __future__ import annotations

import numpy as np

from firmware_py import plausibility as pl
from sim_plant.campaign.batch_authority import within
from sim_plant.campaign.batch_frozen import frozen_checks, frozen_steady
from sim_plant.campaign.batch_speed_checks import SpeedChecks


def _count(count: np.ndarray, over: np.ndarray, runs: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """A net counter of ``monitor_step``: +1 over the bound (held at ``steps``), else -1 down to
    0, in the rows where the check ``runs``; the new counts and the rows it trips in."""
    up = runs & over
    down = runs & ~over & (count > 0)
    count = np.where(up, count + 1, np.where(down, count - 1, count))
    trip = up & (count >= steps)
    return np.where(trip, steps, count), trip


_FLOATS = ("lat_prev", "steer2_prev", "r_model", "yaw_last", "yaw_ref", "lat_last", "lat_ref", "st_last", "st_ref",
           "st2_last", "st2_ref", "kin_err", "pair_err", "model_err", "raw_prev", "beta_prev",
           "lat_beta_prev", "aux_lag", "yaw_pair_err", "delta_lag", "lag_beta_prev", "turn_r0", "turn_a0",
           "turn_res", "turn_r", "turn_err", "jump_prev")
_INTS = ("kin_count", "pair_count", "model_count", "yaw_same", "lat_same", "st_same", "st2_same", "latched",
         "flags", "bits", "kin_idx", "kin_n", "since", "yaw_pair_idx", "yaw_pair_n", "turn_n", "yaw_hold_n",
         "yaw_clear_n", "steer_hold_n")
_BOOLS = ("started", "have_sample", "yaw_ref_ok", "st_ref_ok", "yaw2_seen", "turn_settled", "jump_ok")
#: every value the detailed flags can take (up to their highest bit, whichever check has it)
_FLAG_VALUES = 2 * max(pl.SUSPECT_YAW_PAIR, pl.CHECK_SPEED_PAIR, pl.SUSPECT_STEER_JUMP, pl.OUTSIDE_MODEL)


class BatchMonitor:
    """N plausibility monitors (``monitor_step``) configured with one ``PlausibilityConfig``:
    one array per ``MonitorState`` slot (the kinematic windows (KIN_WINDOW, N)), every branch of
    the scalar code a mask in its order."""

    def __init__(self, config: pl.PlausibilityConfig, n: int) -> None:
        self.c = pl.configure(config)
        for name in _FLOATS:
            setattr(self, name, np.zeros(n))
        for name in _INTS:
            setattr(self, name, np.zeros(n, dtype=np.int64))
        for name in _BOOLS:
            setattr(self, name, np.zeros(n, dtype=bool))
        self.kin_raw = np.zeros((pl.KIN_WINDOW, n))
        self.kin_comp = np.zeros((pl.KIN_WINDOW, n))
        self.kin_lat = np.zeros((pl.KIN_WINDOW, n))
        self.kin_sensor = np.zeros((pl.KIN_WINDOW, n))
        self.yaw_pair = np.zeros((pl.YAW_PAIR_WINDOW, n))
        self._cols = np.arange(n)
        #: checks 6 and 8 (the speed's jump and the speed pair) and their state slots
        self.speeds = SpeedChecks(self.c, n)
        self._speed2_lost: np.ndarray | bool = False  # this period's rows with the second speed lost
        self._pair: tuple[np.ndarray | None, np.ndarray | None] = (None, None)  # the last period's lat, d2
        self._pair_ok = False  # the pair present in every row at the last full period
        self._all_started = False  # every row started after it
        self.steady_periods = 0  # periods that took the shortcut (``step``)
        self._v_seen: np.ndarray | None = None  # the speed array the shortcut's model denominator is of
        self._den = np.zeros(n)
        self._lat_max = self._st2_max = self._run = 0  # the counters' largest values at the last full period
        #: the CtrlStatus_Plausibility bits of each value of the detailed flags
        self._bits_of = np.array([(pl.PLAUS_YAW if f & pl.YAW_CHECKS else 0) | (pl.PLAUS_STEER if f & pl.STEER_CHECKS
                                                                               else 0)
                                  | (pl.PLAUS_DEGRADED if f & pl.DEGRADED_CHECKS else 0) for f in range(_FLAG_VALUES)],
                                 dtype=np.int64)

    def _set(self, name: str, rows: np.ndarray, value) -> None:
        setattr(self, name, np.where(rows, value, getattr(self, name)))

    def step(self, d: np.ndarray, d2: np.ndarray, r: np.ndarray, lat: np.ndarray, v: np.ndarray,
             aux: np.ndarray, r2: np.ndarray | None = None, v2: np.ndarray | None = None) -> np.ndarray:
        """``monitor_step(c, s, delta_driver=d, delta_driver_redundant=d2, yaw_rate=r,
        lat_accel=lat, speed=v, aux_cmd_applied=aux, yaw_rate_redundant=r2,
        speed_redundant=v2)`` per row (``r2``, ``v2`` None: NaN in every row, the car without
        the second element, the second speed); the CtrlStatus_Plausibility bits.

        A caller that holds the redundant pair between its samples (the node's 50 ms frame)
        passes the very same two arrays, unmodified, until the next sample.  A period in which
        they are the arrays of the period before, the pair is present in every row, the primary
        inputs are in range and no row starts its checks afresh takes ``_steady``: the scalar's
        branches for a period without a new sample, and nothing else (``_steady_pausing`` when
        some rows are below ``speed_min``)."""
        self._speed2_lost = self.speeds.step(v, v2, self.latched)  # (before the pause, in every path)
        if (lat is self._pair[0] and d2 is self._pair[1] and self._pair_ok and within(d) and within(r)
                and within(aux) and within(v, -1e3)):
            # every primary input in range but perhaps the speed: the rows below speed_min pause
            act = None if v.min() >= self.c.speed_min else v >= self.c.speed_min
            if act is None and self._all_started or act is not None and not (act & ~self.started).any():
                self.steady_periods += 1
                if act is None:
                    return self._steady(d, d2, r, lat, v, aux, r2)
                return self._steady_pausing(d, d2, r, lat, v, aux, r2, act)
        bits = self._full(d, d2, r, lat, v, aux, r2)
        self._pair = (lat, d2)
        self._pair_ok = not (self.flags & pl.MISSING).any()
        self._all_started = bool(self.started.all())
        self._lat_max, self._st2_max, self._run = int(self.lat_same.max()), int(self.st2_same.max()), 0
        return bits

    def _full(self, d: np.ndarray, d2: np.ndarray, r: np.ndarray, lat: np.ndarray, v: np.ndarray,
              aux: np.ndarray, r2: np.ndarray | None) -> np.ndarray:
        """Every branch of ``monitor_step`` as a mask, in its order."""
        c = self.c
        with np.errstate(all="ignore"):  # a paused row's arithmetic (NaN, 1/0) is computed and dropped
            flags = self.latched.copy()
            act = ((-1e3 < d) & (d < 1e3) & (-1e3 < r) & (r < 1e3) & (c.speed_min <= v) & (v < 1e3)
                   & (-1e3 < aux) & (aux < 1e3))
            lat_ok = (-1e3 < lat) & (lat < 1e3)
            st2_ok = (-1e3 < d2) & (d2 < 1e3)
            missing = ~(lat_ok & st2_ok)
            flags |= np.where(missing | self._lost(r, r2) | self._speed2_lost, pl.MISSING, 0)
            self._set("turn_n", missing, 0)  # the steady-turn check starts afresh when the frame is back
            self._set("turn_settled", missing, False)
            gap = missing & (self.since >= c.kin_gap_steps)  # a shorter gap is bridged (the scalar's comment)
            self._set("have_sample", gap, False)
            self._set("kin_n", gap, 0)
            paused = ~act
            for name in ("kin_count", "pair_count", "model_count", "yaw_same", "lat_same", "st_same", "st2_same",
                         "kin_n", "turn_n"):
                self._set(name, paused, 0)
            self._set("turn_settled", paused, False)
            self._set("started", paused, False)
            paired = self._paired(r2)  # the pair's state before this sample, as the model check reads it
            flags |= self._yaw_pair(act, r, r2)  # before the kinematic check, whose bound reads its window
            flags |= self._checks(act, lat_ok, st2_ok, d, d2, r, lat, v, aux, paired)
            flags |= self.latched
        bits = (np.where((flags & pl.YAW_CHECKS) != 0, pl.PLAUS_YAW, 0)
                | np.where((flags & pl.STEER_CHECKS) != 0, pl.PLAUS_STEER, 0)
                | np.where((flags & pl.DEGRADED_CHECKS) != 0, pl.PLAUS_DEGRADED, 0))
        self.flags, self.bits = flags, bits
        return bits

    # The active rows' part of monitor_step, in its order (model, kinematic and pair at a new
    # redundant sample, frozen); long because it is the scalar's four checks inline.  Returns the
    # steering pair's suspicion (flags, not latched).
    def _checks(self, act, lat_ok, st2_ok, d, d2, r, lat, v, aux, paired) -> np.ndarray:
        c = self.c
        inv_v = 1.0 / v
        r_kin = np.where(lat_ok, lat * inv_v, 0.0)
        init = act & ~self.started
        self._set("aux_lag", init, aux)
        self._set("aux_lag", act, self.aux_lag + c.aux_alpha * (aux - self.aux_lag))
        delta = d + self.aux_lag
        r_ss = delta * v / (c.wheelbase + c.k_us * v * v)
        for name, value in (("r_model", r_ss), ("kin_n", 0), ("kin_idx", 0), ("since", 0), ("have_sample", False),
                            ("lat_prev", lat), ("steer2_prev", d2), ("yaw_last", r), ("lat_last", lat),
                            ("st_last", d), ("st2_last", d2), ("yaw_ref", r_kin), ("lat_ref", r), ("st_ref", d2),
                            ("st2_ref", d), ("yaw_ref_ok", False), ("st_ref_ok", False), ("delta_lag", delta),
                            ("turn_n", 0), ("turn_settled", False), ("started", True)):
            self._set(name, init, value)
        self._set("delta_lag", act, self.delta_lag + c.delta_alpha * (delta - self.delta_lag))
        self._set("r_model", act, self.r_model + c.model_alpha * (r_ss - self.r_model))
        e = np.abs(r - self.r_model)
        bound = c.model_margin + c.model_rel * np.abs(self.r_model)
        self._set("model_err", act, e / bound)
        vouched = paired & lat_ok & self._kin_agrees()
        self.model_count, trip = _count(self.model_count, (e > bound) & ~vouched, act, c.model_steps)
        self.latched |= np.where(trip, np.where(paired, pl.OUTSIDE_MODEL, pl.CHECK_MODEL), 0)
        self._set("since", act & (self.since < 1000000), self.since + 1)

        new = act & lat_ok & st2_ok & ((lat != self.lat_prev) | (d2 != self.steer2_prev))
        suspect = self._steer_jump(act, st2_ok, new, d)
        raw = r_kin - r
        beta = (c.moment_m * inv_v * inv_v * r + c.cf_m * inv_v * delta - r_kin) * c.inv_cs_m * v
        lat_beta = lat * c.inv_cs_m
        lag_beta = c.cf_m * inv_v * (self.delta_lag - delta) * c.inv_cs_m * v
        into = new & self.have_sample
        mid = 0.5 * (raw + self.raw_prev)
        i, cols = self.kin_idx, self._cols
        self.kin_raw[i, cols] = np.where(into, mid, self.kin_raw[i, cols])
        comp_now = mid - (beta - self.beta_prev) / (self.since * c.ts)
        self.kin_comp[i, cols] = np.where(into, comp_now, self.kin_comp[i, cols])
        lat_now = (lat_beta - self.lat_beta_prev) / (self.since * c.ts)
        self.kin_lat[i, cols] = np.where(into, lat_now, self.kin_lat[i, cols])
        sens_now = (self.lag_beta_prev - lag_beta) / (self.since * c.ts)
        self.kin_sensor[i, cols] = np.where(into, sens_now, self.kin_sensor[i, cols])
        self._set("kin_idx", into, np.where(i + 1 >= pl.KIN_WINDOW, 0, i + 1))
        self._set("kin_n", into & (self.kin_n < pl.KIN_WINDOW), self.kin_n + 1)
        self._set("have_sample", new, True)
        self._set("raw_prev", new, raw)
        self._set("beta_prev", new, beta)
        self._set("lat_beta_prev", new, lat_beta)
        self._set("lag_beta_prev", new, lag_beta)
        self._set("since", new, 0)
        kr, kc = self.kin_raw, self.kin_comp
        raw_avg = np.abs((kr[0] + kr[1] + kr[2] + kr[3]) * (1.0 / pl.KIN_WINDOW)) * c.inv_yaw_raw_fraction
        comp = (kc[0] + kc[1] + kc[2] + kc[3]) * (1.0 / pl.KIN_WINDOW)
        kl, ks = self.kin_lat, self.kin_sensor
        span = np.where(self.yaw_pair_n >= pl.YAW_PAIR_WINDOW, c.lat_span_paired, c.lat_span)
        far = span * ((kl[0] + kl[1] + kl[2] + kl[3]) * (1.0 / pl.KIN_WINDOW))
        sens = (ks[0] + ks[1] + ks[2] + ks[3]) * (1.0 / pl.KIN_WINDOW)
        # the family of nominal cars on mu in [mu_min, 1] (mu_min_paired while the pair runs) and
        # sensor lags in [0, sensor_tau]: 0 where its four corners differ in sign, else the
        # smallest corner's magnitude
        corners = (comp, comp + sens, comp + far, comp + far + sens)
        lo, hi = np.minimum.reduce(corners), np.maximum.reduce(corners)
        comp = np.where((lo <= 0.0) & (0.0 <= hi), 0.0, np.where(lo > 0.0, lo, -hi))
        e = np.where(comp < raw_avg, comp, raw_avg)
        e = np.where(self.kin_n < pl.KIN_WINDOW, 0.0, e)
        bound = c.yaw_bound + c.yaw_rel * np.minimum(np.abs(r_kin), np.abs(r))  # the smaller measure of the turn
        bound = np.where(self.yaw_pair_n >= pl.YAW_PAIR_WINDOW, bound + c.side_accel * inv_v, bound)
        self._set("kin_err", new, e / bound)
        self.kin_count, trip = _count(self.kin_count, e > bound, new, c.yaw_count)
        confirmed = (self.yaw_pair_n >= pl.YAW_PAIR_WINDOW) & (self.yaw_clear_n >= pl.YAW_PAIR_WINDOW)
        self.latched |= np.where(trip, np.where(confirmed, pl.OUTSIDE_MODEL, pl.CHECK_KINEMATIC), 0)
        e = np.abs(d - d2)
        self._set("pair_err", new, e * c.inv_steer_bound)
        self.pair_count, trip = _count(self.pair_count, e > c.steer_bound, new, c.steer_count)
        self.latched |= np.where(trip, pl.CHECK_STEER_PAIR, 0)
        self._turn(new, r, lat, v)
        self._set("lat_prev", act & lat_ok, lat)
        self._set("steer2_prev", act & st2_ok, d2)
        frozen_checks(self, act, lat_ok, st2_ok, new, d, d2, r, lat, r_kin)
        return suspect

    def _steer_jump(self, act: np.ndarray | None, st2_ok: np.ndarray | bool, new: np.ndarray | bool,
                    d: np.ndarray) -> np.ndarray:
        """The steering pair's suspicion in the rows that ``act`` (None: every row), as
        ``monitor_step`` has it: a jump of the driver's angle over ``steer_jump`` between two
        redundant samples holds for up to ``kin_gap_steps``, ended by a new sample or a missing
        second channel; a paused row forgets the angle before.  Returns the flags'
        SUSPECT_STEER_JUMP (not latched)."""
        c = self.c
        on = np.asarray(st2_ok) & ~np.asarray(new)  # the pair neither judging now nor unable to
        if act is not None:
            on = on & act
        e = d - self.jump_prev
        jumped = on & self.jump_ok & ((e > c.steer_jump) | (e < -c.steer_jump))
        hold = np.where(jumped, c.kin_gap_steps, self.steer_hold_n)
        suspect = on & (hold > 0)
        self.steer_hold_n = np.where(on, hold - suspect, 0)
        if act is None:
            self.jump_prev, self.jump_ok = d, np.ones_like(self.jump_ok)
        else:
            self.jump_prev, self.jump_ok = np.where(act, d, self.jump_prev), act.copy()
        return np.where(suspect, pl.SUSPECT_STEER_JUMP, 0)

    def _turn(self, new: np.ndarray, r: np.ndarray, lat: np.ndarray, v: np.ndarray) -> None:
        """Check 7, the speed against a_y / r in a steady turn, in the rows with a new sample."""
        c = self.c
        low = new & (np.abs(r) < c.turn_yaw_min)
        turn = new & ~low
        away = turn & (self.turn_n > 0) & ((np.abs(r - self.turn_r0) > c.turn_yaw_tol)
                                           | (np.abs(lat - self.turn_a0) > c.turn_lat_tol + c.turn_lat_rel
                                              * np.abs(self.turn_a0)))
        restart = low | away
        self._set("turn_n", restart, 0)
        self._set("turn_settled", restart, False)
        if not turn.any():
            return
        first = turn & (self.turn_n == 0)
        for name, value in (("turn_r0", r), ("turn_a0", lat), ("turn_res", 0.0), ("turn_r", 0.0)):
            self._set(name, first, value)
        self._set("turn_res", turn, self.turn_res + (r * v - lat))
        self._set("turn_r", turn, self.turn_r + r)
        self._set("turn_n", turn, self.turn_n + 1)
        full = turn & (self.turn_n >= pl.TURN_BLOCK)
        if full.any():
            e = np.abs(self.turn_res / self.turn_r)
            rm = np.abs(self.turn_r * (1.0 / pl.TURN_BLOCK))
            bound = c.turn_speed_rel * v + (c.turn_yaw_bias * v + c.turn_lat_bias) / rm
            judged = full & self.turn_settled
            self._set("turn_err", judged, e / bound)
            self.latched |= np.where(judged & (e > bound) & ~self.speeds.vouched(), pl.CHECK_TURN, 0)
            self._set("turn_settled", full, True)
            self._set("turn_n", full, 0)

    def _paired(self, r2: np.ndarray | None) -> np.ndarray | bool:
        """The rows whose yaw rate its second element confirms (``monitor_step``'s ``confirmed``,
        half of ``vouched``, read before this sample enters the pair's window): the element
        valid now, the window full and its last samples within ``yaw_pair_hold``."""
        if r2 is None:
            return False
        return ((-1e3 < r2) & (r2 < 1e3) & (self.yaw_pair_n >= pl.YAW_PAIR_WINDOW)
                & (self.yaw_clear_n >= pl.YAW_PAIR_WINDOW))

    def _kin_agrees(self) -> np.ndarray:
        """The rows whose yaw rate a_y / v confirms (the other half of ``vouched``, with a_y
        valid): a full kinematic window within its bound."""
        return (self.kin_n >= pl.KIN_WINDOW) & (self.kin_count == 0)

    def _lost(self, r: np.ndarray, r2: np.ndarray | None) -> np.ndarray | bool:
        """The rows whose second yaw-rate element is missing after it was received, the first
        valid (``monitor_step``'s lost element: DEGRADED); marks the rows that have it now
        (so a second call in the same period gives the same rows)."""
        if r2 is None:
            return False if not self.yaw2_seen.any() else self.yaw2_seen & (-1e3 < r) & (r < 1e3)
        ok = (-1e3 < r2) & (r2 < 1e3)
        lost = ~ok & self.yaw2_seen & (-1e3 < r) & (r < 1e3)
        self.yaw2_seen |= ok
        return lost

    def _yaw_pair(self, act: np.ndarray | None, r: np.ndarray, r2: np.ndarray | None) -> np.ndarray | int:
        """Check 4, the yaw-rate pair, in the rows that ``act`` (None: every row): the mean of
        r - r2 over the last ``YAW_PAIR_WINDOW`` samples; a row without the second element
        (NaN, or ``r2`` None) or paused restarts its window.  Returns the flags' SUSPECT_YAW_PAIR
        (not latched): the rows whose latest r - r2 is over ``yaw_pair_hold`` (``monitor_step``'s
        suspicion, at most ``YAW_PAIR_WINDOW`` samples until as many within it re-arm it)."""
        if r2 is None:
            self.yaw_pair_n.fill(0)
            return 0
        c, w = self.c, self.yaw_pair
        ok = (-1e3 < r2) & (r2 < 1e3)
        if act is not None:
            ok &= act
        i, cols = self.yaw_pair_idx, self._cols
        apart = r - r2  # this sample of the pair: into the window, and the suspicion's
        w[i, cols] = np.where(ok, apart, w[i, cols])
        self.yaw_pair_idx = np.where(ok, np.where(i + 1 >= pl.YAW_PAIR_WINDOW, 0, i + 1), i)
        self.yaw_pair_n = np.where(ok, np.minimum(self.yaw_pair_n + 1, pl.YAW_PAIR_WINDOW), 0)
        full = ok & (self.yaw_pair_n >= pl.YAW_PAIR_WINDOW)
        e = np.abs((w[0] + w[1] + w[2] + w[3] + w[4]) * (1.0 / pl.YAW_PAIR_WINDOW))
        self.yaw_pair_err = np.where(full, e * c.inv_yaw_pair_bound, self.yaw_pair_err)
        np.bitwise_or(self.latched, pl.CHECK_YAW_PAIR, out=self.latched, where=full & (e > c.yaw_pair_bound))
        # the suspicion, capped so that an offset the window never confirms cannot freeze the law
        over = ok & ((apart > c.yaw_pair_hold) | (apart < -c.yaw_pair_hold))
        suspect = over & (self.yaw_hold_n < pl.YAW_PAIR_WINDOW)
        self.yaw_hold_n += suspect
        clear = ok & ~over
        self.yaw_clear_n = np.where(over, 0, self.yaw_clear_n + (clear & (self.yaw_clear_n < pl.YAW_PAIR_WINDOW)))
        self.yaw_hold_n = np.where(clear & (self.yaw_clear_n >= pl.YAW_PAIR_WINDOW), 0, self.yaw_hold_n)
        return np.where(suspect, pl.SUSPECT_YAW_PAIR, 0)

    # monitor_step's path for a period without a new redundant sample, every row checking: the
    # model check, the count since the last sample and the four frozen checks with new_sample
    # False (``kin_*``, ``pair_*``, ``lat_prev``, ``steer2_prev`` keep their values: the scalar
    # writes the value they hold).  Long because it is those checks inline.
    def _steady_pausing(self, d, d2, r, lat, v, aux, r2, act: np.ndarray) -> np.ndarray:
        """``_steady`` for the rows that ``act``; the others paused as ``monitor_step`` pauses a
        row below ``speed_min``: its counters and windows at 0, not started, the rest untouched."""
        kept = {k: getattr(self, k) for k in ("r_model", "model_err", "since", "yaw_last", "yaw_ref_ok", "st_last",
                                              "st_ref_ok", "aux_lag", "delta_lag", "jump_prev")}
        latched = self.latched.copy()
        with np.errstate(all="ignore"):  # a paused row's arithmetic (a speed of 0) is dropped
            self._steady(d, d2, r, lat, v, aux, r2, act)
        for k, old in kept.items():
            setattr(self, k, np.where(act, getattr(self, k), old))
        for k in ("model_count", "yaw_same", "lat_same", "st_same", "st2_same", "kin_count", "pair_count", "kin_n",
                  "turn_n"):
            setattr(self, k, np.where(act, getattr(self, k), 0))
        self.turn_settled = self.turn_settled & act
        self.started = self.started & act
        self.latched = np.where(act, self.latched, latched)
        self.flags = (self.latched | np.where(self._lost(r, r2) | self._speed2_lost, pl.MISSING, 0)
                      | (self.flags & pl.SUSPECT_CHECKS))
        self.bits = self._bits_of[self.flags]
        return self.bits

    def _steady(self, d, d2, r, lat, v, aux, r2, act: np.ndarray | None = None) -> np.ndarray:
        c, latched = self.c, self.latched
        if v is not self._v_seen:  # the speed is held for several periods: the model's denominator once
            self._v_seen, self._den = v, c.wheelbase + c.k_us * v * v
        self.aux_lag = self.aux_lag + c.aux_alpha * (aux - self.aux_lag)
        delta = d + self.aux_lag
        self.delta_lag = self.delta_lag + c.delta_alpha * (delta - self.delta_lag)
        r_ss = delta * v / self._den
        self.r_model = self.r_model + c.model_alpha * (r_ss - self.r_model)
        e = np.abs(r - self.r_model)
        bound = c.model_margin + c.model_rel * np.abs(self.r_model)
        self.model_err = e / bound
        over = e > bound
        if over.any():  # +1 held at model_steps, else -1 down to 0 (_count)
            over &= ~(self._paired(r2) & self._kin_agrees())  # out-voted (the redundant frame valid in every row)
            count = np.minimum(np.maximum(self.model_count + np.where(over, 1, -1), 0), c.model_steps)
            trip = over & (count >= c.model_steps)
            if trip.any():
                latched |= np.where(trip, np.where(self._paired(r2), pl.OUTSIDE_MODEL, pl.CHECK_MODEL), 0)
        else:
            count = np.maximum(self.model_count - 1, 0)
        self.model_count = count
        self.since = np.minimum(self.since + 1, 1000000)
        # A frozen counter whose largest value, plus the periods since the last full one, stays
        # below frozen_steps can neither reach its cap nor trip: it only counts.
        self._run += 1
        frozen_steady(self, d, d2, r, lat, v, latched, self._lat_max + self._run < c.frozen_steps,
                      self._st2_max + self._run < c.frozen_steps)
        suspect = self._yaw_pair(act, r, r2)  # (latches into self.latched, which is latched)
        suspect = suspect | self._steer_jump(act, True, False, d)
        self.flags = latched | np.where(self._lost(r, r2) | self._speed2_lost, pl.MISSING, 0) | suspect
        self.bits = self._bits_of[self.flags]
        return self.bits

