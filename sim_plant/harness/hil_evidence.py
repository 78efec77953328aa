"""``mrsteer hil evidence``: the realistic built-in scenarios on the bus, each with and without
the controller, in one table (issue 15, item 5).

Every figure comes from the plant's true states (``hil_report.car_figures``): the peak yaw
rate and its reduction against the same run without the controller, the peak side slip, the
auxiliary command's peak and RMS, and the time it sat at the +-3 deg limit.

The outputs are written whole or not at all (``files.staged_directory``): every run goes to a
directory beside ``out`` first, and replaces ``out``'s entries of the same names only when all
have finished, so a failed or interrupted evidence leaves ``out`` as it was.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

from firmware_py import model_regulator as mr
from firmware_py.platform.files import staged_directory, write_files
from sim_plant.car import scenario as scn
from sim_plant.figures import tidy_figures
from sim_plant.harness import hil

#: The built-ins of issue 15's HIL evidence (``scenario.BUILTINS``).
SCENARIOS = ("split-mu", "side-wind", "blow-out")
#: ``--quick``: each scenario ends this long after its last event (s): a smoke run of the command.
QUICK_AFTER_LAST_EVENT = 1.0
#: What ``run`` writes beside the runs' directories: the rows, and the table as printed.
ROWS_FILE, TABLE_FILE = "evidence.json", "evidence.txt"


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
                "duration_s": on["duration"],
                "plant": on["plant"], "actuator": on["actuator"], "sensors": on["sensors"]}


def quick_duration(name: str) -> float:
    """The scenario's duration under ``--quick``: up to ``QUICK_AFTER_LAST_EVENT`` after its
    last event, never longer than the scenario."""
    sc = scn.load(name)
    last = max((e.t for e in sc.events), default=0.0)
    return min(sc.duration, last + QUICK_AFTER_LAST_EVENT)


def run(base: hil.HilConfig, scenarios: tuple[str, ...] = SCENARIOS,
        progress: Callable[[str], None] | None = None, quick: bool = False) -> list[Evidence]:
    """Each scenario twice, with ``base``'s controller and without one, into
    ``base.out``/<scenario>/{with,without}-controller/, and the rows into ``base.out``/evidence.json
    and the table into evidence.txt: all of it or, on an error, none (see the module's docstring)."""
    out = []
    with staged_directory(base.out) as stage:
        say = None if progress is None else lambda msg: progress(msg.replace(str(stage), str(base.out)))
        for name in scenarios:
            duration = quick_duration(name) if quick else base.duration
            runs = {}
            for ctrl in (base.controller, "none"):
                sub = "with-controller" if ctrl != "none" else "without-controller"
                cfg = replace(base, scenario=name, controller=ctrl, duration=duration,
                              out=stage / Path(name).stem / sub)
                runs[ctrl] = hil.run(cfg, say).summary
            out.append(Evidence(name, runs[base.controller], runs["none"]))
        write_files(stage, {ROWS_FILE: json.dumps(tidy_figures([e.row() for e in out]), indent=2) + "\n",
                            TABLE_FILE: format_table(out) + "\n"})
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
        lines.append(f"car: {r['plant']} plant, actuator {r['actuator']}, sensors {r['sensors']}; yaw rate and side "
                     "slip are the plant's true states")
        on = rows[0].with_controller
        lines.append(f"controller {on['controller']}, gains {mr.format_gains(on)}")
        lines.append("runs of " + ", ".join(f"{e.scenario} {e.row()['duration_s']:g} s" for e in rows))
    return "\n".join(lines)

