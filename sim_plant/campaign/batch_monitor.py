"""Issue 18's safety layer vectorised over a batch, for the batch engine: so far the authority
limiter (``firmware_py.authority.authority_step``) for N rows at once.

``BatchAuthority.step`` is ``authority_step`` statement for statement on arrays: each branch of
the scalar code a mask, the engaged and quiet counters int arrays, ``flags`` per row as the
scalar ``AuthorityState`` has them.  The coefficients are the firmware's own
(``authority.configure_authority``).  ``tests/test_campaign_engine.py`` holds it equal to the
scalar limiter, row by row, over random requests and monitor bits.

Not here yet (docs/campaigns.md, "Not yet in the batch engine"): the plausibility monitor
(``monitor_step``) vectorised, and both wired into ``engine`` after the law.
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

    def step(self, u_request: np.ndarray, plaus_bits: np.ndarray) -> np.ndarray:
        """The command allowed this period per row (rad) for the law's ``u_request`` and the
        monitor's ``plaus_bits``."""
        c = self.c
        finite = (-1e3 < u_request) & (u_request < 1e3)  # False for NaN and +-inf
        fault = ((plaus_bits & PLAUS_FAULT) != 0) | ~finite
        timed_out = ~fault & (self.engaged >= c.window_steps) & ((plaus_bits & PLAUS_DEGRADED) != 0)
        fading = fault | timed_out
        flags = np.where(fault, au.AUTH_FAULT, 0) | np.where(timed_out, au.AUTH_TIME, 0)
        # the request clamped to +-u_max (a fading row's target is 0; its request may be NaN)
        request = np.where(fading, 0.0, u_request)
        over, under = request > c.u_max, request < -c.u_max
        target = np.where(over, c.u_max, np.where(under, -c.u_max, request))
        flags |= np.where(~fading & (over | under), au.AUTH_MAGNITUDE, 0)
        du = np.where(fading, c.fade_step, c.du_max)
        d = target - self.u
        up, down = d > du, d < -du
        d = np.where(up, du, np.where(down, -du, d))
        flags |= np.where((up | down) & (du == c.du_max), au.AUTH_RATE, 0)
        u = self.u + d
        acting = (u > c.engage) | (u < -c.engage)
        self.engaged = np.where(acting & (self.engaged < c.window_steps), self.engaged + 1, self.engaged)
        quiet = np.where(acting, 0, np.where(self.quiet < c.rearm_steps, self.quiet + 1, self.quiet))
        self.engaged = np.where(~acting & (quiet >= c.rearm_steps), 0, self.engaged)
        self.quiet = quiet
        self.u = u
        self.flags = flags
        return u
