"""``mrsteer hil evidence``: the realistic built-in scenarios on the bus, each with and without
the controller, in one table (issue 15, item 5).

Every figure comes from the plant's true states (``hil_report.car_figures``): the peak yaw
rate and its reduction against the same run without the controller, the peak side slip, the
auxiliary command's peak and RMS, and the time it sat at the +-3 deg limit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

from sim_plant.harness import hil

#: The built-ins of issue 15's HIL evidence (``scenario.BUILTINS``).
SCENARIOS = ("split-mu", "side-wind", "blow-out")


@dataclass(frozen=True)
class Evidence:
    """One scenario's two runs' summaries."""

    scenario: str
    with_controller: dict[str, Any]
    without_controller: dict[str, Any]

    @property
    def reduction(self) -> float:
        """1 - peak yaw rate with / without the controller (true yaw rates)."""
        off = self.without_controller["peak_yaw_rate_rad_s"]
        return 1.0 - self.with_controller["peak_yaw_rate_rad_s"] / off if off else 0.0

    def row(self) -> dict[str, Any]:
        on, off = self.with_controller, self.without_controller
        return {"scenario": self.scenario, "peak_yaw_rate_off_rad_s": off["peak_yaw_rate_rad_s"],
                "peak_yaw_rate_on_rad_s": on["peak_yaw_rate_rad_s"], "reduction": self.reduction,
                "peak_side_slip_off_deg": off["peak_side_slip_deg"], "peak_side_slip_on_deg": on["peak_side_slip_deg"],
                "aux_peak_deg": on["peak_aux_steer_deg"], "aux_rms_deg": on["aux_rms_deg"],
                "time_at_limit_s": on["time_at_limit_s"], "final_speed_m_s": on["final_speed_m_s"],
                "plant": on["plant"], "actuator": on["actuator"], "sensors": on["sensors"]}


def run(base: hil.HilConfig, scenarios: tuple[str, ...] = SCENARIOS,
        progress: Callable[[str], None] | None = None) -> list[Evidence]:
    """Each scenario twice, with ``base``'s controller and without one, into ``base.out``/<scenario>/."""
    out = []
    for name in scenarios:
        runs = {}
        for ctrl in (base.controller, "none"):
            sub = "with-controller" if ctrl != "none" else "without-controller"
            cfg = replace(base, scenario=name, controller=ctrl, out=base.out / Path(name).stem / sub)
            runs[ctrl] = hil.run(cfg, progress).summary
        out.append(Evidence(name, runs[base.controller], runs["none"]))
    return out


def format_table(rows: list[Evidence]) -> str:
    head = (f"{'scenario':<12}{'peak r off':>11}{'peak r on':>11}{'reduction':>10}{'beta off':>10}{'beta on':>9}"
            f"{'aux peak':>10}{'aux RMS':>9}{'at limit':>10}{'v end':>8}")
    lines = [head, f"{'':<12}{'rad/s':>11}{'rad/s':>11}{'':>10}{'deg':>10}{'deg':>9}{'deg':>10}{'deg':>9}{'s':>10}"
             f"{'m/s':>8}", "-" * len(head)]
    for e in rows:
        r = e.row()
        lines.append(f"{r['scenario']:<12}{r['peak_yaw_rate_off_rad_s']:>11.4f}{r['peak_yaw_rate_on_rad_s']:>11.4f}"
                     f"{r['reduction']:>10.0%}{r['peak_side_slip_off_deg']:>10.2f}{r['peak_side_slip_on_deg']:>9.2f}"
                     f"{r['aux_peak_deg']:>10.2f}{r['aux_rms_deg']:>9.3f}{r['time_at_limit_s']:>10.2f}"
                     f"{r['final_speed_m_s']:>8.1f}")
    if rows:
        r = rows[0].row()
        lines.append(f"car: {r['plant']} plant, actuator {r['actuator']}, sensors {r['sensors']}; "
                     f"controller {rows[0].with_controller['controller']} (K = {rows[0].with_controller['k']:g}, "
                     f"tau = {rows[0].with_controller['tau']:g} s); yaw rate and side slip are the plant's true states")
    return "\n".join(lines)

