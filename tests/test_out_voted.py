"""The checks that infer the yaw rate or the speed from a model give way to two measurements
that agree (docs/decisions/0005-two-measurements-out-vote-a-model.md): the model check
while the yaw rate's second element and a_y / v both confirm it, the steady-turn check while the
second speed confirms the speed, and the kinematic family reaches mu_min_paired while the pair
runs.  The paper's six operating conditions (10/20/40 m/s on mu 1 and 0.3) on its own linear car
are the fault-free runs these exist for; synthetic inputs pin each condition down."""

from __future__ import annotations

import math

import pytest

from firmware_py import plausibility as pl
from sim_plant.car import scenario as scn
from sim_plant.car.sensor_faults import SensorFault
from sim_plant.car.sensors import SensorConfig
from sim_plant.offline import plausibility_runs as pr

PAPER_CONDITIONS = [(v, mu) for v in (10.0, 20.0, 40.0) for mu in (1.0, 0.3)]  # sim_plant.offline.paper


def _paper(name: str, v: float, mu: float, pairs: bool = True, second_speed: bool = True,
           monitor: pl.PlausibilityConfig | None = None) -> pr.MonitorRun:
    """The built-in scenario on its own car, sensors and actuator, as the plant node sends it:
    with the yaw-rate sensor's second element and the second speed unless told otherwise."""
    sc = scn.load(name).with_overrides(v=v, mu=mu)
    return pr.run(sc, second_yaw=sc.sensor_config if pairs else None, second_speed=second_speed,
                  monitor=monitor)


@pytest.mark.parametrize("name", ["paper-fig8", "paper-fig9", "handover"])
@pytest.mark.parametrize("v, mu", PAPER_CONDITIONS)
def test_the_paper_s_scenarios_at_its_six_conditions_raise_nothing(name: str, v: float, mu: float) -> None:
    run = _paper(name, v, mu)
    assert run.report_time is None
    assert not (run.bits & pl.PLAUS_DEGRADED).any()


def test_figure_9_on_mu_0_3_slides_past_the_model_check_s_bound_which_the_pairs_out_vote() -> None:
    # 4000 Nm against a command saturated at -3 deg: the car yaws against its steering, as no
    # nominal car would.  Without the second element nothing out-votes the model check, which
    # calls it a yaw-rate fault.
    with_pairs = _paper("paper-fig9", 20.0, 0.3)
    assert with_pairs.margins["model"] > 1.2 and with_pairs.report_time is None
    alone = _paper("paper-fig9", 20.0, 0.3, pairs=False)
    assert alone.fault_time is not None and alone.fault_time < 1.0


def test_the_kinematic_family_reaches_mu_min_paired_only_while_the_pair_runs() -> None:
    # Figure 8's unit yaw-rate step on mu 0.3 at 40 m/s: the linear car's side slip grows at the
    # rate of a mu 0.3 car, outside the mu 0.5 family.
    assert _paper("paper-fig8", 40.0, 0.3).report_time is None
    narrow = _paper("paper-fig8", 40.0, 0.3, monitor=pl.PlausibilityConfig(mu_min_paired=0.5))
    # (the element confirms the yaw rate: the trip is the car outside the family, DEGRADED)
    assert narrow.report_time is not None and narrow.fault_time is None
    assert _paper("paper-fig8", 40.0, 0.3, pairs=False).fault_time is not None  # mu_min 0.5 without the pair


def test_the_steady_turn_check_gives_way_only_to_an_agreeing_second_speed() -> None:
    # Figure 9 at 30 m/s on mu 0.3: the linear car's side slip still settles seconds after the
    # step, so a_y / r is not the speed there.
    assert _paper("paper-fig9", 30.0, 0.3).report_time is None
    run = _paper("paper-fig9", 30.0, 0.3, second_speed=False)
    assert run.fault_time is not None and run.margins["turn"] > 1.0


def _model_flags(redundant: bool, element: bool, periods: int = 450, toggle: bool = True) -> list[int]:
    """The monitor at 20 m/s while the car yaws steadily at 0.5 rad/s (a_y = v r: no side slip
    changing), first on the wheel angle the nominal car needs for it, then, from period 150 on, on
    a straight wheel (a yaw moment holding the car in its turn): the model check's residual
    grows past its bound.  ``redundant``: a_y and the second steering channel there (else the
    redundant frame missing); ``element``: the yaw rate's second element agrees (else none);
    ``toggle``: the redundant frame's values move by their noise throughout (else only until
    period 150, then repeat exactly, as exact sensors' do in a steady state: no new sample)."""
    c = pl.configure(pl.PlausibilityConfig())
    r, v = 0.5, 20.0
    turn = r * (c.wheelbase + c.k_us * v * v) / v
    mon = pl.PlausibilityMonitor()
    out = []
    for k in range(periods):
        d = turn if k < 150 else 0.0
        noise = 1e-3 * ((k // 25) % 2) * (toggle or k < 150)  # the redundant frame's values change once per 50 ms
        mon.step(d, d + noise * 1e-2 if redundant else math.nan, r, r * v + noise if redundant else math.nan, v,
                 0.0, r if element else math.nan, v)
        out.append(mon.state.flags)
    return out


def test_the_model_check_trips_unless_both_measurements_confirm_the_yaw_rate() -> None:
    assert _model_flags(False, False)[-1] & pl.CHECK_MODEL  # neither
    # the element agrees, a_y is missing: the car is what disagrees (OUTSIDE_MODEL, DEGRADED)
    assert _model_flags(False, True)[-1] & (pl.CHECK_MODEL | pl.OUTSIDE_MODEL) == pl.OUTSIDE_MODEL
    assert _model_flags(True, False)[-1] & pl.CHECK_MODEL  # a_y / v agrees, no element
    both = _model_flags(True, True)  # out-voted
    assert not any(f & pl.YAW_CHECKS for f in both)
    # a_y repeating its value (no new redundant sample for 0.6 s) still confirms the yaw rate:
    # the kinematic window it filled before is within its bound
    assert not any(f & pl.YAW_CHECKS for f in _model_flags(True, True, toggle=False))
    # the same trip time whenever it is not out-voted: the count is the model check's own
    first = [[f & bit for f in _model_flags(*x)].index(bit)
             for x, bit in (((False, False), pl.CHECK_MODEL), ((False, True), pl.OUTSIDE_MODEL),
                            ((True, False), pl.CHECK_MODEL))]
    assert first[0] == first[1] == first[2] > 150 + pl.configure(pl.PlausibilityConfig()).model_steps


def test_a_yaw_rate_fault_under_figure_9_on_mu_0_3_is_still_found_by_the_pair() -> None:
    sc = scn.load("paper-fig9").with_overrides(v=20.0, mu=0.3).with_sensor_faults(
        (SensorFault("yaw_rate", "bias", 1.0, math.radians(3.0)),))
    run = pr.run(sc, second_yaw=SensorConfig(seed=3), second_speed=True)
    assert run.fault_time is not None and 1.0 <= run.fault_time <= 1.02
