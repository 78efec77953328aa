"""Bounded authority (issue 18, item 3) -- a porting reference in ``model_regulator``'s style.

An independent limit on how far and how long the auxiliary command may act, whatever computed
it: ``AuthorityConfig`` -> ``configure_authority()`` -> ``AuthorityState`` ->
``authority_step(c, s, u_request, plaus_bits, cut, fade)`` once per control period (scalar arithmetic, no
allocation; its units ``fade_cause``, ``magnitude_bound``, ``rate_bound``, ``intervention_window``
are the C port's), with the bits of ``firmware_py.plausibility.monitor_step``.  Ported bit for
bit (float64) in ``ports/c/mrs_monitor.c``; docs/controller.md, "Bounded
authority", says what it does, docs/decisions/0008-authority-fades-rate-bound-and-re-arm.md why.  Meant to run where the command leaves the controller and again at the actuator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_py.calibration import AUX_LIMIT, SHIPPED_TS
from firmware_py.plausibility import PLAUS_DEGRADED, PLAUS_FAULT, check_positive, steps_of

# Authority limiter flags (AuthorityState.flags): what bound the command this period.
AUTH_MAGNITUDE = 0x01
AUTH_RATE = 0x02
AUTH_TIME = 0x04  # beyond the panic window with inputs not known consistent: faded
AUTH_FAULT = 0x08  # plausibility fault or a non-finite request: faded


@dataclass(frozen=True)
class AuthorityConfig:
    """The independent bound on the command (issue 18, item 3), rad and s."""

    ts: float = SHIPPED_TS
    u_max: float = AUX_LIMIT  # magnitude: the actuator's range
    rate_max: float = 10.0  # rad/s: a 6 deg reversal in >= 10.5 ms; above the law's needs (decision 0008)
    fade_rate: float = math.radians(6.0)  # rad/s toward 0 when the time is up: a hand-back to the driver
    fault_fade_rate: float = math.radians(30.0)  # rad/s toward 0 on a plausibility fault: a wrong command
    panic_window: float = 2.0  # s: the upper end of the paper's 0.5-2 s panic reaction time
    engage: float = math.radians(0.1)  # |u| or |u_request| above this counts as intervening
    rearm_time: float = 1.0  # s of |u| and |u_request| <= engage before the window starts afresh


@dataclass(frozen=True, slots=True)
class AuthorityCoefficients:
    u_max: float
    du_max: float
    fade_step: float
    fault_fade_step: float
    window_steps: int
    engage: float
    rearm_steps: int


class AuthorityState:
    __slots__ = ("u", "engaged", "quiet", "flags")

    def __init__(self) -> None:
        reset_authority(self)


def reset_authority(s: AuthorityState) -> None:
    s.u = 0.0
    s.engaged = 0  # periods intervening since the window started
    s.quiet = 0  # periods at rest in a row
    s.flags = 0


def configure_authority(cfg: AuthorityConfig) -> AuthorityCoefficients:
    check_positive(cfg, tuple(vars(cfg)))
    return AuthorityCoefficients(u_max=cfg.u_max, du_max=cfg.rate_max * cfg.ts, fade_step=cfg.fade_rate * cfg.ts,
                                 fault_fade_step=cfg.fault_fade_rate * cfg.ts,
                                 window_steps=steps_of(cfg.panic_window, cfg.ts), engage=cfg.engage,
                                 rearm_steps=steps_of(cfg.rearm_time, cfg.ts))


def authority_step(c: AuthorityCoefficients, s: AuthorityState, u_request: float, plaus_bits: int,
                   cut: int = 0, fade: int = 0) -> float:
    """The command allowed this period for ``u_request`` (rad), given the monitor's bits: within
    +-u_max, moving at most ``rate_max``; faded to zero at ``fault_fade_rate`` on a plausibility
    fault or a non-finite request, and at ``fade_rate`` once the intervention has lasted
    ``panic_window`` unless the inputs are known consistent (every check running: no DEGRADED).
    The window starts afresh after ``rearm_time`` in which neither the command nor the request
    intervened: a request the time rule faded stays faded until the law lets go of it, rather
    than coming back for another window each time the faded command has rested.
    ``cut`` nonzero with a fault (the node passes the monitor's ``flags & CUT_CHECKS``: a pair
    check): the fault was found while its command is still building, so the command is removed
    at ``rate_max``, not faded.  ``fade`` nonzero (the node passes the monitor's ``flags &
    FADE_CHECKS``: the car outside the model the checks and the law assume) fades the command
    as a fault does, though the bits say DEGRADED.  ``s.flags`` says which bound acted."""
    why = fade_cause(c, s, u_request, plaus_bits, fade)
    s.flags = why
    if why == AUTH_FAULT:
        target = 0.0
        du = c.du_max if cut != 0 and (plaus_bits & PLAUS_FAULT) != 0 else c.fault_fade_step
    elif why == AUTH_TIME:
        target = 0.0
        du = c.fade_step
    else:
        target = magnitude_bound(c, s, u_request)
        du = c.du_max
    u = s.u + rate_bound(c, s, target - s.u, du)
    intervention_window(c, s, u, u_request)
    s.u = u
    return u


def fade_cause(c: AuthorityCoefficients, s: AuthorityState, u_request: float, plaus_bits: int, fade: int) -> int:
    """Why the command goes to zero this period: ``AUTH_FAULT`` (a plausibility fault, ``fade``
    or a non-finite request), ``AUTH_TIME`` (the panic window over while DEGRADED), else 0."""
    if (plaus_bits & PLAUS_FAULT) != 0 or fade != 0 or not (-1e3 < u_request < 1e3):
        return AUTH_FAULT
    if s.engaged >= c.window_steps and (plaus_bits & PLAUS_DEGRADED) != 0:
        return AUTH_TIME
    return 0


def magnitude_bound(c: AuthorityCoefficients, s: AuthorityState, u_request: float) -> float:
    """The request within +-u_max (``AUTH_MAGNITUDE`` into ``s.flags`` when it bounds)."""
    if u_request > c.u_max:
        s.flags |= AUTH_MAGNITUDE
        return c.u_max
    if u_request < -c.u_max:
        s.flags |= AUTH_MAGNITUDE
        return -c.u_max
    return u_request


def rate_bound(c: AuthorityCoefficients, s: AuthorityState, d: float, du: float) -> float:
    """The step ``d`` within +-du (``AUTH_RATE`` into ``s.flags`` when ``rate_max`` bounds it)."""
    if d > du:
        d = du
        s.flags |= AUTH_RATE if du == c.du_max else 0
    elif d < -du:
        d = -du
        s.flags |= AUTH_RATE if du == c.du_max else 0
    return d


def intervention_window(c: AuthorityCoefficients, s: AuthorityState, u: float, u_request: float) -> None:
    """The panic window's count: periods the command or the request intervened (the request too:
    a request the time rule faded does not re-arm the window by resting the command), restarted
    after ``rearm_steps`` at rest in a row."""
    if u > c.engage or u < -c.engage or u_request > c.engage or u_request < -c.engage:
        if s.engaged < c.window_steps:
            s.engaged += 1
        s.quiet = 0
    else:
        if s.quiet < c.rearm_steps:
            s.quiet += 1
        if s.quiet >= c.rearm_steps:
            s.engaged = 0
