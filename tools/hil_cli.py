"""``mrsteer hil``: HIL runs on the bus (run, evidence, demo), their options and handlers."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from firmware_py import model_regulator as mr
from firmware_py.controller.node import DEFAULT_RATE_HZ
from firmware_py.controller.options import RATES_HELP, calibration_at_rate
from firmware_py.platform.cli import add_quick_arg, add_secoc_args, Parser, secoc_key
from mrsteer_cli.cli_args import add_gains, count, number, say
from sim_plant.car.options import add_car_args, add_sensor_fault_arg
from sim_plant.car.scenario import SPEED_RANGE
from sim_plant.car.vehicle import MAX_MU, VehicleParams
from sim_plant.harness.launch import add_controller_impl_args, program_of
from sim_plant.judge.caused_yaw import CAUSED_YAW_TARGET
from sim_plant.harness.faults.settings import PLAUS_DETECT
from sim_plant.offline import experiments
from sim_plant.offline.closed_loop import CONTROLLERS

if TYPE_CHECKING:
    from sim_plant.harness.hil import HilConfig


def add_parsers(sub: Any) -> None:
    """``mrsteer hil run|evidence|demo``."""
    hil = sub.add_parser("hil", help="hardware-in-the-loop runs: plant, controller and logger on one bus",
                         description="Hardware-in-the-loop runs on SocketCAN vcan0 or the fallback bus.")
    hil_sub = hil.add_subparsers(dest="hil_command", required=True, parser_class=Parser)
    p = hil_sub.add_parser("run", help="run one scenario and write log, CSV, plot and summary",
                           description="Start the plant, the controller and a bus logger as separate processes, "
                           "run the scenario, stop everything and write traffic.log (candump -L), signals.csv, "
                           "plot.png and summary.json.")
    _add_hil_args(p)
    p.add_argument("--scenario", default="paper-fig9",
                   help="built-in (paper-fig8, paper-fig9, handover; on the realistic car split-mu, side-wind, "
                   "blow-out) or a TOML file (default paper-fig9)")
    p.add_argument("--v", type=number("speed v", *SPEED_RANGE), metavar="MPS", help="override the scenario's speed")
    p.add_argument("--mu", type=number("friction mu", 0.0, MAX_MU, lo_open=True), metavar="MU",
                   help="override the scenario's friction")
    p.add_argument("--mz", type=number("M_z", -20000.0, 20000.0), metavar="NM",
                   help="override the scenario's yaw-moment steps")
    p.add_argument("--duration", type=number("duration", 0.0, 600.0, lo_open=True), metavar="S",
                   help="override the scenario's duration")
    p.add_argument("--controller", choices=CONTROLLERS, default=mr.Q_LIMITED,
                   help="none, standard or limited (default limited)")
    add_gains(p)
    p.add_argument("--delay-steps", type=count, default=1, metavar="N",
                   help="lockstep: samples from measurement to applied command (default 1)")
    add_car_args(p)
    add_sensor_fault_arg(p)
    add_controller_impl_args(p)
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(handler=_cmd_hil_run)
    p = hil_sub.add_parser("evidence", help="the realistic scenarios with and without the controller, one table",
                           description="Run split-mu, side-wind and blow-out (the realistic car: nonlinear tyres, "
                           "the default actuator and sensors, the driver model with a 1 s panic time) on the bus, "
                           "each with and without the controller, and print peak yaw rate and its reduction, peak "
                           "side slip, the auxiliary command's peak and RMS and the time at the +-3 deg limit.")
    _add_hil_args(p, default_out="out/hil-evidence")
    p.add_argument("--scenario", action="append", metavar="NAME",
                   help="run only these scenarios (built-in or TOML file); repeatable (default: the three)")
    p.add_argument("--controller", choices=(mr.Q_STANDARD, mr.Q_LIMITED), default=mr.Q_LIMITED,
                   help="standard or limited (default limited)")
    add_gains(p)
    add_car_args(p)
    add_quick_arg(p, "end each scenario 1 s after its last event (1.5 s for the three built-ins, instead of 4 s): "
                   "a smoke run of the command, not the evidence")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    p.set_defaults(handler=_cmd_hil_evidence)
    p = hil_sub.add_parser("demo", help="the quick-start demo: paper-fig9 with and without the controller",
                           description="Run the paper's 4000 Nm yaw-moment step (Figure 9) on the bus with and "
                           "without the controller, and explain the result.")
    _add_hil_args(p, default_out="out/hil-demo")
    p.set_defaults(handler=_cmd_hil_demo)


def _add_hil_args(p: argparse.ArgumentParser, default_out: str | None = None) -> None:
    p.add_argument("--interface", help="python-can interface (default: SocketCAN vcan0 if present, "
                   "else a private mrsteer fallback bus)")
    p.add_argument("--channel", help="channel for the interface")
    p.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep",
                   help="lockstep: deterministic, comparable with `sim --ts` (default); realtime: wall clock")
    p.add_argument("--rate-hz", type=number("rate", 1.0, 5000.0), default=None,
                   help=f"controller and plant rate in Hz (default: the calibration's, {DEFAULT_RATE_HZ:g} for the "
                   f"shipped one); without --calibration or --k a rate with a calibration of its own: {RATES_HELP}")
    p.add_argument("--out", type=Path, default=Path(default_out) if default_out else None, metavar="DIR",
                   help=f"output directory (default {default_out or 'out/hil/<scenario>-<mode>'})")
    add_secoc_args(p)


def _hil_config(args: argparse.Namespace, **overrides: object) -> "HilConfig":
    """The run the options ask for, at a rate with a calibration made for it (RateError, a
    ValueError: one line); a bad SecOC key is a SecOCError, a ValueError too."""
    from sim_plant.harness.hil import HilConfig

    key = secoc_key(args)
    ctrl = calibration_at_rate(args, args.rate_hz)
    rate_hz = args.rate_hz if args.rate_hz is not None else 1.0 / ctrl.ts
    base = dict(mode=args.mode, rate_hz=rate_hz, calibration=ctrl, interface=args.interface, channel=args.channel,
                secoc_key=key)
    base.update(overrides)
    return HilConfig(**base)  # type: ignore[arg-type]


def _cmd_hil_run(args: argparse.Namespace) -> int:
    from sim_plant.harness import hil

    out = args.out or Path("out/hil") / f"{Path(args.scenario).stem}-{args.mode}"
    cfg = _hil_config(args, scenario=args.scenario, v=args.v, mu=args.mu, mz=args.mz, duration=args.duration,
                      controller=args.controller, delay_steps=args.delay_steps, out=out, plant=args.plant,
                      actuator=args.actuator, sensors=args.sensors, seed=args.seed,
                      sensor_faults=tuple(args.sensor_fault))
    cfg = replace(cfg, controller_program=program_of(args))  # LaunchError: one line
    args.interrupted = f"interrupted; every process it started is stopped, nothing written to {out}"
    result = hil.run(cfg, progress=say)  # HilError (a process failed), BusOpenError: one line
    s = result.summary
    print(json.dumps(s, indent=2) if args.json else "\n".join(summary_lines(s)))
    return 0


# What ``hil run`` prints of its summary (summary.json has it all), in this order.
PRINTED = ("scenario", "mode", "rate_hz", "delay_steps", "controller", "peak_yaw_rate_rad_s", "final_yaw_rate_rad_s",
           "peak_aux_steer_deg", "final_aux_steer_deg", "saturated", "stable", "plant", "actuator", "sensors",
           "peak_measured_yaw_rate_rad_s", "peak_side_slip_deg", "aux_rms_deg", "time_at_limit_s", "spun",
           "spin_time_s", "final_speed_m_s", "frames")


def summary_lines(s: dict[str, Any]) -> list[str]:
    """``hil run``'s printed summary: ``key value`` lines (the frame counts nested under
    ``frames``), the plausibility monitor's verdict, and whether the loops held their timing."""
    from sim_plant import figures
    from sim_plant.harness import hil_timing

    out = figures.lines({key: s[key] for key in PRINTED if key in s})
    out.append(f"  {'plausibility':<26}"
               + (plausibility_line(s["plausibility"], s["duration"]) if s["controller"] != "none"
                  else "no controller: nothing monitors the sensors"))
    if "timing" in s:
        out += hil_timing.lines(s["timing"])
    return out


