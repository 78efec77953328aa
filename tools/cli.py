"""``mrsteer`` command line: a thin layer over firmware_py and sim_plant.

Every error is one line on stderr, ``mrsteer: COMMAND: what``, and exit status 2: an argument
error from the parser (``firmware_py.platform.cli.Parser``), any other from ``main``, which
formats what a command raises (``ERRORS``) with ``firmware_py.platform.cli.error_line``.  Ctrl-C
is one line and exit status 130; exit status 1 is a verdict (a replay that disagrees, a failed
design or fault-matrix row), never an error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Sequence

from firmware_py import model_regulator as mr
from firmware_py.controller.options import calibration_from_args, describe_gains, hand_gains
from firmware_py.platform.bus_open import BusOpenError
from firmware_py.platform.cli import EXIT_INTERRUPTED, CommandError, Parser, check_output_dir, describe, fail
from mrsteer_cli import campaign_cli, design_cli, hil_cli, replay_cli
from mrsteer_cli.cli_args import MASS_RANGE, add_gains, add_models, count, loop_models, number, say
from sim_plant.car.plants import LINEAR, PLANTS
from sim_plant.car.scenario import SPEED_RANGE
from sim_plant.car.vehicle import MAX_MU, PAPER_MASS, VehicleParams
from sim_plant.figures import tidy_figures
from sim_plant.offline import experiments
from sim_plant.harness.launch import LaunchError
from sim_plant.harness.processes import RunError
from sim_plant.offline.closed_loop import CONTROLLERS

MAX_DURATION = 60.0
PAPER_OUT = Path("out/paper")


UsageError = CommandError  # bad input from the user: one line, exit status 2

#: What a command raises for an error it reports in one line: bad input (ValueError: a file, a
#: value, a calibration, a scenario), a file that cannot be read or written (OSError), a bus that
#: cannot be opened, a controller program that cannot be had, a run whose process failed.
ERRORS = (CommandError, ValueError, OSError, BusOpenError, LaunchError, RunError)


def _add_operating_point(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument("--v", type=number("speed v", *SPEED_RANGE), required=required, default=None if required else 20.0,
                   metavar="MPS", help=f"speed in m/s, {SPEED_RANGE[0]:g}..{SPEED_RANGE[1]:g}")
    p.add_argument("--mu", type=number("friction mu", 0.0, MAX_MU, lo_open=True), required=required,
                   default=None if required else 1.0, metavar="MU", help=f"road friction, (0, {MAX_MU:g}]")
    p.add_argument("--mass", type=number("mass", *MASS_RANGE), default=PAPER_MASS, metavar="KG",
                   help=f"vehicle mass in kg (default {PAPER_MASS:g}, the paper's)")


def _add_controller(p: argparse.ArgumentParser, choices: Sequence[str] = CONTROLLERS) -> None:
    d = mr.ControllerConfig()
    p.add_argument("--controller", choices=choices, default=mr.Q_LIMITED,
                   help="none, standard (eq. 17) or limited (eq. 22) model regulator (default limited)")
    add_gains(p)
    p.add_argument("--method", choices=(mr.METHOD_TUSTIN, mr.METHOD_ZOH), default=None,
                   help=f"discretisation of the firmware when --ts > 0 (default: the calibration's, {d.method})")
    p.add_argument("--ts", type=number("ts", 0.0, 0.1, lo_open=True, allow_zero=True), default=None, metavar="S",
                   help="T > 0: the firmware at step T with the exact ZOH plant; 0: the continuous reference of "
                   "the paper's plain law (default: the calibration's step, 0 with --k/--tau/--tau-n)")
    p.add_argument("--delay-steps", type=count, default=1, metavar="N",
                   help="samples between measurement and applied command when --ts > 0 (default 1)")
    p.add_argument("--duration", type=number("duration", 0.0, MAX_DURATION, lo_open=True), default=3.0,
                   metavar="S", help="simulated time in s (default 3)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def _add_plant(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plant", choices=PLANTS, default=LINEAR,
                   help="the car: linear (the paper's exact model, default) or nonlinear (the bus runs' realistic car: "
                   "magic-formula tyres, the speed a state; needs --ts > 0; with --actuator default --sensors default "
                   "it is the car of the realistic built-in scenarios)")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="mrsteer", description="Limited-integrator model-regulator active steering: "
                    "controller firmware, vehicle simulator and tools.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    _add_sim_parsers(sub)
    _add_delegated_parsers(sub)
    design_cli.add_parsers(sub, Parser)
    p = sub.add_parser("vectors", help="write golden test vectors for ports of the controller",
                       description="Write, for several configurations and scenarios, every step's inputs, command "
                       "and state as CSV, and each configuration's calibration and coefficients as key = value "
                       "lines (see docs/porting.md). tests/vectors/ holds the checked-in set.")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory (created if needed)")
    p.set_defaults(handler=_cmd_vectors)
    hil_cli.add_parsers(sub)
    replay_cli.add_parsers(sub)
    campaign_cli.add_parsers(sub)
    _name_commands(parser)
    return parser


def _name_commands(parser: argparse.ArgumentParser) -> None:
    """Each subcommand's parser records its own name (``args.prog``, ``mrsteer hil run``): the
    command an error line names."""
    parser.set_defaults(prog=parser.prog)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                _name_commands(child)


def _add_sim_parsers(sub: Any) -> None:
    sim = sub.add_parser("sim", help="offline closed-loop simulation and the paper reproduction",
                         description="Closed-loop simulations of the single-track car with the model regulator.")
    sim_sub = sim.add_subparsers(dest="experiment", required=True, parser_class=Parser)

    p = sim_sub.add_parser("disturbance", help="yaw moment step with the driver's wheel held",
                           description="A step of yaw moment M_z at t = 0, driver's wheel held straight.")
    p.add_argument("--mz", type=number("M_z", -1e5, 1e5), required=True, metavar="NM", help="yaw moment step in Nm")
    _add_operating_point(p, required=True)
    _add_controller(p)
    _add_plant(p)
    add_models(p, seed=True)
    p.set_defaults(handler=_cmd_disturbance)

    p = sim_sub.add_parser("steer", help="driver steering step, normalised as in Figure 8",
                           description="Driver front-wheel step sized for a steady yaw rate of 1 rad/s of the "
                           "uncontrolled car on dry road; yaw rate is reported in those units.")
    _add_operating_point(p, required=True)
    _add_controller(p)
    _add_plant(p)
    add_models(p, seed=True)
    p.set_defaults(handler=_cmd_steer)

    p = sim_sub.add_parser("threshold", help="smallest yaw moment step that saturates the actuator",
                           description="Smallest M_z step (Nm) that drives the auxiliary command to its limit.")
    _add_operating_point(p, required=False)
    _add_controller(p, choices=(mr.Q_STANDARD, mr.Q_LIMITED))
    p.set_defaults(handler=_cmd_threshold)

    p = sim_sub.add_parser("paper", help="regenerate Figures 8-10 and compare with the paper's numbers",
                           description="Regenerate Figures 8, 9, 10 (PNG and CSV) at the six operating "
                           "conditions and print our numbers beside the paper's.")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help=f"directory for the figures (default {PAPER_OUT}; with --json, none unless given)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    p.set_defaults(handler=_cmd_paper)


def _add_delegated_parsers(sub: Any) -> None:
    """Commands whose own main parses the rest of the line (each has its own --help)."""
    for name, text in (("controller", "run the controller process on a CAN bus (same as python -m firmware_py)"),
                       ("plant", "run the simulated car on a CAN bus (same as python -m sim_plant)"),
                       ("bus", "run the fallback CAN bus broker (for machines without vcan)"),
                       ("bench", "benchmarks with same-run baselines (mrsteer bench --help)"),
                       ("faults", "fault injection: the fault matrix and the fault bridge (mrsteer faults --help)")):
        p = sub.add_parser(name, help=text, add_help=False, description=text)
        p.add_argument("args", nargs=argparse.REMAINDER)
        p.set_defaults(handler=_delegate(name))


def _delegate(name: str) -> Callable[[argparse.Namespace], int]:
    def handler(args: argparse.Namespace) -> int:
        if name == "controller":
            from firmware_py.controller.main import main as target
        elif name == "plant":
            from sim_plant.nodes.plant import main as target
        elif name == "bench":
            from mrsteer_bench.run import main as target
        elif name == "faults":
            from sim_plant.harness.faults import main as target
        else:
            from firmware_py.platform.fallback_broker import main as target
        return target(args.args, prog=f"mrsteer {name}")

    return handler


def _config(args: argparse.Namespace) -> mr.ControllerConfig:
    """The calibration the options give; also settles ``args.ts`` (see --ts)."""
    cfg = calibration_from_args(args)
    cfg = replace(cfg, method=args.method or cfg.method)
    if args.ts is None:
        args.ts = 0.0 if hand_gains(args) else cfg.ts
    if args.ts > 0.0:
        cfg = replace(cfg, ts=args.ts)
    mr.configure(cfg)  # reject an impossible calibration before simulating
    return cfg


def _params(args: argparse.Namespace) -> VehicleParams:
    return VehicleParams(v=args.v, mu=args.mu, mass=args.mass)


def _echo(args: argparse.Namespace) -> dict[str, object]:
    cfg = _config(args)
    return {"v": args.v, "mu": args.mu, "mass": args.mass, "controller": args.controller,
            **{k: v for k, v in describe_gains(cfg).items() if k != "q_form"}, "ts": args.ts, "method": cfg.method,
            "delay_steps": args.delay_steps if args.ts > 0 else 0,
            "model_delay_steps": cfg.model_delay_steps if args.ts > 0 else 0, "duration": args.duration}


#: The law's gains in a result (``describe_gains``): printed as text on one ``gains`` line.
_GAIN_KEYS = ("k", "tau", "tau_n", "schedule", "model_actuator_tau_s", "model_filter_hz")


def _emit(args: argparse.Namespace, result: dict[str, object], title: str) -> None:
    if args.json:
        print(json.dumps(tidy_figures(result), indent=2))
        return
    print(title)
    for key, value in result.items():
        if key in _GAIN_KEYS:
            if key == _GAIN_KEYS[0] or key == "schedule":
                print(f"  {'gains':<28}{mr.format_gains(result)}")
            continue
        text = f"{value:.6g}" if isinstance(value, float) else "n/a" if value is None else value
        print(f"  {key:<28}{text}")


def _models_out(args: argparse.Namespace, trace: Any) -> tuple[Any, dict[str, object]]:
    """The loop's models, and what the output adds with them: the applied angle beside the
    command, and the models (nothing for the ideal loop, whose output stays as it was)."""
    models = loop_models(args)
    return models, ({} if models.is_ideal or trace is None else {**trace.applied_summary(), **models.describe()})


def _cmd_disturbance(args: argparse.Namespace) -> int:
    exp = experiments.disturbance(_params(args), args.mz, args.controller, _config(args), args.duration)
    models, _ = _models_out(args, None)
    trace = experiments.run(exp, args.ts, args.delay_steps, models, args.plant)
    _emit(args, {**trace.summary(), **_models_out(args, trace)[1], **trace.car_summary(), "m_z": args.mz,
                 **_echo(args)}, f"yaw moment step of {args.mz:g} Nm")
    return 0


def _cmd_steer(args: argparse.Namespace) -> int:
    exp = experiments.steer(_params(args), args.controller, _config(args), args.duration)
    models, _ = _models_out(args, None)
    trace = experiments.run(exp, args.ts, args.delay_steps, models, args.plant)
    s = trace.summary()
    result = {
        "peak_yaw_rate_norm": s["peak_yaw_rate_rad_s"],
        "final_yaw_rate_norm": s["final_yaw_rate_rad_s"],
        "steer_step_deg": math.degrees(exp.delta_driver),
        "peak_aux_steer_deg": s["peak_aux_steer_deg"],
        "final_aux_steer_deg": s["final_aux_steer_deg"],
        "saturated": s["saturated"],
        "stable": s["stable"],
        **_models_out(args, trace)[1],
        **trace.car_summary(),
        **_echo(args),
    }
    _emit(args, result, "driver steering step (yaw rate normalised to the uncontrolled dry-road steady state)")
    return 0


def _cmd_threshold(args: argparse.Namespace) -> int:
    thr = experiments.saturation_threshold(_params(args), args.controller, _config(args), args.ts,
                                           args.delay_steps, args.duration)
    _emit(args, {"threshold_nm": thr, "aux_limit_deg": math.degrees(mr.ControllerConfig().aux_limit), **_echo(args)},
          "smallest saturating yaw moment step")
    return 0


def _cmd_paper(args: argparse.Namespace) -> int:
    from sim_plant.offline import paper

    # The figures go to --out, by default out/paper with the table; with --json, only to an --out
    # given, so that the numbers alone need no plotting library.
    out = args.out if args.out is not None else None if args.json else PAPER_OUT
    if out is not None:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise UsageError("matplotlib is needed for the figures: pip install 'mrsteer[plot]'") from None
        check_output_dir("--out", out)
    run = paper.reproduce(progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    written: list[Path] = []
    if out is not None:
        from sim_plant.offline import figures

        written = figures.write_all(run, out)
    if args.json:
        print(json.dumps({**run.numbers(), "files": [str(p) for p in written]}, indent=2))
    else:
        print(paper.format_table(run))
        print(f"\nwrote {len(written)} files to {out}/")
    return 0


def _cmd_vectors(args: argparse.Namespace) -> int:
    from sim_plant.offline import vectors

    check_output_dir("--out", args.out)
    written = vectors.write_all(args.out, progress=say)
    print(f"wrote {len(vectors.CONFIGS)} configurations and {len(written)} vector files "
          f"({sum(w.rows for w in written)} steps), and the SecOC vectors, to {args.out}/")
    return 0


DELEGATED = ("controller", "plant", "bus", "bench", "faults")


def main(argv: Sequence[str] | None = None) -> int:
    entry = argv is None  # the process's own entry point (not a call from Python)
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in DELEGATED:
        # These commands own their whole argument list (including --help).
        return _delegate(argv[0])(argparse.Namespace(args=argv[1:]))
    parser = build_parser()
    args = parser.parse_args(argv)
    prog = getattr(args, "prog", parser.prog)
    try:
        return args.handler(args)
    except BrokenPipeError:  # e.g. piped into `head`: not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        # Whatever the command started is stopped by now (each runner's own clean-up); what it
        # leaves is its own help's "Ctrl-C" (docs/can-runtime.md, "Errors and Ctrl-C").
        return fail(prog, getattr(args, "interrupted", "interrupted; nothing written"), EXIT_INTERRUPTED)
    except ERRORS as exc:
        return fail(prog, describe(exc))
    finally:
        if entry:  # the command has ended: a Ctrl-C now would only break the interpreter's exit
            signal.signal(signal.SIGINT, signal.SIG_IGN)


if __name__ == "__main__":
    sys.exit(main())
