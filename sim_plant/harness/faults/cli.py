"""``mrsteer faults``: the fault matrix's command line (``run``, or the ``bridge`` on its own)
and its table."""

from __future__ import annotations

import json
import os
import sys
from dataclasses import asdict, replace
from pathlib import Path

from sim_plant.car.options import add_car_args
from sim_plant.figures import tidy_figures
from sim_plant.harness.faults.verdicts import RowResult
from sim_plant.harness.faults.rows import QUICK_ROWS, ROWS, secured_rows
from sim_plant.harness.faults.run import holds_files, run_matrix
from firmware_py.controller.options import RATES_HELP
from sim_plant.harness.faults.settings import RATE_HZ, Setup
from sim_plant.harness.launch import LaunchError, add_controller_impl_args, program_of
from sim_plant.harness.processes import RunError


def format_table(results: list[RowResult]) -> str:
    lines = [f"{'fault':<38}{'expected':<42}{'result':<7}{'max |applied|':>14}{'max step':>10}{'detect':>8}  observed",
             "-" * 160]
    for r in results:
        det = "-" if r.detection_cycles is None else f"{r.detection_cycles} cyc"
        result = "PASS" if r.passed else "KNOWN" if r.known else "FAIL"
        lines.append(f"{r.name:<38}{r.expected:<42}{result:<7}{r.worst_applied_deg:>12.3f} deg"
                     f"{r.worst_step_deg:>8.4f}°{det:>8}  {r.observed}")
        for f in r.failures:
            lines.append(f"{'':<38}!! {f}")
        if r.known:
            lines.append(f"{'':<38}   {r.known}")
    n_pass = sum(r.passed for r in results)
    n_known = sum(bool(r.known) for r in results)
    lines.append(f"{n_pass}/{len(results)} rows pass" + (f", {n_known} fail as a known defect" if n_known else ""))
    return "\n".join(lines)


def main(argv: list[str] | None = None, prog: str = "mrsteer faults") -> int:
    import argparse

    from firmware_py.platform import bus_open
    from firmware_py.platform.cli import EXIT_INTERRUPTED, Parser, add_quick_arg, fail

    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["bridge"]:  # the bridge owns its whole argument list, --help included
        from sim_plant.nodes.fault_bridge import main as bridge_main

        return bridge_main(argv[1:], prog=f"{prog} bridge")
    p = Parser(prog=prog, description="Fault injection: the fault matrix, or the bridge on its own.")
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    r = sub.add_parser("run", help="run the fault matrix and print the table",
                       description="Run every row of the fault matrix (each a few seconds of realtime plant and "
                       "controller joined by the fault bridge) and judge it from the logged traffic.  By default "
                       "on two private fallback buses; on SocketCAN: --interface socketcan --channels vcan0,vcan1 "
                       "(tools/vcan.sh up 2).")
    r.add_argument("--only", action="append", metavar="TEXT", help="only rows whose name contains TEXT; repeatable")
    r.add_argument("--keep", type=Path, metavar="DIR", help="keep every row's logs, traces and statistics here")
    r.add_argument("--json", action="store_true", help="print the results as JSON")
    add_quick_arg(r, f"only the rows {', '.join(QUICK_ROWS)} (a smoke run; --only overrides it)")
    r.add_argument("--secoc", action="store_true",
                   help="run every row with the commands and sensor frames authenticated (a random key per row); "
                   "the rows that show what E2E alone lets through are left out")
    r.add_argument("--interface", default="mrsteer", help="python-can interface of both buses (default mrsteer, "
                   "the fallback bus)")
    r.add_argument("--channels", metavar="VEHICLE,CONTROLLER",
                   help="the two buses the bridge joins (default: two private fallback buses)")
    r.add_argument("--rate-hz", type=float, default=RATE_HZ,
                   help=f"control and plant rate, one with a calibration of its own: {RATES_HELP} (default "
                   f"{RATE_HZ:g})")
    r.add_argument("--time-scale", type=float, default=1.0, metavar="F",
                   help="stretch scenario, fault window and kill/restart times by F, for slow machines (default 1)")
    r.add_argument("--slow-motion", type=float, default=1.0, metavar="F",
                   help="run every node F times slower than real time, for machines too slow for the loop "
                   "(QEMU without KVM): each period lasts F times its step in wall time; the verdicts are "
                   "judged in the car's time, unchanged (default 1)")
    r.add_argument("--startup-s", type=float, default=0.0, metavar="S",
                   help="extra scenario seconds in the restart rows for the new process to start (default 0)")
    add_car_args(r, default="ideal, the paper's linear car (the rows' scenario names none)", with_seed=False)
    add_controller_impl_args(r)
    b = sub.add_parser("bridge", help="the fault-injecting bridge on its own (see --help)", add_help=False)
    b.add_argument("args", nargs=argparse.REMAINDER)
    args = p.parse_args(argv)
    every = secured_rows() if args.secoc else ROWS
    rows = tuple(row for row in every if not args.only or any(o.lower() in row.name.lower() for o in args.only))
    if args.quick and not args.only:
        rows = tuple(row for row in rows if row.name in QUICK_ROWS)
    if not rows:
        r.error(f"no row matches {args.only or 'the quick rows'}; rows: " + "; ".join(r.name for r in every))
    try:
        channels = tuple(args.channels.split(",")) if args.channels else None
        setup = Setup(args.interface, channels, args.rate_hz, args.time_scale, args.startup_s,  # type: ignore[arg-type]
                      args.plant, args.actuator, args.sensors, slow_motion=args.slow_motion)
        for channel in channels or (None,):
            bus_open.check(args.interface, channel, between_processes=True)
    except (ValueError, bus_open.BusOpenError) as exc:
        r.error(str(exc))
    try:
        setup = replace(setup, controller_program=program_of(args))
    except LaunchError as exc:
        return fail(r.prog, str(exc))
    if args.keep is not None and args.keep.exists() and not args.keep.is_dir():
        r.error(f"--keep {args.keep} exists and is not a directory")
    if holds_files(args.keep):
        r.error(f"--keep {args.keep} is not empty: an earlier run's files would be judged as this run's")
    if args.keep is not None:
        try:
            args.keep.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            r.error(f"--keep {args.keep}: cannot create it: {exc.strerror}")
        if not os.access(args.keep, os.W_OK):
            r.error(f"--keep {args.keep} is not writable")
    try:
        results = run_matrix(rows, lambda m: print(f"{prog}: {m}", file=sys.stderr, flush=True), args.keep, setup)
    except RunError as exc:
        return fail(r.prog, str(exc))
    except KeyboardInterrupt:  # every process of the row was stopped on the way out (run_row)
        kept = f"; the rows run before it are in {args.keep}/" if args.keep is not None else ""
        return fail(r.prog, f"interrupted: every process it started is stopped, no table{kept}", EXIT_INTERRUPTED)
    if args.json:
        print(json.dumps(tidy_figures([asdict(r) for r in results]), indent=2))
    else:
        print(format_table(results))
    return 0 if all(r.ok for r in results) else 1