def plausibility_line(pl: dict, duration: float | None = None) -> str:
    """The summary's ``plausibility`` entry in words (``hil run``'s last line).  A fault not
    reported whose error passed the bound says how long before the run's ``duration`` (s) that
    was: less than the 300 ms target is no verdict yet (a longer run would give one)."""
    reported = pl.get("reported_s", pl["fault_detected_s"])
    found = "none" if reported is None else f"at {reported:.3f} s"
    over = pl.get("error_over_bound_s")
    if reported is None and over is not None:
        found += f"; its error passed the bound at {over:.3f} s"
        if duration is not None:
            left = duration - over
            found += (f", {1e3 * left:.0f} ms before the run's end: too soon to judge, run longer"
                      if left < PLAUS_DETECT else f", {left:.2f} s before the run's end: not found in time")
    if pl["detection_latency_s"] is not None:
        found += f", {1e3 * pl['detection_latency_s']:.0f} ms after the sensor fault"
    if pl["latency_from_bound_s"] is not None:
        ms = 1e3 * pl["latency_from_bound_s"]
        found += f", {ms:.0f} ms after its error passed the bound" if ms >= 0.0 else (
            f", {-ms:.0f} ms before its error passed the bound (found by its noise or another check)")
    what = "DEGRADED (no sensor fault bit)" if pl.get("reported_as") == "degraded" else "fault"
    line = f"bits seen {pl['bits_seen']}, {what} reported {found}"
    if pl.get("sensor_faults"):
        caused = pl.get("caused_yaw_rad_s")
        line += (f"; caused yaw not estimated: {pl.get('caused_yaw_note')}" if caused is None else
                 f"; the command caused at most {caused:.4f} rad/s of yaw (target {CAUSED_YAW_TARGET:g}: "
                 f"{'met' if caused <= CAUSED_YAW_TARGET else 'NOT met'})")
    return line


