"""``mrsteer design margins|tune|compare|busload``: offline design checks (issues 5 and 15)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

from firmware_py import model_regulator as mr
from firmware_py.controller.options import calibration_from_args
from firmware_py.platform.cli import add_quick_arg, fail, output_file_problem
from mrsteer_cli.cli_args import MASS_RANGE, add_gains, add_models, count, loop_models, number
from sim_plant.car.scenario import SPEED_RANGE
from sim_plant.car.vehicle import MAX_MU

GRID_HELP = "LO:HI:N (N evenly spaced values, ends included) or a single value"


def _grid(kind: str, lo_limit: float, hi_limit: float) -> Callable[[str], tuple[float, ...]]:
    """argparse type for an envelope axis, ``LO:HI:N`` or one value."""

    def parse(text: str) -> tuple[float, ...]:
        from sim_plant.offline.margins import linspace_grid

        parts = text.split(":")
        try:
            if len(parts) == 1:
                lo = hi = float(parts[0])
                n = 1
            elif len(parts) == 3:
                lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
            else:
                raise ValueError
        except ValueError:
            raise argparse.ArgumentTypeError(f"{kind} grid must be {GRID_HELP}, got {text!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo_limit <= lo <= hi <= hi_limit):
            raise argparse.ArgumentTypeError(f"{kind} grid must satisfy {lo_limit:g} <= LO <= HI <= {hi_limit:g}, "
                                             f"got {text!r}")
        if not 1 <= n <= 200:
            raise argparse.ArgumentTypeError(f"{kind} grid needs 1..200 points, got {n}")
        return linspace_grid(lo, hi, n)

    return parse


def _add_envelope(p: argparse.ArgumentParser) -> None:
    from sim_plant.offline import margins as M

    for flag, kind, (lo, hi, n), limits in (
            ("--v-grid", "speed", M.DEFAULT_SPEEDS, SPEED_RANGE),
            ("--mu-grid", "friction", M.DEFAULT_FRICTIONS, (0.01, MAX_MU)),
            ("--mass-grid", "mass", M.DEFAULT_MASSES, MASS_RANGE)):
        p.add_argument(flag, type=_grid(kind, *limits), default=None, metavar="LO:HI:N",
                       help=f"{kind} values of the envelope, {GRID_HELP} (default {lo:g}:{hi:g}:{n})")


def _envelope(args: argparse.Namespace) -> Any:
    from sim_plant.offline.margins import QUICK_ENVELOPE, Envelope

    d = QUICK_ENVELOPE if getattr(args, "quick", False) else Envelope()
    return Envelope(args.v_grid or d.speeds, args.mu_grid or d.frictions, args.mass_grid or d.masses)


def _add_loop(p: argparse.ArgumentParser, form_help: str) -> None:
    d = mr.ControllerConfig()
    p.add_argument("--ts", type=number("ts", 0.0, 0.1, lo_open=True), default=d.ts, metavar="S",
                   help=f"controller step in s (default {d.ts:g}, the shipped default)")
    p.add_argument("--delay-steps", type=count, default=1, metavar="N",
                   help="samples from measurement to applied command (default 1)")
    p.add_argument("--controller", choices=(mr.Q_LIMITED, mr.Q_STANDARD), default=d.q_form,
                   help=f"{form_help} (default {d.q_form})")


def _add_reference(p: argparse.ArgumentParser) -> None:
    add_models(p)
    p.add_argument("--reference", action="store_true",
                   help="issue 15's reference loop: --actuator default --sensors default (with the default "
                   "--ts 0.002 and --delay-steps 1)")


def _models(args: argparse.Namespace) -> Any:
    from sim_plant.offline.loop_plant import LoopModels

    if args.reference:
        if args.actuator is not None or args.sensors is not None:
            raise ValueError("--reference sets --actuator and --sensors; give one or the other")
        return LoopModels.reference()
    return loop_models(args)


def add_parsers(sub: Any, parser_class: type) -> None:
    design = sub.add_parser("design", help="stability margins, tuning and bus load (offline design)",
                            description="Offline design checks of the discrete controller on a real bus.")
    dsub = design.add_subparsers(dest="design_command", required=True, parser_class=parser_class)
    d = mr.ControllerConfig()

    p = dsub.add_parser("margins", help="pole radius, gain/phase/delay margins over the operating envelope",
                        description="Closed-loop pole radius and gain, phase and delay margins of the sampled "
                        "loop (exact ZOH plant, the firmware's own discretised controller, N samples of delay) "
                        "at every point of an operating envelope, and the worst case.")
    _add_loop(p, "limited (eq. 22) or standard (eq. 17) model regulator")
    add_gains(p)
    p.add_argument("--method", choices=(mr.METHOD_TUSTIN, mr.METHOD_ZOH), default=None,
                   help=f"discretisation (default: the calibration's, {d.method})")
    _add_envelope(p)
    _add_reference(p)
    add_quick_arg(p, "a coarse envelope by default: 24 points (v 5:50:4, mu 0.1:1:3, mass 1296:1800:2) instead of "
                   "300; the grid options still override it")
    p.add_argument("--constraints", action="store_true",
                   help="also the constraint figures of issue 15 (extra sample of delay, actuator time constant "
                   "x0.5..x2, command noise, applied-angle saturation threshold, dry-road peaks); on by default "
                   "when an actuator or sensor model is in the loop")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (stable, worst, points; with the constraints: constraints.worst, "
                   "constraints.points, constraints.dry_road)")
    p.set_defaults(handler=_cmd_margins)

    p = dsub.add_parser("tune", help="choose K, tau, tau_n for the strongest rejection with GM >= 6 dB, PM >= 45 deg",
                        description="Search K, tau and tau_n (and whether to model the loop delay) for the lowest "
                        "peak yaw rate after a 4000 Nm yaw-moment step at 10 m/s on dry road, keeping gain margin "
                        ">= 6 dB and phase margin >= 45 deg over the whole envelope.")
    _add_loop(p, "model regulator form")
    _add_envelope(p)
    _add_reference(p)
    p.add_argument("--schedule", action="store_true",
                   help="tune the shipped law's speed schedule instead (K, tau_Q, tau_n per breakpoint, nominal "
                   "actuator and filter, M 1) on the reference loop unless --actuator/--sensors say otherwise, "
                   "for the lowest peak yaw rate at each breakpoint with every constraint of issue 15 met")
    p.add_argument("--start", type=_calibration_file, default=None, metavar="FILE.cfg",
                   help="with --schedule: the schedule to start from (default: the shipped one)")
    p.add_argument("--out", type=Path, default=None, metavar="FILE.cfg",
                   help="with --schedule: write the tuned calibration there (firmware_py.calibration_file format)")
    add_quick_arg(p, "search every third K and tau of the grid and verify on the 24-point envelope of `design "
                   "margins --quick` unless a grid option says otherwise; with --schedule coarse local grids and "
                   "few trials: a smoke run, not the optimum")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_tune)

    p = dsub.add_parser("compare", help="trade-off table: the paper's, the previous and the shipped calibration, "
                        "ideal and reference loop", description="The paper's tuning, the previous shipped calibration "
                        "and the shipped schedule on the ideal loop (G_sa = 1, exact sensors) and on issue 15's "
                        "reference loop (20 ms actuator, 30 Hz yaw-rate filter), 500 Hz with one sample of delay: "
                        "stability, margins, delay margin, dry-road peaks, worst command noise, saturation "
                        "thresholds; with --out also a plot of peak yaw rate against command noise over candidates.")
    _add_envelope(p)
    add_quick_arg(p, "the table on the 24-point envelope of `design margins --quick` unless a grid option says "
                   "otherwise (the plot's candidates are scored as without it)")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="also write tradeoff.png (and tradeoff.json) there: peak yaw rate at the Figure-10 point "
                   "against worst command noise over candidate calibrations")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the Markdown table")
    p.set_defaults(handler=_cmd_compare)

    p = dsub.add_parser("busload", help="CAN bus load of the DBC's frames (nominal and worst-case stuffing)",
                        description="Bus load of every cyclic frame of the DBC; the control-loop frames at the "
                        "control rate.")
    from mrsteer_dbc.busload import BITRATE

    p.add_argument("--bitrate", type=number("bitrate", 10e3, 1e6), default=float(BITRATE), metavar="BPS",
                   help=f"bit rate in bit/s (default {BITRATE}, the bus the shipped design budgets)")
    p.add_argument("--rate-hz", type=number("rate", 0.0, 10000.0, lo_open=True), default=None, metavar="HZ",
                   help="control rate (default: the DBC's cycle time of the control-loop frames)")
    p.add_argument("--dbc", type=Path, default=None, help="DBC file (default: the packaged dbc/mrsteer.dbc)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_busload)


def _progress(label: str) -> Callable[..., None]:
    last = [-1]

    def show(*args: Any) -> None:
        stage, done, total = args if len(args) == 3 else (label, *args)
        pct = int(100 * done / total)
        if pct // 10 != last[0] // 10 or done == total:
            last[0] = pct
            print(f"{stage}: {done}/{total}", file=sys.stderr, flush=True)

    return show


def _fmt(x: float | None, spec: str) -> str:
    return "inf" if x is None else format(x, spec)


def _margins_table(result: dict[str, Any]) -> str:
    w = result["worst"]
    lines = [f"{result['controller']} model regulator, gains {mr.format_gains(result)}",
             f"Ts={result['ts']:g} s, {result['delay_steps']} sample(s) of delay, model delay "
             f"{result['model_delay_steps']}",
             f"{len(result['points'])} operating points: {'STABLE' if result['stable'] else 'UNSTABLE'} everywhere"
             if result["stable"] else
             f"{len(result['points'])} operating points: UNSTABLE at "
             f"{sum(not p['stable'] for p in result['points'])} of them",
             f"{'worst':<22}{'value':>12}   at v [m/s], mu, mass [kg]"]
    for key, spec in (("max_pole_radius", ".5f"), ("gain_margin_db", ".2f"), ("phase_margin_deg", ".1f"),
                      ("delay_margin_s", ".5f")):
        where = w["where"].get(key)
        at = f"{where['v']:g}, {where['mu']:g}, {where['mass']:g}" if where else "-"
        lines.append(f"{key:<22}{_fmt(w[key], spec):>12}   {at}")
    return "\n".join(lines)


def _constraints_table(res: dict[str, Any]) -> str:
    from sim_plant.offline.constraints import LIMITS

    labels = {"max_pole_radius": ("pole radius", "<", ".5f"), "gain_margin_db": ("gain margin, dB", ">=", ".2f"),
              "phase_margin_deg": ("phase margin, deg", ">=", ".1f"),
              "extra_delay_pole_radius": ("radius, +1 sample", "<", ".5f"),
              "tau_range_pole_radius": ("radius, T x0.5..2", "<", ".5f"),
              "noise_rms_deg": ("command noise, deg", "<=", ".3f"), "threshold_nm": ("threshold, Nm", ">=", ".0f")}
    c = res["constraints"]
    lines = [f"constraints ({res['models']['actuator']}; sensors {res['models']['sensors']}):",
             f"{'':<22}{'worst':>12}{'limit':>12}  verdict  at v [m/s], mu, mass [kg]"]
    for key in LIMITS:
        label, sense, spec = labels[key]
        w = c["worst"][key]
        value = "n/a" if w["where"] is None else ("unbounded" if w["value"] is None else format(w["value"], spec))
        at = "-" if w["where"] is None else ", ".join(f"{x:g}" for x in w["where"].values())
        lines.append(f"{label:<22}{value:>12}{sense:>4}{w['limit']:>8g}  {'pass' if w['pass'] else 'FAIL':<7}  {at}")
    for p in c["dry_road"]["points"]:
        lines.append(f"peak yaw rate after {c['dry_road']['m_z_nm']:g} Nm at {p['v']:g} m/s, mu 1: "
                     f"{p['peak_yaw_rate_rad_s']:.4f} rad/s")
    lines.append("ALL CONSTRAINTS MET" if c["passes"] else f"FAILS: {', '.join(c['failing'])}")
    return "\n".join(lines)


def _cmd_margins(args: argparse.Namespace) -> int:
    from sim_plant.offline.margins import envelope_margins

    cfg = calibration_from_args(args)
    cfg = replace(cfg, q_form=args.controller, ts=args.ts, method=args.method or cfg.method)
    env = _envelope(args)
    models = _models(args)
    margins = envelope_margins(cfg, args.delay_steps, env, progress=_progress("margins"), models=models)
    res = margins.as_dict()
    if args.constraints or not models.is_ideal:
        from sim_plant.offline.constraints import evaluate

        res["models"] = models.describe()
        res["constraints"] = evaluate(cfg, args.delay_steps, margins, models,
                                      progress=_progress("constraints")).as_dict()
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(_margins_table(res))
        if "constraints" in res:
            print(_constraints_table(res))
    return 0


def _calibration_file(text: str) -> Any:
    from firmware_py import calibration_file

    try:
        return calibration_file.load(Path(text))
    except (calibration_file.CalibrationError, OSError) as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _cmd_tune(args: argparse.Namespace) -> int:
    from sim_plant.offline.tuning import TuneInfeasible, tune

    if args.schedule:
        return _cmd_tune_schedule(args)
    if args.start is not None or args.out is not None:
        raise ValueError("--start and --out need --schedule")

    try:
        res = tune(args.ts, args.delay_steps, _envelope(args), q_form=args.controller,
                   progress=_progress("tune"), models=_models(args), coarse=args.quick).as_dict()
    except TuneInfeasible as exc:
        # a verdict on the structure, not an error: exit status 1
        return fail("mrsteer design tune", f"no calibration of this structure meets every constraint: {exc}", 1)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    o = res["objective"]
    print(f"tuned for Ts={res['ts']:g} s ({res['rate_hz']:g} Hz), {res['delay_steps']} sample(s) of delay:\n"
          f"  K = {res['k']:.4g}   tau = {res['tau']:.4g} s   tau_n = {res['tau_n']:g} s   "
          f"model delay = {res['model_delay_steps']}\n"
          f"  peak yaw rate after {o['m_z_nm']:g} Nm at {o['v']:g} m/s, mu {o['mu']:g}: "
          f"{o['peak_yaw_rate_rad_s']:.5f} rad/s\n"
          f"  worst gain margin {_fmt(res['worst']['gain_margin_db'], '.2f')} dB, worst phase margin "
          f"{_fmt(res['worst']['phase_margin_deg'], '.1f')} deg, worst pole radius "
          f"{res['worst']['max_pole_radius']:.5f} ({res['search']['feasible']} of {res['search']['screened']} "
          "grid candidates feasible)")
    if "constraint_figures" in res:
        c = res["constraint_figures"]
        print("  " + ("every constraint met" if c["passes"] else f"FAILS: {', '.join(c['failing'])}") + ": "
              + ", ".join(f"{k} {_fmt(w['value'], '.4g')}" for k, w in c["worst"].items()))
    return 0


def _cmd_tune_schedule(args: argparse.Namespace) -> int:
    from firmware_py import calibration_file
    from firmware_py.platform.files import write_files
    from mrsteer_cli.cli_args import say
    from sim_plant.offline import schedule_tuning as S
    from sim_plant.offline.loop_plant import LoopModels

    d = mr.ControllerConfig()
    if (args.ts, args.delay_steps, args.controller) != (d.ts, S.DELAY_STEPS, d.q_form):
        raise ValueError("--schedule tunes the shipped structure: --ts, --delay-steps and --controller must keep "
                         "their defaults")
    given = args.reference or args.actuator is not None or args.sensors is not None
    models = _models(args) if given else LoopModels.reference()
    if args.out is not None and (problem := output_file_problem("--out", args.out)) is not None:
        raise ValueError(problem)
    res = S.tune_schedule(_envelope(args), start=args.start, models=models, grids=S.QUICK if args.quick else S.FULL,
                          progress=say)
    if args.out is not None:
        write_files(args.out.parent, {args.out.name: calibration_file.dumps(res.config)})
    out = res.as_dict()
    if args.json:
        print(json.dumps(out, indent=2))
        return 0 if res.passes else 1
    print(f"{'v m/s':>6}{'K':>9}{'tau_Q ms':>10}{'tau ms':>10}{'tau_n ms':>10}{'peak r':>10}{'(start)':>10}")
    for r in out["breakpoints"]:
        print(f"{r['v']:>6g}{r['k']:>9.4g}{r['tau_q_s'] * 1e3:>10.4g}{r['tau_s'] * 1e3:>10.4g}{r['tau_n_s'] * 1e3:>10.4g}"
              f"{r['peak_yaw_rate_rad_s']:>10.5f}{r['start_peak_yaw_rate_rad_s']:>10.5f}")
    print(_constraints_table({"models": models.describe(), "constraints": out["constraints"]}))
    if args.out is not None:
        print(f"wrote {args.out}")
    return 0 if res.passes else 1


def _cmd_compare(args: argparse.Namespace) -> int:
    from firmware_py.platform.files import write_files
    from sim_plant.offline import compare as K

    if args.out is not None:
        try:
            args.out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"cannot create --out {args.out}: {exc.strerror}") from None
    table = K.compare(_envelope(args), progress=_progress("compare"))
    res: dict[str, Any] = {"assumes": K.ASSUMES, "delay_steps": K.DELAY_STEPS,
                           "rows": {n: {loop: f.as_dict() for loop, f in loops.items()} for n, loops in table.items()}}
    if args.out is not None:
        cands = K.cloud(progress=_progress("cloud"))
        res["cloud"] = [c.as_dict() for c in cands]
        write_files(args.out, {"tradeoff.png": K.plot_png(cands), "tradeoff.json": json.dumps(res, indent=2) + "\n"})
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    print(f"Assumes: {K.ASSUMES}.\n")
    print(K.markdown(table))
    if args.out is not None:
        print(f"\nwrote {args.out / 'tradeoff.png'} and {args.out / 'tradeoff.json'}")
    return 0


def _cmd_busload(args: argparse.Namespace) -> int:
    import mrsteer_dbc
    from mrsteer_dbc.busload import bus_load, max_rate_hz

    contract = mrsteer_dbc.load(args.dbc)
    load = bus_load(contract, args.bitrate, args.rate_hz)
    res = load.as_dict()
    res["max_rate_hz_at_40_percent_worst"] = max_rate_hz(contract, args.bitrate, 40.0)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    print(f"{args.bitrate / 1000:g} kbit/s, control loop at {load.rate_hz:g} Hz")
    print(f"{'message':<20}{'id':>6}{'bytes':>6}{'cycle ms':>10}{'bits':>6}{'worst':>6}{'load %':>8}{'worst %':>9}")
    for m in load.messages:
        print(f"{m.name:<20}{m.frame_id:>#6x}{m.length:>6}{m.cycle_s * 1e3:>10.3g}{m.bits_nominal:>6}"
              f"{m.bits_worst:>6}{m.load_percent_nominal:>8.2f}{m.load_percent_worst:>9.2f}")
    print(f"{'total':<54}{load.load_percent_nominal:>8.2f}{load.load_percent_worst:>9.2f}")
    print(f"highest control rate under 40 % worst-case load: {res['max_rate_hz_at_40_percent_worst']:.0f} Hz")
    return 0
