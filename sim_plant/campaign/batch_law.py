"""The firmware's control law (``firmware_py.model_regulator.step``) vectorised over a batch.

``BatchLaw.step`` is ``model_regulator.step`` for N controller instances at once, statement for
statement on arrays: the input checks and fault flags, the fade to zero while inactive or
faulted, the bumpless re-initialisation on the next valid step, the slew window while
recovering, the actuator clamp, and the recursion of the law itself: the coefficient set
interpolated over the speed breakpoints as ``step()`` does it (``_Schedule``), the nominal
actuator p_n and the nominal 2nd-order yaw-rate filter of issue 15's model, the command
history of the modelled delay.  The coefficients are the firmware's own
(``model_regulator.configure``); nothing is re-derived here.

The branches of the scalar code become masks: every row computes the active path (a row
whose speed is out of range or too slow at ``speed_active_min``), and a row that is inactive
or faulted this step takes the faded command, its status and ``needs_init``.  Its filter
states (z, p_n, the filter's, the history, ``recovering``) are left as the active path made
them, not as the scalar leaves them: none of them is read before the row's next valid step,
whose re-initialisation sets every one (so no state is saved and restored each period).  The
command history is one circular buffer with one index for all rows: a re-initialised row's
history is its held command in every slot, so where it starts reading does not matter.
The outputs (command, status, flags) are the scalar's.  The law's own recursion is in ``_law``
alone, so that a change of the law in the firmware changes one function here.

A period in which every row's inputs are in range and active (the common case) checks them as
minima and maxima, and a caller that holds the speed between its samples (the node's 10 ms
frame) passes the same array, unmodified, until the next: the speed's checks, 1/K_n and the
coefficient set are then the period before's.
"""

from __future__ import annotations

import numpy as np

from firmware_py import model_regulator as mr


