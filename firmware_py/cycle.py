"""One control cycle -- a porting reference in ``model_regulator``'s style.

The scheduling contract's order within one control period (docs/porting.md): the plausibility
monitor over the yaw-rate samples since the last period, the law with the monitor's suspicion of
the yaw rate holding its command, and the authority limiter with the monitor's cut and fade.
``configure(law, monitor, authority)`` -> ``CycleCoefficients`` (once); ``CycleState`` (the three
states, the command sent last and the monitor's bits, held between yaw-rate samples);
``step(c, s, inputs)`` once per control period: scalar arithmetic, no allocation, no I/O, no
clock.  What the period's inputs are (which frames are fresh, how many yaw-rate samples came) is
the caller's: the controller node reads them off the bus, a replay off a log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import firmware_py.authority as au
import firmware_py.model_regulator as mr
import firmware_py.plausibility as pl


@dataclass(frozen=True)
class CycleCoefficients:
    """The three pieces' coefficients, computed once."""

    law: mr.Coefficients
    monitor: pl.MonitorCoefficients
    authority: au.AuthorityCoefficients
    # The monitor's checks whose fault the limiter removes at its rate bound instead of fading
    # (pl.CUT_CHECKS: the pairs); another mask only to weigh the design against its options.
    cut_checks: int = pl.CUT_CHECKS


@dataclass
class CycleState:
    """What one cycle leaves for the next."""

    law: mr.State = field(default_factory=mr.State)
    monitor: pl.MonitorState = field(default_factory=pl.MonitorState)
    authority: au.AuthorityState = field(default_factory=au.AuthorityState)
    command: float = 0.0  # the limited command of the last cycle: what acts on the car now
    plausibility: int = 0  # the monitor's bits, held between yaw-rate samples
    reported: int = mr.STATUS_INACTIVE  # model_regulator.reported_state of the last cycle


@dataclass
class CycleInputs:
    """One period's inputs; NaN is an input that is not valid this period.  One instance,
    refilled by its caller every period."""

    delta_driver: float = math.nan  # rad
    yaw_rate: float = math.nan  # rad/s
    speed: float = math.nan  # m/s
    lat_accel: float = math.nan  # m/s^2: the redundant sample (NaN: none fresh)
    delta_driver_redundant: float = math.nan  # rad: the second steering channel
    yaw_rate_redundant: float = math.nan  # rad/s: the yaw rate's second element
    speed_redundant: float = math.nan  # m/s: the second speed
    monitor_steps: int = 1  # yaw-rate samples since the last period; 0 holds the monitor's bits
    # The driver's angle for the monitor's first step: the one that came with a redundant sample
    # not yet stepped over (a burst's newest angle is younger than it), else ``delta_driver``.
    monitor_driver: float = math.nan
    starting: bool = False  # the start state: some input not yet seen (model_regulator.reported_state)


def configure(law: mr.ControllerConfig, monitor: pl.PlausibilityConfig, authority: au.AuthorityConfig,
              cut_checks: int = pl.CUT_CHECKS) -> CycleCoefficients:
    """The coefficients of the three pieces; ValueError for an impossible configuration."""
    return CycleCoefficients(mr.configure(law), pl.configure(monitor), au.configure_authority(authority), cut_checks)


def reset(s: CycleState) -> None:
    """Back to power-on: every state at rest, no command, no bits."""
    mr.reset(s.law)
    pl.reset_monitor(s.monitor)
    au.reset_authority(s.authority)
    s.command = 0.0
    s.plausibility = 0
    s.reported = mr.STATUS_INACTIVE


def step(c: CycleCoefficients, s: CycleState, i: CycleInputs) -> float:
    """One control period: the limited command to send (also ``s.command``)."""
    bits = s.plausibility
    steer = i.monitor_driver
    for _ in range(i.monitor_steps):  # a sample lost on the way is held at the newest values
        bits = pl.monitor_step(c.monitor, s.monitor, steer, i.delta_driver_redundant, i.yaw_rate, i.lat_accel,
                               i.speed, s.command, i.yaw_rate_redundant, i.speed_redundant)
        steer = i.delta_driver
    flags = s.monitor.flags
    # before the law: the monitor's suspicion of the yaw rate holds the law's command
    u = mr.step(c.law, s.law, i.delta_driver, i.yaw_rate, i.speed, (flags & pl.SUSPECT_CHECKS) != 0)
    # a pair check's fault (yaw rate or steering) is found while its command builds: removed at the
    # limiter's rate bound, not faded
    u = au.authority_step(c.authority, s.authority, u, bits, flags & c.cut_checks, flags & pl.FADE_CHECKS)
    s.plausibility = bits
    s.command = u
    s.reported = mr.reported_state(s.law.status, bits, i.starting)
    return u


class Cycle:
    """``configure``, a ``CycleState`` and ``step`` in one object, as ``ModelRegulator`` is for
    the law."""

    def __init__(self, law: mr.ControllerConfig | None = None, monitor: pl.PlausibilityConfig | None = None,
                 authority: au.AuthorityConfig | None = None) -> None:
        law = law or mr.ControllerConfig()
        monitor = monitor or pl.PlausibilityConfig(ts=law.ts)
        authority = authority or au.AuthorityConfig(ts=law.ts, u_max=law.aux_limit)
        self.coefficients = configure(law, monitor, authority)
        self.state = CycleState()

    def step(self, i: CycleInputs) -> float:
        return step(self.coefficients, self.state, i)

    def reset(self) -> None:
        reset(self.state)
