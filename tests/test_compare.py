"""``mrsteer design compare`` (issue 15, item 4): the trade-off table and the candidate cloud."""

from __future__ import annotations

import pytest

from firmware_py import model_regulator as mr
from sim_plant.offline import compare as K
from sim_plant.offline.margins import Envelope

ONE = Envelope(speeds=(10.0,), frictions=(1.0,), masses=(1296.0,))


def test_the_paper_row_is_the_papers_gains_at_500_hz_with_and_without_the_delay_modelled() -> None:
    rows = dict(K.named_calibrations())
    paper = rows["paper K 10, tau 6 ms, M 0"]
    assert (paper.k, paper.tau, paper.tau_n, paper.ts, paper.model_delay_steps) == (10.0, 0.006, 0.02, 0.002, 0)
    assert rows["paper K 10, tau 6 ms, M 1"].model_delay_steps == 1
    assert rows["shipped schedule"] == mr.ControllerConfig()


def test_shipped_schedule_on_the_reference_loop_gives_the_figure_10_peak() -> None:
    f = K.loop_figures(mr.ControllerConfig(), K.LOOPS["reference"], ONE)
    assert f.stable and f.passes
    assert f.peak_yaw_rate[10.0] == pytest.approx(0.04461, abs=5e-5)
    assert f.worst_noise_deg == pytest.approx(0.146, abs=1e-3)
    assert f.threshold_nm[10.0] > 6119.0
    prev = K.loop_figures(mr.PREVIOUS_CONFIG, K.LOOPS["reference"], Envelope(speeds=(5.0,), frictions=(1.0,),
                                                                            masses=(1296.0,)))
    assert not prev.stable and "max_pole_radius" in prev.failing
    table = K.markdown({"shipped": {"reference": f}, "previous": {"reference": prev}})
    assert "| shipped | reference | yes" in table and "| previous | reference | **no**" in table


def test_scaled_schedule_scales_k_and_tau_q_keeping_tau_consistent() -> None:
    b = mr.ControllerConfig()
    s = K.scaled_schedule(b, k=2.0, tau_q=0.5)
    for k0, t0, k1, t1 in zip(b.schedule_k, b.schedule_tau, s.schedule_k, s.schedule_tau):
        assert k1 == pytest.approx(2.0 * k0)
        assert t1 / (1.0 + k1) == pytest.approx(0.5 * t0 / (1.0 + k0))
    assert s.schedule_tau_n == b.schedule_tau_n


def test_a_candidate_under_the_saturation_threshold_is_infeasible_and_the_plot_renders() -> None:
    loud = K.score("K x2", K.scaled_schedule(mr.ControllerConfig(), k=2.0), ONE)
    # Twice the gain: a lower peak, but the applied angle saturates below 6119 Nm.
    assert loud.peak < 0.0446 and not loud.feasible and loud.failing == "threshold_nm"
    png = K.plot_png([loud, K.Candidate("shipped schedule", 0.0446, 0.146, True, None, named=True)])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