class BatchLaw:
    """N instances of the model regulator configured with one calibration."""

    def __init__(self, config: mr.ControllerConfig, n: int) -> None:
        self.c = c = mr.configure(config)
        self.m = c.model_delay
        self.table = _Schedule(c)
        self.act = (c.act_a, c.act_b)  # the nominal actuator of the model
        self.flt = (c.flt_b0, c.flt_b1, c.flt_b2, c.flt_a1, c.flt_a2)  # the nominal yaw-rate filter
        self.z = np.zeros(n)
        self.u_prev = np.zeros(n)
        self.u_hist = np.zeros((max(self.m, 1), n))
        self.hist_idx = 0  # every row's (see the module's docstring)
        self.p_n = np.zeros(n)
        self.f_s1 = np.zeros(n)
        self.f_s2 = np.zeros(n)
        self.needs_init = np.ones(n, dtype=bool)
        self.recovering: np.ndarray | None = None  # None: no row recovering
        self.status = np.full(n, mr.STATUS_INACTIVE, dtype=np.int8)
        self.fault_flags = np.zeros(n, dtype=np.int8)
        self._flags_clear = True  # no row's fault_flags set
        self._needs_any = True  # some row needs_init
        self._speed: np.ndarray | None = None  # the speed array of the last period, and its terms:
        self._speed_ok = False  # every row's in [speed_active_min, speed_max]
        self._ok_speed = self._slow = self._law_speed = None  # the range check, below active, the law's speed
        self._inv_kn: np.ndarray | None = None

    def step(self, delta_driver: np.ndarray, yaw_rate: np.ndarray, speed: np.ndarray,
             hold: np.ndarray | None = None) -> np.ndarray:
        """One control period of every row; the commands (rad).  ``status`` and
        ``fault_flags`` per row as the scalar ``State`` has them.  ``hold``: ``step()``'s per row
        (None: no row's)."""
        c = self.c
        if hold is not None and not hold.any():
            hold = None
        if speed is not self._speed:
            self._speed_terms(speed)
        if (self._speed_ok and self._flags_clear and _within(delta_driver, c.driver_angle_max)
                and _within(yaw_rate, c.yaw_rate_max)):
            return self._advance(delta_driver, yaw_rate, None, None, hold)
        idle, bad = self._check(delta_driver, yaw_rate)
        if idle is None:
            return self._advance(delta_driver, yaw_rate, None, None, hold)
        with np.errstate(all="ignore"):  # an idle row's arithmetic (NaN, huge inputs) is dropped
            return self._advance(delta_driver, yaw_rate, idle, bad, hold)

    def _speed_terms(self, speed: np.ndarray) -> None:
        c = self.c
        self._speed, self._inv_kn = speed, None
        # every row's speed within [speed_active_min, speed_max] (False for a NaN)
        self._speed_ok = bool(speed.min() >= c.speed_active_min) and bool(speed.max() <= c.speed_max)
        if self._speed_ok:
            self._ok_speed = self._slow = None
            self._law_speed = speed
            return
        self._ok_speed = (0.0 <= speed) & (speed <= c.speed_max)
        self._slow = ~self._ok_speed | (speed < c.speed_active_min)
        # an idle row's speed made harmless for the law (its result is dropped)
        self._law_speed = np.where(self._slow, c.speed_active_min, speed)

    def _check(self, delta_driver: np.ndarray, yaw_rate: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """``step()``'s input checks: the fault flags; the rows idle this period (None: none)
        and those with a flag."""
        c = self.c
        # |x| <= max is -max <= x <= max, NaN failing both
        ok_driver = np.abs(delta_driver) <= c.driver_angle_max
        ok_yaw = np.abs(yaw_rate) <= c.yaw_rate_max
        ok = ok_driver & ok_yaw
        if self._ok_speed is not None:
            ok &= self._ok_speed
        bad = ~ok
        idle = bad if self._slow is None else bad | self._slow
        flags = np.where(ok_driver, 0, mr.FAULT_DRIVER_ANGLE)
        flags |= np.where(ok_yaw, 0, mr.FAULT_YAW_RATE)
        if self._ok_speed is not None:
            flags |= np.where(self._ok_speed, 0, mr.FAULT_SPEED)
        self.fault_flags = flags.astype(np.int8)
        self._flags_clear = not bool(bad.any())
        return (idle if idle.any() else None), bad

    def _advance(self, delta_driver: np.ndarray, yaw_rate: np.ndarray, idle: np.ndarray | None,
                 bad: np.ndarray | None, hold: np.ndarray | None = None) -> np.ndarray:
        """The active path for every row; then, for the ``idle`` rows, the fade (``bad``: those
        with an input fault)."""
        c = self.c
        if self._inv_kn is None:
            v = self._law_speed
            self._inv_kn = c.wheelbase / v + c.k_us * v
        rho = self._inv_kn * yaw_rate
        law = self.table.at(self._law_speed)
        recovering = self.recovering
        if self._needs_any:
            init = self.needs_init if idle is None else self.needs_init & ~idle
            if init.any():
                recovering = self._reinit(init, delta_driver, rho, law)
        u_prev = self.u_prev
        if recovering is not None and recovering.any():
            du = np.where(recovering & (c.fade_step < c.du_max), c.fade_step, c.du_max)
        else:
            recovering, du = None, c.du_max
        lo_slew = u_prev - du
        hi_slew = u_prev + du
        lo = np.maximum(lo_slew, -c.u_max)
        hi = np.minimum(hi_slew, c.u_max)
        if hold is not None:
            # step()'s hold: the window keeps u_prev and 0's side of it (its comparisons' ties)
            pos = u_prev > 0.0
            lo, hi = (np.where(hold, np.where(pos, np.maximum(lo, 0.0), np.maximum(u_prev, lo)), lo),
                      np.where(hold, np.where(pos, np.minimum(u_prev, hi), np.minimum(hi, 0.0)), hi))
        u = self._law(delta_driver, rho, lo, hi, law)
        inside = (lo_slew < u) & (u < hi_slew)
        if hold is not None:
            inside &= ~hold
        still = None if recovering is None else recovering & ~inside
        status = np.where((u >= c.u_max) | (u <= -c.u_max), mr.STATUS_SATURATED, mr.STATUS_ACTIVE).astype(np.int8)
        if idle is None:
            self.recovering, self.u_prev, self.status = still, u, status
            if self._needs_any:
                self.needs_init = np.zeros_like(self.needs_init)
                self._needs_any = False
            return u
        fs = c.fade_step
        faded = np.where(u_prev > fs, u_prev - fs, np.where(u_prev < -fs, u_prev + fs, 0.0))
        self.recovering = None if still is None else still & ~idle  # (re-initialisation sets an idle row's)
        self.needs_init = idle  # (a row that is not idle has initialised by now)
        self._needs_any = True
        self.u_prev = out = np.where(idle, faded, u)
        self.status = np.where(idle, np.where(bad, mr.STATUS_FAULT, mr.STATUS_INACTIVE), status).astype(np.int8)
        return out

    def _reinit(self, init: np.ndarray, delta_driver: np.ndarray, rho: np.ndarray, law) -> np.ndarray:
        """The re-start of every filter at its steady state for the present inputs with the
        command held; the rows now recovering."""
        a, g_w0, g_w1, g_r0, g_r1, q0 = law
        b0, b1, b2, a1, a2 = self.flt
        w0 = delta_driver + self.u_prev
        self.z = np.where(init, q0 * (w0 - rho) - (g_w0 * w0 - g_r0 * rho), self.z)
        np.copyto(self.u_hist, self.u_prev, where=init)  # every slot (hist_idx: see the module's docstring)
        self.p_n = np.where(init, self.u_prev, self.p_n)
        self.f_s1 = np.where(init, (1.0 - b0) * w0, self.f_s1)
        self.f_s2 = np.where(init, (b2 - a2) * w0, self.f_s2)
        return init if self.recovering is None else self.recovering | init

    def _law(self, delta_driver: np.ndarray, rho: np.ndarray, lo: np.ndarray, hi: np.ndarray, law) -> np.ndarray:
        """The recursion of the law (docs/controller.md): the clamped command; z and the
        model's states advanced."""
        a, g_w0, g_w1, g_r0, g_r1, _ = law
        # x < lo: lo; x > hi: hi; else x (lo <= hi; a NaN stays; on a tie numpy's maximum and
        # minimum return their second argument, so a signed zero is the scalar's too)
        if self.m == 0:  # constant law only
            p = g_w0 * delta_driver - g_r0 * rho + self.z
            v = p * self.c.inv_one_minus_g_w0
            u = np.minimum(hi, np.maximum(lo, v))
            y = p + g_w0 * u
            w = delta_driver + u
        else:
            act_a, act_b = self.act
            b0, b1, b2, a1, a2 = self.flt
            i = self.hist_idx
            self.p_n = act_a * self.p_n + act_b * self.u_hist[i]
            x = delta_driver + self.p_n
            w = b0 * x + self.f_s1
            self.f_s1 = b1 * x - a1 * w + self.f_s2
            self.f_s2 = b2 * x - a2 * w
            y = g_w0 * w - g_r0 * rho + self.z
            u = np.minimum(hi, np.maximum(lo, y))
            self.u_hist[i] = u
            self.hist_idx = i + 1 if i + 1 < self.m else 0
        self.z = g_w1 * w - g_r1 * rho + a * y
        return u


def _within(x: np.ndarray, bound: float) -> bool:
    """-bound <= x <= bound in every row (False for a NaN: min and max propagate it)."""
    return bool(x.min() >= -bound) and bool(x.max() <= bound)


class _Schedule:
    """The law's coefficient set (a, g_w0, g_w1, g_r0, g_r1, q0) at each row's speed, with
    ``model_regulator.step``'s interpolation: linear between breakpoints, held outside.

    The six tables are one (6, n) array and their differences t[j+1] - t[j] are taken once
    (the same subtraction ``step()`` makes each period, so the same values): one gather per
    step instead of three per table.  A row's speed that has not changed since the last step
    (a constant-speed scenario) gets the coefficients it had."""

    def __init__(self, c: mr.Coefficients) -> None:
        self.const = None
        self.n = c.n_sched
        self.v = np.asarray(c.sched_v)
        self.inv_dv = np.asarray(c.sched_inv_dv + (0.0,))
        self.tables = np.array([c.sched_a, c.sched_g_w0, c.sched_g_w1, c.sched_g_r0, c.sched_g_r1, c.sched_q0])
        self.diffs = np.zeros_like(self.tables)
        self.diffs[:, :-1] = self.tables[:, 1:] - self.tables[:, :-1]
        self._speed: np.ndarray | None = None
        self._law: tuple[np.ndarray, ...] = ()
        self._seen: np.ndarray | None = None  # the array of the last call (held: the same values)
        if self.n == 1:
            self.const = tuple(t[0] + 0.0 * (t[0] - t[0]) for t in self.tables)

    def at(self, speed: np.ndarray):
        if self.const is not None:
            return self.const
        if speed is self._seen or self._speed is not None and np.array_equal(speed, self._speed):
            self._seen = speed
            return self._law
        n, sv = self.n, self.v
        # the last breakpoint at or below the speed (ascending): the count of sv[1..n-2] <= speed
        j = np.searchsorted(sv[1:n - 1], speed, side="right")
        inside = (speed > sv[0]) & (speed < sv[n - 1])
        top = (speed > sv[0]) & (speed >= sv[n - 1])
        j = np.where(inside, j, np.where(top, n - 1, 0))
        f = np.where(inside, (speed - sv[j]) * self.inv_dv[j], 0.0)
        # outside the breakpoints step() adds 0 (t[j] - t[j]); here 0 times the (finite) next difference
        law = self.tables[:, j] + f * self.diffs[:, j]
        self._speed, self._law, self._seen = speed.copy(), tuple(law), speed
        return self._law
