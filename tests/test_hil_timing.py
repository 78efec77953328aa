"""``hil run`` says whether its loops held their timing (``hil_timing``), and prints its summary
as a person reads it: ``key value`` lines, no dict reprs, figures rounded to their resolution in
print and in JSON (``sim_plant.figures``)."""

from __future__ import annotations

import json
import math
from typing import Any

from mrsteer_cli.hil_cli import summary_lines
from sim_plant.figures import resolution_of, tidy, tidy_figures
from sim_plant.harness.hil_timing import timing

LATE = {"controller": {"cycles": 2500, "overruns": 38, "missed_cycles": 44, "lateness_p50_s": 8.8e-05,
                       "lateness_p99_s": 0.005164, "lateness_max_s": 0.0061, "rx_frames": 5354},
        "plant": {"steps": 2501, "overruns": 0, "lateness_p50_s": 1e-05, "lateness_p99_s": 0.0001,
                  "lateness_max_s": 0.0004}}
CLEAN = {"controller": {**LATE["controller"], "overruns": 0, "missed_cycles": 0, "lateness_p99_s": 0.00021,
                        "lateness_max_s": 0.0009},
         "plant": LATE["plant"]}


def _summary(loop: dict[str, Any], mode: str = "realtime") -> dict[str, Any]:
    """A hil run summary as ``hil_report.finish`` builds it, with the float noise the issue saw."""
    return {"scenario": "handover", "mode": mode, "rate_hz": 500.0, "delay_steps": 1, "controller": "none",
            "duration": 5.0, "peak_yaw_rate_rad_s": 0.020300000000000002, "final_yaw_rate_rad_s": -1.16e-164,
            "peak_aux_steer_deg": 2.2589412345678, "final_aux_steer_deg": -1.81416, "saturated": False,
            "stable": True, "plant": "linear", "actuator": "ideal", "sensors": "ideal",
            "peak_measured_yaw_rate_rad_s": 0.0438372111, "peak_side_slip_deg": 1.09354, "aux_rms_deg": 1.70861,
            "time_at_limit_s": 0.0, "final_speed_m_s": 25.0,
            "frames": {"on_bus_logged": 9206, "sent_plant": 5354, "sent_controller": 3852},
            "loop": loop, "timing": timing(loop, mode, 500.0)}


def test_a_run_with_overruns_did_not_hold_its_timing_and_says_so_in_one_line() -> None:
    t = timing(LATE, "realtime", 500.0)
    assert t["held"] is False and t["controller"]["overruns"] == 38 and t["plant"]["overruns"] == 0
    lines = summary_lines(_summary(LATE))
    assert "  timing controller         overruns 38, missed cycles 44, lateness p99 5.16 ms, max 6.1 ms" in lines
    assert "  timing plant              overruns 0, lateness p99 0.1 ms, max 0.4 ms" in lines
    # a plant that overran makes its late steps up (it has no missed cycles to count): said so
    late_plant = {**LATE, "plant": {**LATE["plant"], "overruns": 3}}
    assert "  timing plant              overruns 3, late steps made up, none skipped, lateness p99 0.1 ms, max 0.4 ms" \
        in summary_lines(_summary(late_plant))
    verdict = [ln for ln in lines if ln.startswith("  timing  ")]
    assert len(verdict) == 1 and "did NOT hold" in verdict[0] and "the controller ran late" in verdict[0]
    assert "plant" not in verdict[0]  # only the process that ran late is named


def test_a_clean_run_held_its_timing() -> None:
    t = timing(CLEAN, "realtime", 500.0)
    assert t["held"] is True
    verdict = summary_lines(_summary(CLEAN))[-1]
    assert verdict.startswith("  timing  ") and "held: no overrun or missed cycle" in verdict and "NOT" not in verdict


def test_late_starts_without_an_overrun_and_lockstep_runs() -> None:
    slow = {**CLEAN, "plant": {**CLEAN["plant"], "lateness_p99_s": 0.0012}}  # more than half the 2 ms period
    assert timing(slow, "realtime", 500.0)["held"] is False
    assert "the plant ran late" in summary_lines(_summary(slow))[-1]
    lockstep = timing({"controller": {"overruns": 0, "missed_cycles": 0, "lateness_p99_s": 0.0}}, "lockstep", 500.0)
    assert lockstep["held"] is None
    assert "lockstep" in summary_lines(_summary(CLEAN, mode="lockstep"))[-1]


def test_the_printed_summary_has_no_dict_reprs_and_no_float_noise() -> None:
    text = "\n".join(summary_lines(_summary(LATE)))
    assert "{" not in text and "}" not in text
    assert "  frames\n    on_bus_logged           9206\n" in text  # nested figures as key value lines
    assert "peak_yaw_rate_rad_s       0.0203\n" in text and "final_yaw_rate_rad_s      0\n" in text
    assert "0.020300000000000002" not in text and "e-164" not in text and "rate_hz                   500\n" in text


def _floats(value: Any, name: str = "") -> list[tuple[str, float]]:
    if isinstance(value, dict):
        return [f for k, v in value.items() for f in _floats(v, k)]
    if isinstance(value, list):
        return [f for v in value for f in _floats(v, name)]
    return [(name, value)] if isinstance(value, float) else []


def test_json_floats_carry_no_more_digits_than_their_rounding() -> None:
    doc = json.loads(json.dumps(tidy_figures(_summary(LATE))))
    floats = _floats(doc)
    assert len(floats) > 15 and all(tidy(x, resolution_of(name)) == x for name, x in floats)
    assert doc["peak_yaw_rate_rad_s"] == 0.0203 and doc["final_yaw_rate_rad_s"] == 0.0  # below 1e-6 rad/s: 0
    assert doc["peak_aux_steer_deg"] == 2.25894 and doc["timing"]["controller"]["lateness_p99_s"] == 0.005164
    assert isinstance(doc["frames"]["on_bus_logged"], int) and doc["saturated"] is False
    assert tidy(-1.16e-164, resolution_of("aux_applied_rad")) == 0.0 and math.copysign(1, tidy(-1e-9, 1e-6)) == 1.0
