"""``mrsteer bench [--quick] [--json] [--only NAME] [--loop-seconds S] [--loop-rate-hz HZ]
[--load-procs N] [--loop-plain-machine]``: every benchmark, a table and JSON."""

from __future__ import annotations

import argparse
import json
import platform
import signal
import sys
import time
from types import FrameType
from typing import TYPE_CHECKING, Any, Callable, Sequence

from firmware_py.controller import node as rt
from firmware_py.controller.options import RATES_HELP, RateError, calibration_for_rate
from firmware_py.platform.cli import add_quick_arg, describe, EXIT_INTERRUPTED, fail, Parser
from sim_plant.campaign.c_cycle import NotBuilt

if TYPE_CHECKING:
    from mrsteer_bench.loop_compare import CompareSettings

NAMES = ("step", "receive", "sweep", "campaign", "loop", "soak")


def build_parser(prog: str = "mrsteer bench") -> Parser:
    p = Parser(prog=prog, description="Benchmarks with same-run baselines: firmware step() against numpy, the "
               "receive path against cantools alone, the offline sweep against scipy.signal point by point, "
               "a validation campaign against the scalar firmware loop, the loop timing and latency of the Python and the C controller side by side on the fallback bus with the "
               "plant running, quiet and under a CPU load the bench starts and stops, and the controller's memory. "
               "Figures, not pass/fail: timing on shared machines is noisy.")
    add_quick_arg(p, "short runs (loop 5 s, soak 10 s, 1,000 sweep points) instead of the full ones "
                   "(loop 30 s per controller and condition, soak 10 min, 10,000 points); campaign 512 "
                   "scenarios instead of 100,000")
    p.add_argument("--only", choices=NAMES, action="append", metavar="NAME",
                   help=f"run only these ({', '.join(NAMES)}); repeatable")
    p.add_argument("--json", action="store_true", help="print the results as one JSON object")
    g = p.add_argument_group("loop", "the Python and the C controller side by side (the C node is built first), "
                             "quiet and under a CPU load the bench starts and stops itself")
    g.add_argument("--loop-seconds", type=float, metavar="S",
                   help="each controller's run in each condition (default 30, 5 with --quick)")
    g.add_argument("--loop-rate-hz", type=float, default=rt.DEFAULT_RATE_HZ, metavar="HZ",
                   help=f"the control rate of the loop runs, one with a calibration of its own: {RATES_HELP} "
                   f"(default {rt.DEFAULT_RATE_HZ:g})")
    g.add_argument("--load-procs", type=int, metavar="N",
                   help="busy-loop processes of the loaded condition, at the bench's niceness (default: one per "
                   "CPU; 0: quiet only)")
    g.add_argument("--loop-plain-machine", action="store_true",
                   help="leave the plant and the broker at normal priority, unpinned, and the CPUs' idle states "
                   "alone: their scheduling jitter and wake-ups then enter the figures (default: plant and broker "
                   "at SCHED_FIFO 40 on the CPUs the controller is not on, /dev/cpu_dma_latency held at 0 us)")
    return p


def _check(p: Parser, args: argparse.Namespace) -> None:
    if args.loop_seconds is not None and not 0 < args.loop_seconds <= 3600:
        p.error(f"--loop-seconds must be in (0, 3600], got {args.loop_seconds:g}")
    if not 1 <= args.loop_rate_hz <= 10000:
        p.error(f"--loop-rate-hz must be in [1, 10000], got {args.loop_rate_hz:g}")
    try:  # the controller runs at this rate with the calibration made for it
        calibration_for_rate(args.loop_rate_hz, flag="--loop-rate-hz", file_flag=None)
    except RateError as exc:
        p.error(str(exc))
    if args.load_procs is not None and not 0 <= args.load_procs <= 64:
        p.error(f"--load-procs must be in [0, 64], got {args.load_procs}")


def _row(name: str, value: str, baseline: str, ratio: str, target: str) -> str:
    return f"{name:<34}{value:>22}{baseline:>22}{ratio:>10}   {target}"


