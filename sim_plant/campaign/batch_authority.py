"""Issue 18's authority limiter vectorised over a batch, for the batch engine:
``firmware_py.authority.authority_step`` for N rows at once, statement for statement on arrays
(each branch a mask in its order; ``AuthorityState``'s slots one array each; the coefficients the
firmware's own ``configure_authority``).  ``tests/test_campaign_engine.py`` holds it equal to
the scalar code row by row and period by period.  ``step`` has a shortcut for the periods
without DEGRADED and with every request finite.
"""

from __future__ import annotations

import numpy as np

from firmware_py import authority as au
from firmware_py.plausibility import PLAUS_DEGRADED, PLAUS_FAULT


class BatchAuthority:
    """N instances of the authority limiter configured with one ``AuthorityConfig``."""

    def __init__(self, config: au.AuthorityConfig, n: int) -> None:
        self.c = au.configure_authority(config)
        self.u = np.zeros(n)
        self.engaged = np.zeros(n, dtype=np.int64)
        self.quiet = np.zeros(n, dtype=np.int64)
        self.flags = np.zeros(n, dtype=np.int64)

    def step(self, u_request: np.ndarray, plaus_bits: np.ndarray, cut: np.ndarray | None = None,
             fade: np.ndarray | None = None) -> np.ndarray:
        """The command allowed this period per row (rad) for the law's ``u_request``, the
        monitor's ``plaus_bits``, ``cut`` and ``fade`` (nonzero: ``authority_step``'s cut and
        fade; None: none)."""
        if within(u_request) and not (plaus_bits & PLAUS_DEGRADED).any() and (fade is None or not fade.any()):
            return self._checked(u_request, plaus_bits, cut)
        c = self.c
        finite = (-1e3 < u_request) & (u_request < 1e3)  # False for NaN and +-inf
        plaus_fault = (plaus_bits & PLAUS_FAULT) != 0
        fault = plaus_fault | ~finite
        if fade is not None:
            fault |= fade != 0
        timed_out = ~fault & (self.engaged >= c.window_steps) & ((plaus_bits & PLAUS_DEGRADED) != 0)
        fading = fault | timed_out
        flags = np.where(fault, au.AUTH_FAULT, 0) | np.where(timed_out, au.AUTH_TIME, 0)
        # the request clamped to +-u_max (a fading row's target is 0; its request may be NaN)
        request = np.where(fading, 0.0, u_request)
        over, under = request > c.u_max, request < -c.u_max
        target = np.where(over, c.u_max, np.where(under, -c.u_max, request))
        flags |= np.where(~fading & (over | under), au.AUTH_MAGNITUDE, 0)
        fault_step = c.fault_fade_step if cut is None else np.where(plaus_fault & (cut != 0), c.du_max,
                                                                      c.fault_fade_step)
        du = np.where(fault, fault_step, np.where(timed_out, c.fade_step, c.du_max))
        d = target - self.u
        up, down = d > du, d < -du
        d = np.where(up, du, np.where(down, -du, d))
        flags |= np.where((up | down) & (du == c.du_max), au.AUTH_RATE, 0)
        self.flags = flags
        return self._move(d, u_request)

    def _checked(self, u_request: np.ndarray, plaus_bits: np.ndarray, cut: np.ndarray | None) -> np.ndarray:
        """``step`` with every request finite and no row DEGRADED (so none timed out): a
        faulted row fades to 0 (a cut one moves at the rate bound), the others bounded in
        magnitude and rate (min and max are the scalar's comparisons for finite numbers)."""
        c = self.c
        fault = (plaus_bits & PLAUS_FAULT) != 0
        cutting = None
        if fault.any():
            request = np.where(fault, 0.0, u_request)
            if cut is not None:
                cutting = fault & (cut != 0)
            du = np.where(fault & ~cutting if cutting is not None else fault, c.fault_fade_step, c.du_max)
            low = -du
        else:
            request, du, low = u_request, c.du_max, -c.du_max
        target = np.minimum(np.maximum(request, -c.u_max), c.u_max)
        d = target - self.u
        bounded = np.minimum(np.maximum(d, low), du)
        flags = np.where(target != request, au.AUTH_MAGNITUDE, 0) | np.where(bounded != d, au.AUTH_RATE, 0)
        if request is not u_request:
            # a faulted row's flags: FAULT, and RATE where a cut (at du_max) bound it
            faulted = au.AUTH_FAULT | (np.where(cutting & (bounded != d), au.AUTH_RATE, 0) if cutting is not None else 0)
            flags = np.where(fault, faulted, flags)
        self.flags = flags
        return self._move(bounded, u_request)

    def _move(self, d: np.ndarray, u_request: np.ndarray) -> np.ndarray:
        """The command moved by ``d``, and the intervention's window counted (``authority_step``'s
        counters: the command or the request over engage, |x| > engage being its two
        comparisons, False for NaN alike)."""
        c = self.c
        u = self.u + d
        acting = (np.abs(u) > c.engage) | (np.abs(u_request) > c.engage)
        self.engaged += acting & (self.engaged < c.window_steps)
        quiet = np.where(acting, 0, self.quiet + (self.quiet < c.rearm_steps))
        # (an acting row's quiet is 0, below rearm_steps >= 1)
        self.engaged = np.where(quiet >= c.rearm_steps, 0, self.engaged)
        self.quiet = quiet
        self.u = u
        return u


def within(x: np.ndarray, lo: float = -1e3, closed: bool = False) -> bool:
    """Every entry of ``x`` in (lo, 1e3), or in [lo, 1e3) when ``closed``: the scalar's range
    checks for all rows at once.  False for any NaN (min and max propagate it)."""
    x_lo, x_hi = x.min(), x.max()
    return bool((x_lo >= lo if closed else x_lo > lo) and x_hi < 1e3)
