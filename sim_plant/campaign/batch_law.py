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

    def step(self, delta_driver: np.ndarray, yaw_rate: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """One control period of every row; the commands (rad).  ``status`` and
        ``fault_flags`` per row as the scalar ``State`` has them."""
        c = self.c
        # |x| <= max is -max <= x <= max, NaN failing both
        ok_driver = np.abs(delta_driver) <= c.driver_angle_max
        ok_yaw = np.abs(yaw_rate) <= c.yaw_rate_max
        ok_speed = (0.0 <= speed) & (speed <= c.speed_max)
        ok = ok_driver & ok_yaw & ok_speed
        idle = ~ok | (speed < c.speed_active_min)
        any_idle = bool(idle.any())
        if any_idle or self.fault_flags.any():  # the flags of a row with every input in range are 0
            flags = np.where(ok_driver, 0, mr.FAULT_DRIVER_ANGLE)
            flags |= np.where(ok_yaw, 0, mr.FAULT_YAW_RATE)
            flags |= np.where(ok_speed, 0, mr.FAULT_SPEED)
            self.fault_flags = flags.astype(np.int8)

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
            self.u_prev = u
            self.status = active_status.astype(np.int8)
            return u
        self._restore(idle, keep)  # an idle row's state is the scalar's: untouched
        self.recovering = np.where(idle, self.recovering, still)
        self.needs_init = idle | (self.needs_init & ~init)
        out = np.where(idle, faded, u)
        self.u_prev = out
        self.status = np.where(idle, np.where(~ok, mr.STATUS_FAULT, mr.STATUS_INACTIVE),
                               active_status).astype(np.int8)
        return out

    _STATE = ("z", "p_n", "f_s1", "f_s2", "hist_idx")

    def _state(self) -> tuple[np.ndarray, ...]:
        return tuple(getattr(self, k) for k in self._STATE) + (self.u_hist.copy(),)

    def _restore(self, idle: np.ndarray, kept: tuple[np.ndarray, ...]) -> None:
        if not idle.any():
            return
        for k, old in zip(self._STATE, kept):
            setattr(self, k, np.where(idle, old, getattr(self, k)))
        self.u_hist = np.where(idle, kept[-1], self.u_hist)

    def _reinit(self, init: np.ndarray, delta_driver: np.ndarray, rho: np.ndarray, law) -> np.ndarray:
        """The re-start of every filter at its steady state for the present inputs with the
        command held; the rows now recovering."""
        if not init.any():
            return self.recovering
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
            i = self.hist_idx
            self.p_n = act_a * self.p_n + act_b * self.u_hist[i, self._cols]
            x = delta_driver + self.p_n
            w = b0 * x + self.f_s1
            self.f_s1 = b1 * x - a1 * w + self.f_s2
            self.f_s2 = b2 * x - a2 * w
            y = g_w0 * w - g_r0 * rho + self.z
            u = np.where(y < lo, lo, np.where(y > hi, hi, y))
            self.u_hist[i, self._cols] = u
            nxt = i + 1
            self.hist_idx = np.where(nxt >= self.m, 0, nxt)
        self.z = g_w1 * w - g_r1 * rho + a * y
        return u


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
        if self.n == 1:
            self.const = tuple(t[0] + 0.0 * (t[0] - t[0]) for t in self.tables)

    def at(self, speed: np.ndarray):
        if self.const is not None:
            return self.const
        if self._speed is not None and np.array_equal(speed, self._speed):
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
        self._speed, self._law = speed.copy(), tuple(law)
        return self._law
