"""``firmware_py.cycle``: one control period in the scheduling contract's order (docs/porting.md),
checked against the three pieces run by hand in that order, and the order's consequences."""

from __future__ import annotations

import copy
import math
import random

import pytest

from firmware_py import authority as au
from firmware_py import cycle as cy
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl

NAN = math.nan


def _slots(*states: object) -> list[object]:
    """The states' values, slot by slot (they are C structs: no ``__eq__``)."""
    return [copy.copy(getattr(st, name)) for st in states for name in type(st).__slots__]


def _by_hand(c: cy.CycleCoefficients, law: mr.State, mon: pl.MonitorState, auth: au.AuthorityState,
             command: float, bits: int, i: cy.CycleInputs) -> tuple[float, int]:
    """The contract written out: monitor over the period's samples (the first with the angle that
    came with the redundant sample), law held by the monitor's suspicion, limiter."""
    for k in range(i.monitor_steps):
        bits = pl.monitor_step(c.monitor, mon, i.monitor_driver if k == 0 else i.delta_driver,
                               i.delta_driver_redundant, i.yaw_rate, i.lat_accel, i.speed, command,
                               i.yaw_rate_redundant, i.speed_redundant)
    u = mr.step(c.law, law, i.delta_driver, i.yaw_rate, i.speed, bool(mon.flags & pl.SUSPECT_CHECKS))
    return au.authority_step(c.authority, auth, u, bits, mon.flags & pl.CUT_CHECKS, mon.flags & pl.FADE_CHECKS), bits


def _inputs(rng: random.Random, k: int, fault_from: int) -> cy.CycleInputs:
    """A turn at 22 m/s whose yaw rate reads 1.6x too high from ``fault_from`` on (a fault the
    monitor finds), with invalid inputs, bursts and pauses sprinkled in."""
    r_true = 0.15 * math.sin(k / 80.0)
    d = r_true * 0.08 + rng.gauss(0.0, 1e-4)
    r = r_true * (1.6 if k >= fault_from else 1.0) + rng.gauss(0.0, 1e-3)
    v = 22.0 + rng.gauss(0.0, 0.01)
    fresh = k % 25 == 0
    i = cy.CycleInputs(d, r, v, lat_accel=r_true * v if fresh else NAN, delta_driver_redundant=d if fresh else NAN,
                       yaw_rate_redundant=r_true + rng.gauss(0.0, 1e-3), speed_redundant=v if fresh else NAN,
                       monitor_steps=rng.choice((1, 1, 1, 1, 0, 2, 3)), monitor_driver=d - 1e-4 if fresh else d,
                       starting=k < 3)
    roll = rng.random()
    if roll < 0.02:
        i.yaw_rate = i.yaw_rate_redundant = NAN
    elif roll < 0.03:
        i.speed = NAN
    elif roll < 0.04:
        i.delta_driver = i.monitor_driver = NAN
    return i


@pytest.mark.parametrize("seed", [1, 2])
def test_a_cycle_is_monitor_then_law_then_limiter(seed: int) -> None:
    rng = random.Random(seed)
    cfg = mr.ControllerConfig()
    cycle = cy.Cycle(cfg)
    c = cycle.coefficients
    law, mon, auth = mr.State(), pl.MonitorState(), au.AuthorityState()
    command, bits = 0.0, 0
    seen = set()
    for k in range(2500):
        i = _inputs(rng, k, fault_from=1500)
        expected, bits = _by_hand(c, law, mon, auth, command, bits, i)
        got = cycle.step(i)
        assert got == expected or (math.isnan(got) and math.isnan(expected)), k
        command = expected
        s = cycle.state
        assert (s.command, s.plausibility) == (got, bits)
        assert s.reported == mr.reported_state(law.status, bits, i.starting)
        assert _slots(s.law, s.monitor, s.authority) == _slots(law, mon, auth)
        seen.add(s.reported)
    # the run went through the states the contract orders: active, and the fault the monitor finds
    assert {mr.STATUS_ACTIVE, mr.STATUS_FAULT} <= seen


def test_the_monitors_suspicion_holds_the_command_of_the_same_period() -> None:
    """Monitor before law: the period whose yaw-rate sample the monitor suspects already has its
    command held, not the next one."""
    cycle = cy.Cycle()
    i = cy.CycleInputs(0.0, 0.02, 20.0, monitor_driver=0.0)
    for _ in range(200):
        cycle.step(i)
    held = copy.deepcopy(cycle.state)
    free = cy.Cycle()
    free.state = copy.deepcopy(held)
    # one sample with the second yaw-rate element far off: the pair check suspects the yaw rate
    i_bad = cy.CycleInputs(0.0, 0.3, 20.0, yaw_rate_redundant=0.0, monitor_driver=0.0)
    u = cycle.step(i_bad)
    assert cycle.state.monitor.flags & pl.SUSPECT_CHECKS
    law = copy.deepcopy(held.law)
    unheld = mr.step(cycle.coefficients.law, law, 0.0, 0.3, 20.0, False)
    assert u != unheld and cycle.state.law.u_prev == held.law.u_prev


def test_no_yaw_rate_sample_holds_the_monitors_bits_and_state() -> None:
    cycle = cy.Cycle()
    i = cy.CycleInputs(0.01, 0.05, 20.0, monitor_driver=0.01)
    for _ in range(50):
        cycle.step(i)
    before = _slots(cycle.state.monitor), cycle.state.plausibility
    i.monitor_steps = 0
    cycle.step(i)
    assert (_slots(cycle.state.monitor), cycle.state.plausibility) == before


def test_reset_is_power_on() -> None:
    cycle = cy.Cycle()
    for k in range(300):
        cycle.step(cy.CycleInputs(0.01, 0.2 * math.sin(k / 30), 25.0, monitor_driver=0.01))
    cycle.reset()
    fresh = cy.CycleState()
    s = cycle.state
    assert _slots(s.law, s.monitor, s.authority) == _slots(fresh.law, fresh.monitor, fresh.authority)
    assert (s.command, s.plausibility, s.reported) == (0.0, 0, mr.STATUS_INACTIVE)
