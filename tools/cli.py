"""``mrsteer`` command line: a thin layer over firmware_py and sim_plant.

Every error in the arguments is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Callable, NoReturn, Sequence

from firmware_py import model_regulator as mr
from sim_plant import experiments
from sim_plant.closed_loop import CONTROLLERS
from sim_plant.vehicle import MAX_MU, PAPER_MASS, VehicleParams

EXIT_USAGE = 2
SPEED_RANGE = (3.0, 70.0)  # m/s: where the firmware is active and the model is used
MASS_RANGE = (300.0, 10000.0)
MAX_DURATION = 60.0


class UsageError(Exception):
    """Bad input from the user: reported as one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def _number(kind: str, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            allow_zero: bool = False) -> Callable[[str], float]:
    """argparse type: a finite float within [lo, hi] (or (lo, hi] with lo_open)."""

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{kind} must be a number, got {text!r}") from None
        if not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"{kind} must be finite, got {text!r}")
        if allow_zero and x == 0.0:
            return x
        below = (x <= lo) if lo_open else (x < lo) if lo is not None else False
        if below or (hi is not None and x > hi):
            left = "(" if lo_open else "["
            raise argparse.ArgumentTypeError(f"{kind} must be in {left}{lo:g}, {hi:g}], got {text}")
        return x

    return parse


def _count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
    if not 0 <= n <= 100:
        raise argparse.ArgumentTypeError(f"must be in [0, 100], got {n}")
    return n


