"""``mrsteer controller`` / ``python -m firmware_py``: the command line of the controller process."""

from __future__ import annotations

import argparse
import json
import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Sequence

from firmware_py import model_regulator as mr
from firmware_py.controller.node import DEFAULT_RATE_HZ, TRIGGERS, ControllerNode, RuntimeConfig
from firmware_py.controller.options import RATES_HELP, add_calibration_args, calibration_at_rate
from firmware_py.controller.timing import DEFAULT_SYNC_OFFSET
from firmware_py.platform.bus_open import BusOpenError, open_bus
from firmware_py.platform.cli import (Parser, add_secoc_args, fail, add_slow_motion_arg, check_output_file,
                                      check_slow_motion, secoc_key, slow_motion_suffix)
from firmware_py.platform.lifecycle import run_node
from firmware_py.platform.realtime import apply_platform


def build_parser(prog: str = "mrsteer controller") -> argparse.ArgumentParser:
    d = mr.ControllerConfig()
    p = Parser(prog=prog, description="Run the model-regulator controller on a CAN bus: read driver angle, "
               "yaw rate and speed, send the auxiliary steering command.")
    p.add_argument("--interface", help="python-can interface (default: python-can config, else SocketCAN vcan0 "
                   "if present, else the mrsteer fallback bus)")
    p.add_argument("--channel", help="channel for the interface (default vcan0 / mrsteer0)")
    p.add_argument("--rate-hz", type=float, default=None,
                   help=f"control rate in Hz (default: the calibration's, {DEFAULT_RATE_HZ:g} for the shipped one); without "
                   "--calibration or --k a rate with a calibration of its own: " + RATES_HELP)
    p.add_argument("--trigger", choices=TRIGGERS, default="clock",
                   help="clock: fixed rate on the monotonic clock (default); sensors: one cycle per yaw-rate frame")
    p.add_argument("--sync-offset-us", type=float, default=DEFAULT_SYNC_OFFSET * 1e6, metavar="US",
                   help="clock trigger: start each cycle this long after the yaw-rate frame arrives, by "
                   f"phase-locking the loop to the frames (default {DEFAULT_SYNC_OFFSET * 1e6:g})")
    p.add_argument("--no-sync", action="store_true", help="clock trigger: free-running grid, no phase lock")
    p.add_argument("--timeout-cycles", type=int, default=10,
                   help="an input missing for more than this many of its own cycle times is a fault (default 10)")
    p.add_argument("--controller", choices=(mr.Q_LIMITED, mr.Q_STANDARD), default=None,
                   help=f"Q filter: limited (eq. 22) or standard (eq. 17) (default: the calibration's, {d.q_form})")
    add_calibration_args(p)
    p.add_argument("--method", choices=(mr.METHOD_TUSTIN, mr.METHOD_ZOH), default=None,
                   help=f"discretisation of Q (default: the calibration's, {d.method})")
    p.add_argument("--rate-limit", type=float, default=None, metavar="RAD_S",
                   help="command rate limit in rad/s (default: the calibration's, 0: off)")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds (wall time)")
    add_slow_motion_arg(p)
    p.add_argument("--stats-out", type=Path, default=None, metavar="FILE",
                   help="write loop statistics as JSON here on exit")
    add_secoc_args(p)
    p.add_argument("--rt-priority", type=int, default=0, metavar="P",
                   help="run under SCHED_FIFO at priority P (1..99) where permitted; 0 (default) leaves the "
                   "scheduler alone; what was applied is reported in --stats-out")
    p.add_argument("--cpu", type=int, default=None, metavar="N",
                   help="pin the process to CPU N where permitted (reported in --stats-out)")
    return p


def _check_loop_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """The loop's options in range, else the parser's one-line error."""
    if args.rate_hz is not None and not (math.isfinite(args.rate_hz) and 1.0 <= args.rate_hz <= 10000.0):
        parser.error(f"--rate-hz must be in [1, 10000], got {args.rate_hz}")
    if args.timeout_cycles < 1:
        parser.error("--timeout-cycles must be at least 1")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        parser.error("--duration must be positive")
    check_slow_motion(parser, args.slow_motion)
    if not 0 <= args.rt_priority <= 99:
        parser.error(f"--rt-priority must be in 0..99, got {args.rt_priority}")
    if args.cpu is not None and not 0 <= args.cpu < (os.cpu_count() or 1):
        parser.error(f"--cpu must be in 0..{(os.cpu_count() or 1) - 1}, got {args.cpu}")


def _law_config(args: argparse.Namespace) -> mr.ControllerConfig:
    """The law's calibration at the loop's rate with the options' overrides (``args.rate_hz`` set
    from it when not given); ValueError (RateError among them) when there is none or it is invalid."""
    ctrl = calibration_at_rate(args, args.rate_hz)  # RateError: no calibration for this rate
    if args.rate_hz is None:
        args.rate_hz = 1.0 / ctrl.ts
    ctrl = replace(ctrl, q_form=args.controller or ctrl.q_form, method=args.method or ctrl.method,
                   rate_limit=args.rate_limit if args.rate_limit is not None else ctrl.rate_limit,
                   ts=1.0 / args.rate_hz)
    mr.configure(ctrl)
    return ctrl


def main(argv: Sequence[str] | None = None, prog: str = "mrsteer controller") -> int:
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    _check_loop_options(parser, args)
    try:
        ctrl = _law_config(args)
    except ValueError as exc:
        parser.error(str(exc))
    if not (math.isfinite(args.sync_offset_us) and 0.0 <= args.sync_offset_us * 1e-6 < 1.0 / args.rate_hz):
        parser.error(f"--sync-offset-us must be in [0, one period), got {args.sync_offset_us}")
    check_output_file(parser, "--stats-out", args.stats_out)
    cfg = RuntimeConfig(rate_hz=args.rate_hz, timeout_cycles=args.timeout_cycles, trigger=args.trigger,
                        sync_offset=None if args.no_sync else args.sync_offset_us * 1e-6,
                        duration=args.duration, slow_motion=args.slow_motion,
                        secoc_key=secoc_key(args, parser), controller=ctrl)
    try:
        bus = open_bus(args.interface, args.channel)
    except BusOpenError as exc:
        return fail(prog, str(exc))
    node = ControllerNode(bus, cfg)
    node.stats.platform.update(apply_platform(args.rt_priority, args.cpu))
    slow = slow_motion_suffix(args.slow_motion)
    auth = ", commands and sensor frames authenticated (SecOC)" if cfg.secoc_key is not None else ""
    return run_node(prog, bus, node.run, node.stop,
                    [(args.stats_out, lambda: json.dumps(node.stats.summary(), indent=2))],
                    ready=f"running at {args.rate_hz:g} Hz{slow} ({args.trigger} trigger{auth}) on {bus.channel_info}")
