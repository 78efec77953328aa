"""``mrsteer hil demo``: what the two runs (with and without the controller) showed, in words
and in one figure."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from firmware_py.platform.files import write_files
from sim_plant.car import scenario as scn
from sim_plant.harness import hil_plot
from sim_plant.harness.hil_report import HilRun

SCENARIO = "paper-fig9"
FIGURE = "plot.png"


def explain(sc: scn.Scenario, on: dict[str, Any], off: dict[str, Any], offline_peak_yaw: float, out: Path) -> str:
    """The demo's story from the two runs' summaries, true to the scenario's driver."""
    cut = 1.0 - on["peak_yaw_rate_rad_s"] / off["peak_yaw_rate_rad_s"]
    match = abs(on["peak_yaw_rate_rad_s"] / offline_peak_yaw - 1.0)
    return f"""
{sc.name}: {sc.description or 'a scenario file'}.
A {on['m_z']:.0f} Nm yaw moment hits the car at {on['v']:g} m/s on a road with mu = {on['mu']:g}, {_driver(sc)};
the controller and the car run as separate processes talking over CAN ({on['mode']}, {on['rate_hz']:g} Hz).

  without the controller the car yaws at up to {off['peak_yaw_rate_rad_s']:.3f} rad/s;
  with it, at up to {on['peak_yaw_rate_rad_s']:.4f} rad/s: {cut:.0%} less,
  using at most {on['peak_aux_steer_deg']:.2f} deg of the +-3 deg auxiliary steering;
  {_ending(sc, on, off)}

The bus run agrees with the offline simulation of the same firmware to {match:.2%} in peak yaw rate.
Figure, with and without the controller: {out}/{FIGURE}
Logs, decoded signals, per-step tables, plots and summaries: {out}/with-controller and {out}/without-controller
(inspect with: cantools decode dbc/mrsteer.dbc < {out}/with-controller/traffic.log)."""


def _driver(sc: scn.Scenario) -> str:
    if sc.driver.mode == "hold":
        return "the driver's wheel held still"
    return f"the driver frozen for a {sc.driver.reaction_time:g} s panic reaction, then steering back"


def _ending(sc: scn.Scenario, on: dict[str, Any], off: dict[str, Any]) -> str:
    end = (f"the car ends at {on['final_yaw_rate_rad_s']:.4f} rad/s "
           f"({off['final_yaw_rate_rad_s']:.3f} rad/s without the controller)")
    if sc.driver.mode == "hold":
        return (f"with the wheel held, the controller keeps up its {on['final_aux_steer_deg']:.2f} deg "
                f"to the end, and {end}.")
    return (f"after the {sc.driver.reaction_time:g} s reaction time the driver steers against the rest of the "
            f"moment: the auxiliary steering ends at {on['final_aux_steer_deg']:.2f} deg and {end}.")


def write_figure(with_ctrl: HilRun, without_ctrl: HilRun, sc: scn.Scenario, out: Path) -> list[Path]:
    """The two runs overlaid in one figure (none without matplotlib)."""
    on, off = with_ctrl.summary, without_ctrl.summary
    cut = 1.0 - on["peak_yaw_rate_rad_s"] / off["peak_yaw_rate_rad_s"]
    png = hil_plot.comparison_png(with_ctrl.steps, without_ctrl.steps, hil_plot.event_marks(sc),
                                  f"HIL {sc.name} ({on['mode']}, {on['rate_hz']:g} Hz): peak yaw rate "
                                  f"{cut:.0%} less with the controller")
    return write_files(out, {FIGURE: png}) if png is not None else []