def _add_operating_point(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument("--v", type=_number("speed v", *SPEED_RANGE), required=required, default=None if required else 20.0,
                   metavar="MPS", help=f"speed in m/s, {SPEED_RANGE[0]:g}..{SPEED_RANGE[1]:g}")
    p.add_argument("--mu", type=_number("friction mu", 0.0, MAX_MU, lo_open=True), required=required,
                   default=None if required else 1.0, metavar="MU", help=f"road friction, (0, {MAX_MU:g}]")
    p.add_argument("--mass", type=_number("mass", *MASS_RANGE), default=PAPER_MASS, metavar="KG",
                   help=f"vehicle mass in kg (default {PAPER_MASS:g}, the paper's)")


def _add_controller(p: argparse.ArgumentParser, choices: Sequence[str] = CONTROLLERS) -> None:
    d = mr.ControllerConfig()
    p.add_argument("--controller", choices=choices, default=mr.Q_LIMITED,
                   help="none, standard (eq. 17) or limited (eq. 22) model regulator (default limited)")
    p.add_argument("--k", type=_number("K", 0.0, 1e6, lo_open=True), default=d.k, help=f"eq. (22) gain K (default {d.k:g})")
    p.add_argument("--tau", type=_number("tau", 0.0, 10.0, lo_open=True), default=d.tau,
                   help=f"eq. (22) time constant in s (default {d.tau:g})")
    p.add_argument("--tau-n", type=_number("tau_n", 0.0, 10.0, lo_open=True), default=d.tau_n,
                   help=f"eq. (18) desired-model time constant in s (default {d.tau_n:g})")
    p.add_argument("--method", choices=(mr.METHOD_TUSTIN, mr.METHOD_ZOH), default=d.method,
                   help="discretisation of the firmware when --ts > 0 (default tustin)")
    p.add_argument("--ts", type=_number("ts", 0.0, 0.1, lo_open=True, allow_zero=True), default=0.0, metavar="S",
                   help="0 (default): continuous reference; T > 0: the firmware at step T with the exact ZOH plant")
    p.add_argument("--delay-steps", type=_count, default=1, metavar="N",
                   help="samples between measurement and applied command when --ts > 0 (default 1)")
    p.add_argument("--duration", type=_number("duration", 0.0, MAX_DURATION, lo_open=True), default=3.0,
                   metavar="S", help="simulated time in s (default 3)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="mrsteer", description="Limited-integrator model-regulator active steering: "
                    "controller firmware, vehicle simulator and tools.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    sim = sub.add_parser("sim", help="offline closed-loop simulation and the paper reproduction",
                         description="Closed-loop simulations of the single-track car with the model regulator.")
    sim_sub = sim.add_subparsers(dest="experiment", required=True, parser_class=Parser)

    p = sim_sub.add_parser("disturbance", help="yaw moment step with the driver's wheel held",
                           description="A step of yaw moment M_z at t = 0, driver's wheel held straight.")
    p.add_argument("--mz", type=_number("M_z", -1e5, 1e5), required=True, metavar="NM", help="yaw moment step in Nm")
    _add_operating_point(p, required=True)
    _add_controller(p)
    p.set_defaults(handler=_cmd_disturbance)

    p = sim_sub.add_parser("steer", help="driver steering step, normalised as in Figure 8",
                           description="Driver front-wheel step sized for a steady yaw rate of 1 rad/s of the "
                           "uncontrolled car on dry road; yaw rate is reported in those units.")
    _add_operating_point(p, required=True)
    _add_controller(p)
    p.set_defaults(handler=_cmd_steer)

    p = sim_sub.add_parser("threshold", help="smallest yaw moment step that saturates the actuator",
                           description="Smallest M_z step (Nm) that drives the auxiliary command to its limit.")
    _add_operating_point(p, required=False)
    _add_controller(p, choices=(mr.Q_STANDARD, mr.Q_LIMITED))
    p.set_defaults(handler=_cmd_threshold)

    p = sim_sub.add_parser("paper", help="regenerate Figures 8-10 and compare with the paper's numbers",
                           description="Regenerate Figures 8, 9, 10 (PNG and CSV) at the six operating "
                           "conditions and print our numbers beside the paper's.")
    p.add_argument("--out", type=Path, default=Path("out/paper"), metavar="DIR",
                   help="directory for the figures (default out/paper)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    p.set_defaults(handler=_cmd_paper)
    return parser


def _config(args: argparse.Namespace) -> mr.ControllerConfig:
    cfg = replace(mr.ControllerConfig(), k=args.k, tau=args.tau, tau_n=args.tau_n, method=args.method)
    if args.ts > 0.0:
        cfg = replace(cfg, ts=args.ts)
    mr.configure(cfg)  # reject an impossible calibration before simulating
    return cfg


def _params(args: argparse.Namespace) -> VehicleParams:
    return VehicleParams(v=args.v, mu=args.mu, mass=args.mass)


def _echo(args: argparse.Namespace) -> dict[str, object]:
    return {"v": args.v, "mu": args.mu, "mass": args.mass, "controller": args.controller, "k": args.k,
            "tau": args.tau, "tau_n": args.tau_n, "ts": args.ts, "method": args.method,
            "delay_steps": args.delay_steps if args.ts > 0 else 0, "duration": args.duration}


def _emit(args: argparse.Namespace, result: dict[str, object], title: str) -> None:
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(title)
    for key, value in result.items():
        print(f"  {key:<28}{value:.6g}" if isinstance(value, float) else f"  {key:<28}{value}")


def _cmd_disturbance(args: argparse.Namespace) -> int:
    exp = experiments.disturbance(_params(args), args.mz, args.controller, _config(args), args.duration)
    trace = experiments.run(exp, args.ts, args.delay_steps)
    _emit(args, {**trace.summary(), "m_z": args.mz, **_echo(args)}, f"yaw moment step of {args.mz:g} Nm")
    return 0


def _cmd_steer(args: argparse.Namespace) -> int:
    exp = experiments.steer(_params(args), args.controller, _config(args), args.duration)
    trace = experiments.run(exp, args.ts, args.delay_steps)
    s = trace.summary()
    result = {
        "peak_yaw_rate_norm": s["peak_yaw_rate_rad_s"],
        "final_yaw_rate_norm": s["final_yaw_rate_rad_s"],
        "steer_step_deg": math.degrees(exp.delta_driver),
        "peak_aux_steer_deg": s["peak_aux_steer_deg"],
        "final_aux_steer_deg": s["final_aux_steer_deg"],
        "saturated": s["saturated"],
        "stable": s["stable"],
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
    from sim_plant import paper

    try:
        from sim_plant import figures
        import matplotlib  # noqa: F401
    except ImportError:
        raise UsageError("matplotlib is needed for the figures: pip install 'mrsteer[plot]'") from None
    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out {args.out} exists and is not a directory")
    run = paper.reproduce(progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    written = figures.write_all(run, args.out)
    if args.json:
        print(json.dumps({**run.numbers(), "files": [str(p) for p in written]}, indent=2))
    else:
        print(paper.format_table(run))
        print(f"\nwrote {len(written)} files to {args.out}/")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except (UsageError, ValueError) as exc:
        print(f"mrsteer: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