def format_table(res: dict[str, Any]) -> str:
    lines = [_row("benchmark", "ours", "baseline", "ratio", "target"), "-" * 120]
    if "step" in res:
        s = res["step"]
        lines.append(_row("firmware step()", f"{s['ours']['median_us']:.2f} us", f"{s['baseline']['median_us']:.2f} us",
                          f"{s['speedup']:.1f}x", "<= 2 us, >= 5x vs numpy"))
    if "receive" in res:
        s = res["receive"]
        lines.append(_row("receive path per frame", f"{s['ours']['median_us']:.2f} us",
                          f"{s['baseline']['median_us']:.2f} us", f"{s['ratio_to_baseline']:.2f}",
                          "<= 10 us (baseline: cantools decode alone)"))
    if "sweep" in res:
        s = res["sweep"]
        lines.append(_row(f"sweep {s['points']} pts x {s['duration_s']:g} s", f"{s['ours_s']:.2f} s",
                          f"{s['baseline_s']:.1f} s", f"{s['speedup']:.0f}x", "10,000 pts in <= 10 s"))
    if "soak" in res:
        s = res["soak"]
        lines.append(_row(f"controller RSS, growth in {s['seconds']:g} s", f"{s['rss_kb'] / 1024:.1f} MiB",
                          "", f"+{s['rss_growth_kb']} KiB", "growth <= 1 MB over 10 min"))
    if "campaign" in res:
        s = res["campaign"]
        lines.append(_row(f"campaign {s['samples']} x {s['duration_s']:g} s, {s['workers']} workers",
                          f"{s['ours_s']:.1f} s", f"{s['baseline_s']:.0f} s", f"{s['speedup']:.0f}x",
                          "100,000 x 5 s in <= 120 s, >= 100x the scalar loop"))
        lines.append(_row("  the same in CPU seconds", f"{s['ours_cpu_s']:.1f} s", f"{s['baseline_cpu_s']:.0f} s",
                          f"{s['speedup_cpu']:.0f}x", "load average " + "/".join(f"{x:.1f}" for x in s["loadavg_1min"])))
        sc = s["scaling"]
        lines.append(_row(f"campaign {sc['samples']}: 2 workers vs 1", f"{sc['two_workers_s']:.1f} s",
                          f"{sc['one_worker_s']:.1f} s", f"{sc['speedup']:.2f}x", ">= 1.7x (LocalCluster)"))
        lines.append(_row("  cores obtained (CPU s / wall s)", f"{sc['two_workers_cores']:.2f}",
                          f"{sc['one_worker_cores']:.2f}", f"{sc['one_worker_cpu_s'] / sc['two_workers_cpu_s']:.2f}",
                          f"CPU s 1 vs 2 workers: {sc['one_worker_cpu_s']:.0f} / {sc['two_workers_cpu_s']:.0f}"))
    if "soak" in res:
        run = res["soak"]
        rtp = run["rt_priority"] or f"denied ({run['rt_priority_denied']})"
        lines.append(f"platform: SCHED_FIFO {rtp}; CPU affinity {run['cpu_affinity']}; "
                     f"GC off in loop: {run['gc_disabled_in_loop']}; absolute-deadline sleeps")
    if len(lines) == 2:
        lines = []  # no row of this table was run
    if "loop" in res:
        from mrsteer_bench import loop_compare

        lines += ["", loop_compare.format_table(res["loop"])] if lines else [loop_compare.format_table(res["loop"])]
    return "\n".join(lines)


def run(names: Sequence[str], quick: bool, say: Callable[[str], None],
        loop_settings: CompareSettings | None = None) -> dict[str, Any]:
    """Each benchmark of ``names``; ``loop_settings``: a ``loop_compare.CompareSettings`` (default:
    the controller's rate, 30 s or 5 s with ``quick``, one busy loop per CPU)."""
    from mrsteer_bench import loop, loop_compare, micro, offline
    from mrsteer_bench.cpu_load import default_procs

    out: dict[str, Any] = {"quick": quick, "python": platform.python_version(), "machine": platform.machine()}
    if "campaign" in names:
        from sim_plant.campaign import c_cycle

        c_cycle.require()  # the engine steps the C cycle: without it, one line before any run
    t0 = time.monotonic()
    if "step" in names:
        say("firmware step() ...")
        out["step"] = micro.firmware_step(quick)
    if "receive" in names:
        say("receive path ...")
        out["receive"] = micro.receive_path(quick)
    if "sweep" in names:
        say("offline sweep ...")
        out["sweep"] = offline.offline_sweep(quick)
    if "campaign" in names:
        say("validation campaign (batch engine on a LocalCluster) ...")
        from mrsteer_bench import campaign

        out["campaign"] = campaign.campaign_bench(quick)
    if "loop" in names:
        settings = loop_settings or loop_compare.CompareSettings(rt.DEFAULT_RATE_HZ, 5.0 if quick else 30.0,
                                                                 default_procs())
        out["loop"] = loop_compare.compare(settings, say)
    if "soak" in names:
        secs = 10.0 if quick else 600.0
        say(f"memory soak at {rt.DEFAULT_RATE_HZ:g} Hz for {secs:g} s ...")
        out["soak"] = loop.loop_timing(rt.DEFAULT_RATE_HZ, secs)
    out["wall_s"] = time.monotonic() - t0
    return out


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt  # SIGTERM unwinds like Ctrl-C: every node and the CPU load are stopped


def loop_settings_of(args: argparse.Namespace) -> CompareSettings:
    """The loop comparison the command line asks for."""
    from mrsteer_bench.cpu_load import default_procs
    from mrsteer_bench.loop_compare import CompareSettings

    return CompareSettings(args.loop_rate_hz, args.loop_seconds or (5.0 if args.quick else 30.0),
                           default_procs() if args.load_procs is None else args.load_procs,
                           harness_rt=not args.loop_plain_machine, pm_qos=not args.loop_plain_machine)


def main(argv: Sequence[str] | None = None, prog: str = "mrsteer bench") -> int:
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    _check(parser, args)
    names = args.only or NAMES
    loop_settings = loop_settings_of(args)

    def say(msg: str) -> None:
        print(f"{prog}: {msg}", file=sys.stderr, flush=True)

    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        res = run(names, args.quick, say, loop_settings)
    except (RuntimeError, OSError, ValueError, NotBuilt) as exc:
        return fail(prog, describe(exc))
    except KeyboardInterrupt:
        return fail(prog, "interrupted; every process it started is stopped, no table", EXIT_INTERRUPTED)
    finally:
        signal.signal(signal.SIGTERM, previous)
    print(json.dumps(res, indent=2) if args.json else format_table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
