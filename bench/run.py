"""``mrsteer bench [--quick] [--json] [--only NAME]``: every benchmark, a table and JSON."""

from __future__ import annotations

import json
import platform
import sys
import time
from typing import Any, Callable, Sequence

from firmware_py.controller import node as rt
from firmware_py.platform.cli import Parser

NAMES = ("step", "receive", "sweep", "campaign", "loop", "soak")


def build_parser(prog: str = "mrsteer bench") -> Parser:
    p = Parser(prog=prog, description="Benchmarks with same-run baselines: firmware step() against numpy, the "
               "receive path against cantools alone, the offline sweep against scipy.signal point by point, "
               "a validation campaign against the scalar firmware loop, and the controller loop's timing, latency and memory on the fallback bus with the plant running. "
               "Figures, not pass/fail: timing on shared machines is noisy.")
    p.add_argument("--quick", action="store_true",
                   help="short runs (loop 5 s, soak 30 s, 1,000 sweep points) instead of the full ones "
                   "(loop 30 s at each rate, soak 10 min, 10,000 points); campaign 4,096 scenarios instead of 100,000")
    p.add_argument("--only", choices=NAMES, action="append", metavar="NAME",
                   help=f"run only these ({', '.join(NAMES)}); repeatable")
    p.add_argument("--json", action="store_true", help="print the results as one JSON object")
    return p


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
    for run in res.get("loop", []):
        lines.append(_row(f"loop {run['rate_hz']:g} Hz lateness p50/p99/max",
                          f"{run['lateness_p50_us']:.0f}/{run['lateness_p99_us']:.0f}/{run['lateness_max_us']:.0f} us",
                          f"{run['baseline_lateness_p50_us']:.0f}/{run['baseline_lateness_p99_us']:.0f}/"
                          f"{run['baseline_lateness_max_us']:.0f} us",
                          f"{run['lateness_p99_us'] / max(run['baseline_lateness_p99_us'], 1.0):.1f}",
                          "p50 <= 100 us, p99 <= 500 us (baseline: empty loop)"))
        lines.append(_row(f"loop {run['rate_hz']:g} Hz missed cycles", f"{run['missed_percent']:.3f} %", "", "",
                          "<= 0.1 %"))
        lines.append(_row(f"loop {run['rate_hz']:g} Hz latency p50/p99",
                          f"{run['latency_p50_us']:.0f}/{run['latency_p99_us']:.0f} us", "", "",
                          "p50 <= 300 us, p99 <= 1 ms"))
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
    if "loop" in res or "soak" in res:
        run = (res.get("loop") or [res.get("soak")])[0]
        rtp = run["rt_priority"] or f"denied ({run['rt_priority_denied']})"
        lines.append(f"platform: SCHED_FIFO {rtp}; CPU affinity {run['cpu_affinity']}; "
                     f"GC off in loop: {run['gc_disabled_in_loop']}; absolute-deadline sleeps")
    return "\n".join(lines)


def run(names: Sequence[str], quick: bool, say: Callable[[str], None]) -> dict[str, Any]:
    from mrsteer_bench import loop, micro, offline

    out: dict[str, Any] = {"quick": quick, "python": platform.python_version(), "machine": platform.machine()}
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
        secs = 5.0 if quick else 30.0
        out["loop"] = []
        for rate in sorted({1000.0, rt.DEFAULT_RATE_HZ}, reverse=True):
            say(f"loop timing at {rate:g} Hz for {secs:g} s ...")
            out["loop"].append(loop.loop_timing(rate, secs))
    if "soak" in names:
        secs = 30.0 if quick else 600.0
        say(f"memory soak at {rt.DEFAULT_RATE_HZ:g} Hz for {secs:g} s ...")
        out["soak"] = loop.loop_timing(rt.DEFAULT_RATE_HZ, secs)
    out["wall_s"] = time.monotonic() - t0
    return out


def main(argv: Sequence[str] | None = None, prog: str = "mrsteer bench") -> int:
    args = build_parser(prog).parse_args(argv)
    names = args.only or NAMES

    def say(msg: str) -> None:
        print(f"{prog}: {msg}", file=sys.stderr, flush=True)

    try:
        res = run(names, args.quick, say)
    except (RuntimeError, OSError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(res, indent=2) if args.json else format_table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
