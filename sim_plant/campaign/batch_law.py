"""The firmware's control law (``firmware_py.model_regulator.step``) vectorised over a batch.

``BatchLaw.step`` is ``model_regulator.step`` for N controller instances at once, statement for
statement on arrays: the input checks and fault flags, the fade to zero while inactive or
faulted, the bumpless re-initialisation on the next valid step, the slew window while
recovering, the actuator clamp, and the recursion of the law itself.  The coefficients are the
firmware's own (``model_regulator.configure``); nothing is re-derived here.

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
        self.z = np.zeros(n)
        self.u_prev = np.zeros(n)
        self.u_hist = np.zeros((max(self.m, 1), n))
        self.hist_idx = np.zeros(n, dtype=np.int64)
        self.needs_init = np.ones(n, dtype=bool)
        self.recovering = np.zeros(n, dtype=bool)
        self.status = np.full(n, mr.STATUS_INACTIVE, dtype=np.int8)
        self.fault_flags = np.zeros(n, dtype=np.int8)
        self._cols = np.arange(n)

    def step(self, delta_driver: np.ndarray, yaw_rate: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """One control period of every row; the commands (rad).  ``status`` and
        ``fault_flags`` per row as the scalar ``State`` has them."""
        c = self.c
        flags = np.where(~((-c.driver_angle_max <= delta_driver) & (delta_driver <= c.driver_angle_max)),
                         mr.FAULT_DRIVER_ANGLE, 0)
        flags |= np.where(~((-c.yaw_rate_max <= yaw_rate) & (yaw_rate <= c.yaw_rate_max)), mr.FAULT_YAW_RATE, 0)
        flags |= np.where(~((0.0 <= speed) & (speed <= c.speed_max)), mr.FAULT_SPEED, 0)
        self.fault_flags = flags.astype(np.int8)
        idle = (flags != 0) | (speed < c.speed_active_min)

        u_prev = self.u_prev
        fs = c.fade_step
        faded = np.where(u_prev > fs, u_prev - fs, np.where(u_prev < -fs, u_prev + fs, 0.0))

        # The active path for every row (an idle row's speed is made harmless, its result dropped).
        safe_speed = np.where(idle, c.speed_active_min, speed)
        inv_kn = c.wheelbase / safe_speed + c.k_us * safe_speed
        rho = inv_kn * yaw_rate
        init = self.needs_init & ~idle
        z, recovering = self._reinit(init, delta_driver, rho)

        du = np.where(recovering & (c.fade_step < c.du_max), c.fade_step, c.du_max)
        lo_slew = u_prev - du
        hi_slew = u_prev + du
        lo = np.maximum(lo_slew, -c.u_max)
        hi = np.minimum(hi_slew, c.u_max)
        u, z_next = self._law(delta_driver, rho, z, lo, hi, ~idle)
        still = recovering & ~((lo_slew < u) & (u < hi_slew))
        active_status = np.where((u >= c.u_max) | (u <= -c.u_max), mr.STATUS_SATURATED, mr.STATUS_ACTIVE)

        self.z = np.where(idle, self.z, z_next)
        self.recovering = np.where(idle, self.recovering, still)
        self.needs_init = idle | (self.needs_init & ~init)
        out = np.where(idle, faded, u)
        self.u_prev = out
        self.status = np.where(idle, np.where(flags != 0, mr.STATUS_FAULT, mr.STATUS_INACTIVE),
                               active_status).astype(np.int8)
        return out

    def _reinit(self, init: np.ndarray, delta_driver: np.ndarray, rho: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """The re-start at the steady state for the present inputs with the command held."""
        if not init.any():
            return self.z, self.recovering
        c = self.c
        w0 = delta_driver + self.u_prev
        z = np.where(init, c.q0 * (w0 - rho) - (c.g_w0 * w0 - c.g_r0 * rho), self.z)
        for i in range(self.m):
            self.u_hist[i] = np.where(init, self.u_prev, self.u_hist[i])
        self.hist_idx = np.where(init, 0, self.hist_idx)
        return z, self.recovering | init

    def _law(self, delta_driver: np.ndarray, rho: np.ndarray, z: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The recursion of the law (docs/controller.md): the clamped command and the next z.
        Rows not ``valid`` this step keep their model history."""
        c = self.c
        if self.m == 0:
            p = c.g_w0 * delta_driver - c.g_r0 * rho + z
            u = np.where(p * c.inv_one_minus_g_w0 < lo, lo, np.where(p * c.inv_one_minus_g_w0 > hi, hi,
                                                                     p * c.inv_one_minus_g_w0))
            y = p + c.g_w0 * u
            w = delta_driver + u
        else:
            i = self.hist_idx
            w = delta_driver + self.u_hist[i, self._cols]
            y = c.g_w0 * w - c.g_r0 * rho + z
            u = np.where(y < lo, lo, np.where(y > hi, hi, y))
            self.u_hist[i, self._cols] = np.where(valid, u, self.u_hist[i, self._cols])
            nxt = i + 1
            self.hist_idx = np.where(valid, np.where(nxt >= self.m, 0, nxt), i)
        return u, c.g_w1 * w - c.g_r1 * rho + c.a * y
