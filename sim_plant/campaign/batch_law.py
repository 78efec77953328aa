"""The firmware's control law (``firmware_py.model_regulator.step``) vectorised over a batch.

``BatchLaw.step`` is ``model_regulator.step`` for N controller instances at once, statement for
statement on arrays: the input checks and fault flags, the fade to zero while inactive or
faulted, the bumpless re-initialisation on the next valid step, the slew window while
recovering, the actuator clamp, and the recursion of the law itself: the coefficient set
interpolated over the speed breakpoints as ``step()`` does it (``_Schedule``), the nominal
actuator p_n and the nominal 2nd-order yaw-rate filter of issue 15's model, the command
history of the modelled delay.  The coefficients are the firmware's own
(``model_regulator.configure``); nothing is re-derived here.

The branches of the scalar code become masks: every row computes the active path, and
``np.where`` keeps, for a row that is inactive or faulted this step, the state the scalar code
leaves untouched.  The law's own recursion is in ``_law`` alone, so that a change of the law in
the firmware changes one function here.
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
        self.hist_idx = np.zeros(n, dtype=np.int64)
        self.p_n = np.zeros(n)
        self.f_s1 = np.zeros(n)
        self.f_s2 = np.zeros(n)
        self.needs_init = np.ones(n, dtype=bool)
        self.recovering = np.zeros(n, dtype=bool)
        self.status = np.full(n, mr.STATUS_INACTIVE, dtype=np.int8)
        self.fault_flags = np.zeros(n, dtype=np.int8)
        self._cols = np.arange(n)
        self._hist_at: int | None = 0  # every row's hist_idx when they are all equal, else None
        self._speed: np.ndarray | None = None  # the speed array of the last period, its checks and 1/K_n
        self._speed_ok = False
        self._inv_kn: np.ndarray | None = None
        self._flags_clear = True  # no row's fault_flags set
        self._needs_any = True  # some row needs_init

    def step(self, delta_driver: np.ndarray, yaw_rate: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """One control period of every row; the commands (rad).  ``status`` and
        ``fault_flags`` per row as the scalar ``State`` has them.

        A caller that holds the speed between its samples passes the same array, unmodified,
        until the next one: its checks and the law's terms of the speed alone are then reused."""
        c = self.c
        if speed is not self._speed:
            self._speed = speed
            # every row's speed within [speed_active_min, speed_max] (False for a NaN)
            self._speed_ok = bool(speed.min() >= c.speed_active_min) and bool(speed.max() <= c.speed_max)
            self._inv_kn = None
        if (self._speed_ok and self._flags_clear and _within(delta_driver, c.driver_angle_max)
                and _within(yaw_rate, c.yaw_rate_max)):
            return self._active(delta_driver, yaw_rate, speed)
        return self._general(delta_driver, yaw_rate, speed)

    def _active(self, delta_driver: np.ndarray, yaw_rate: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """``step`` when every row's inputs are in range and active (no flags, none idle): the
        scalar's active path, with the work of rows that need no re-initialisation and are not
        recovering skipped when none are."""
        c = self.c
        if self._inv_kn is None:
            self._inv_kn = c.wheelbase / speed + c.k_us * speed
        rho = self._inv_kn * yaw_rate
        law = self.table.at(speed)
        recovering = self.recovering
        if self._needs_any:
            init = self.needs_init
            recovering = self._reinit(init, delta_driver, rho, law)
            self.needs_init = np.zeros_like(init)
            self._needs_any = False
        u_prev = self.u_prev
        if recovering is not None and recovering.any():
            du = np.where(recovering & (c.fade_step < c.du_max), c.fade_step, c.du_max)
        else:
            recovering, du = None, c.du_max
        lo_slew = u_prev - du
        hi_slew = u_prev + du
        lo = np.maximum(lo_slew, -c.u_max)
        hi = np.minimum(hi_slew, c.u_max)
        u = self._law(delta_driver, rho, lo, hi, law)
        self.recovering = None if recovering is None else recovering & ~((lo_slew < u) & (u < hi_slew))
        self.u_prev = u
        self.status = np.where((u >= c.u_max) | (u <= -c.u_max), mr.STATUS_SATURATED, mr.STATUS_ACTIVE).astype(np.int8)
        return u

    def _general(self, delta_driver: np.ndarray, yaw_rate: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """``step`` for any inputs: every branch of the scalar code a mask."""
        c = self.c
        self._recovering_array()
        # |x| <= max is -max <= x <= max, NaN failing both
        ok_driver = np.abs(delta_driver) <= c.driver_angle_max
        ok_yaw = np.abs(yaw_rate) <= c.yaw_rate_max
        ok_speed = (0.0 <= speed) & (speed <= c.speed_max)
        ok = ok_driver & ok_yaw & ok_speed
        idle = ~ok | (speed < c.speed_active_min)
        any_idle = bool(idle.any())
        if any_idle or not self._flags_clear:  # the flags of a row with every input in range are 0
            flags = np.where(ok_driver, 0, mr.FAULT_DRIVER_ANGLE)
            flags |= np.where(ok_yaw, 0, mr.FAULT_YAW_RATE)
            flags |= np.where(ok_speed, 0, mr.FAULT_SPEED)
            self.fault_flags = flags.astype(np.int8)
            self._flags_clear = not bool(self.fault_flags.any())

        u_prev = self.u_prev
        fs = c.fade_step
        faded = np.where(u_prev > fs, u_prev - fs, np.where(u_prev < -fs, u_prev + fs, 0.0)) if any_idle else None

        # The active path for every row (an idle row's speed is made harmless, its result dropped).
        safe_speed = np.where(idle, c.speed_active_min, speed) if any_idle else speed
        inv_kn = c.wheelbase / safe_speed + c.k_us * safe_speed
        rho = inv_kn * yaw_rate
        law = self.table.at(safe_speed)
        keep = self._state() if any_idle else ()
        init = self.needs_init & ~idle
        recovering = self._reinit(init, delta_driver, rho, law)

        du = np.where(recovering & (c.fade_step < c.du_max), c.fade_step, c.du_max)
        lo_slew = u_prev - du
        hi_slew = u_prev + du
        lo = np.maximum(lo_slew, -c.u_max)
        hi = np.minimum(hi_slew, c.u_max)
        u = self._law(delta_driver, rho, lo, hi, law)
        still = recovering & ~((lo_slew < u) & (u < hi_slew))
        active_status = np.where((u >= c.u_max) | (u <= -c.u_max), mr.STATUS_SATURATED, mr.STATUS_ACTIVE)

        if not any_idle:
            self.recovering = still
            self.needs_init = self.needs_init & ~init
            self._needs_any = bool(self.needs_init.any())
            self.u_prev = u
            self.status = active_status.astype(np.int8)
            return u
        self._restore(idle, keep)  # an idle row's state is the scalar's: untouched
        self.recovering = np.where(idle, self.recovering, still)
        self.needs_init = idle | (self.needs_init & ~init)
        self._needs_any = True
        out = np.where(idle, faded, u)
        self.u_prev = out
        self.status = np.where(idle, np.where(~ok, mr.STATUS_FAULT, mr.STATUS_INACTIVE),
                               active_status).astype(np.int8)
        return out

    def _recovering_array(self) -> None:
        """``recovering`` as an array (``_active`` leaves None for no row recovering)."""
        if self.recovering is None:
            self.recovering = np.zeros(self.z.size, dtype=bool)

    _STATE = ("z", "p_n", "f_s1", "f_s2", "hist_idx")

    def _hist_array(self) -> None:
        """``hist_idx`` per row, from the one index all rows share (``_hist_at``)."""
        if self._hist_at is not None:
            self.hist_idx = np.full(self.z.size, self._hist_at, dtype=np.int64)
            self._hist_at = None

    def _hist_uniform(self) -> None:
        """The one index of ``hist_idx`` when all rows share it (a gather and scatter saved)."""
        if self._hist_at is None and self.hist_idx.min() == self.hist_idx.max():
            self._hist_at = int(self.hist_idx[0])

    def _state(self) -> tuple[np.ndarray, ...]:
        self._hist_array()
        return tuple(getattr(self, k) for k in self._STATE) + (self.u_hist.copy(),)

    def _restore(self, idle: np.ndarray, kept: tuple[np.ndarray, ...]) -> None:
        if not idle.any():
            return
        for k, old in zip(self._STATE, kept):
            setattr(self, k, np.where(idle, old, getattr(self, k)))
        self.u_hist = np.where(idle, kept[-1], self.u_hist)
        self._hist_uniform()

    def _reinit(self, init: np.ndarray, delta_driver: np.ndarray, rho: np.ndarray, law) -> np.ndarray:
        """The re-start of every filter at its steady state for the present inputs with the
        command held; the rows now recovering."""
        if not init.any():
            return self.recovering
        self._hist_array()
        a, g_w0, g_w1, g_r0, g_r1, q0 = law
        b0, b1, b2, a1, a2 = self.flt
        w0 = delta_driver + self.u_prev
        self.z = np.where(init, q0 * (w0 - rho) - (g_w0 * w0 - g_r0 * rho), self.z)
        for i in range(self.m):
            self.u_hist[i] = np.where(init, self.u_prev, self.u_hist[i])
        self.hist_idx = np.where(init, 0, self.hist_idx)
        self.p_n = np.where(init, self.u_prev, self.p_n)
        self.f_s1 = np.where(init, (1.0 - b0) * w0, self.f_s1)
        self.f_s2 = np.where(init, (b2 - a2) * w0, self.f_s2)
        self._hist_uniform()
        return self.recovering | init

    def _law(self, delta_driver: np.ndarray, rho: np.ndarray, lo: np.ndarray, hi: np.ndarray, law) -> np.ndarray:
        """The recursion of the law (docs/controller.md): the clamped command; z and the
        model's states advanced."""
        a, g_w0, g_w1, g_r0, g_r1, _ = law
        if self.m == 0:  # constant law only
            p = g_w0 * delta_driver - g_r0 * rho + self.z
            v = p * self.c.inv_one_minus_g_w0
            u = np.where(v < lo, lo, np.where(v > hi, hi, v))
            y = p + g_w0 * u
            w = delta_driver + u
        else:
            act_a, act_b = self.act
            b0, b1, b2, a1, a2 = self.flt
            at = self._hist_at
            i = self.hist_idx if at is None else at
            last = self.u_hist[i, self._cols] if at is None else self.u_hist[at]
            self.p_n = act_a * self.p_n + act_b * last
            x = delta_driver + self.p_n
            w = b0 * x + self.f_s1
            self.f_s1 = b1 * x - a1 * w + self.f_s2
            self.f_s2 = b2 * x - a2 * w
            y = g_w0 * w - g_r0 * rho + self.z
            # y < lo: lo; y > hi: hi; else y (lo <= hi; a NaN stays; on a tie numpy's maximum and
            # minimum return their second argument, so a signed zero is the scalar's too)
            u = np.minimum(hi, np.maximum(lo, y))
            if at is None:
                self.u_hist[i, self._cols] = u
                nxt = i + 1
                self.hist_idx = np.where(nxt >= self.m, 0, nxt)
            else:
                self.u_hist[at] = u
                self._hist_at = at + 1 if at + 1 < self.m else 0
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