def _cmd_hil_evidence(args: argparse.Namespace) -> int:
    from sim_plant.harness import hil_evidence

    cfg = _hil_config(args, controller=args.controller, out=args.out, plant=args.plant, actuator=args.actuator,
                      sensors=args.sensors, seed=args.seed)
    args.interrupted = f"interrupted; every process it started is stopped, nothing written to {args.out}"
    rows = hil_evidence.run(cfg, tuple(args.scenario or hil_evidence.SCENARIOS), progress=say, quick=args.quick)
    from sim_plant.figures import tidy_figures

    print(json.dumps(tidy_figures([e.row() for e in rows]), indent=2) if args.json else hil_evidence.format_table(rows))
    say(f"wrote {', '.join(f'{Path(e.scenario).stem}/' for e in rows)}, {hil_evidence.ROWS_FILE} and "
        f"{hil_evidence.TABLE_FILE} to {args.out}/" + (" (--quick: a smoke run, not the evidence)" if args.quick else ""))
    return 0


def _cmd_hil_demo(args: argparse.Namespace) -> int:
    from mrsteer_cli import hil_demo
    from sim_plant.car import scenario as scn
    from sim_plant.harness import hil

    runs = {}
    configs = {ctrl: _hil_config(args, scenario=hil_demo.SCENARIO, controller=ctrl,
                                 out=args.out / ("with-controller" if ctrl != "none" else "without-controller"))
               for ctrl in (mr.Q_LIMITED, "none")}
    args.interrupted = "interrupted; every process it started is stopped, nothing written"
    for ctrl, cfg in configs.items():
        runs[ctrl] = hil.run(cfg, progress=say)  # HilError, BusOpenError: one line
        args.interrupted = (f"interrupted; every process it started is stopped; {cfg.out} holds the run with the "
                            "controller, complete, and nothing else is written")
    on, off = runs[mr.Q_LIMITED].summary, runs["none"].summary
    sc = scn.load(hil_demo.SCENARIO)
    ctrl_cfg = replace(configs[mr.Q_LIMITED].calibration, ts=1.0 / on["rate_hz"])
    offline = experiments.run(experiments.disturbance(VehicleParams(v=on["v"], mu=on["mu"]), on["m_z"], mr.Q_LIMITED,
                                                      ctrl_cfg, 3.0),
                              1.0 / on["rate_hz"], on["delay_steps"]).summary()
    hil_demo.write_figure(runs[mr.Q_LIMITED], runs["none"], sc, args.out)
    print(hil_demo.explain(sc, on, off, offline["peak_yaw_rate_rad_s"], args.out))
    if args.mode == "realtime":
        from sim_plant.harness.hil_timing import verdict_line

        for label, s in (("with the controller", on), ("without it", off)):
            print(f"timing of the run {label}: {verdict_line(s['timing'])}")
    return 0
