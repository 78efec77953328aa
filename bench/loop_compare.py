"""The Python and the C controller side by side on the same bus, quiet and under a bounded load.

``compare`` runs ``loop.loop_timing`` four times at one rate on a private fallback bus: the
Python controller, then the C node (``ports/c/build/mrs_node``, built first), once on the
machine as it is ("quiet") and once with ``CpuLoad`` (``procs`` busy loops, started before the
run and stopped after it). Each condition also times an empty deadline loop in the bench
process, the machine's own scheduling noise at that moment, and records the load average, the
CPU time by kind (busy, niced, steal) and the other real-time processes (``machine_state``),
since a shared machine is never really quiet. ``format_table`` prints the
figures with the Python/C ratio and the C node's targets (lateness p99 <= 100 us, latency p99
<= 500 us, and no more missed cycles than the empty real-time loop: on a machine whose vCPU
stalls, a miss is the machine's when a loop with nothing in it misses too). The real-time empty
loop runs as long as each controller, so its misses count over the same time. Figures, not
pass/fail: nothing here asserts timing.
By default the plant and the broker run at SCHED_FIFO 40 on the CPUs the controller is not on
(``CompareSettings.harness_rt``), as a real ECU's sensors do not wait for a shared CPU, and
``/dev/cpu_dma_latency`` is held at 0 us (``CompareSettings.pm_qos``, ``cpu_latency``), as
cyclictest holds it.
"""

from __future__ import annotations

import os
import platform
from dataclasses import asdict, dataclass
from typing import Any, Callable, ContextManager

from mrsteer_bench import loop, machine_state as ms
from mrsteer_bench.cpu_latency import CpuLatency
from mrsteer_bench.cpu_load import CpuLoad
from sim_plant.harness import launch

CONDITIONS = ("quiet", "loaded")
IMPLS = ("python", "c")
# (result key, table label); the ratio is Python over C for each
METRICS = (("lateness_p50_us", "lateness p50 (us)"), ("lateness_p99_us", "lateness p99 (us)"),
           ("lateness_max_us", "lateness max (us)"), ("missed_cycles", "missed cycles"),
           ("latency_p50_us", "latency p50 (us)"), ("latency_p99_us", "latency p99 (us)"))
C_TARGETS = {"lateness_p99_us": 100.0, "latency_p99_us": 500.0}  # each: value <= target
# missed cycles: the C node's, at most the real-time empty loop's in the same condition
BUS = "fallback bus (mrsteer broker, Unix SOCK_SEQPACKET), private channel per run"
LOAD_MARGIN_S = 240.0  # the load's own time bound beyond the run: process starts on a loaded machine
BASELINE_MAX_S = 5.0

Measure = Callable[..., dict[str, Any]]
Baseline = Callable[[float, float, bool], dict[str, dict[str, Any]]]
LoadFactory = Callable[[int, float], ContextManager[Any]]


@dataclass(frozen=True)
class CompareSettings:
    rate_hz: float
    seconds: float  # each controller, each condition
    load_procs: int  # busy loops for the loaded condition; 0: no loaded condition
    pin: bool = True  # the controller on the last CPU (as loop_timing does), SCHED_FIFO 50 both ways
    # The plant and the broker at SCHED_FIFO 40 on the other CPUs (loop.HARNESS_RT_PRIORITY): the
    # sensor frames then come on time, and the latency is the controller's, not the harness's.
    harness_rt: bool = True
    # /dev/cpu_dma_latency held at 0 us through every condition (``cpu_latency``), as cyclictest
    # does: an idle CPU then polls instead of halting, so a wake-up is not a VM's reschedule.
    pm_qos: bool = True


def empty_loops(rate_hz: float, seconds: float, pin: bool) -> dict[str, dict[str, Any]]:
    """The two baselines: an empty deadline loop in the bench process (no real-time set-up, at
    most ``BASELINE_MAX_S``), and one with the controllers' SCHED_FIFO priority and CPU for as
    long as each controller ran, what the kernel gives any such loop in that time."""
    return {"no_rt": loop.bare_loop_lateness(rate_hz, min(seconds, BASELINE_MAX_S)),
            "rt": loop.rt_loop_lateness(rate_hz, seconds, pin)}


def ratio(python: float, c: float) -> float | None:
    """Python's figure over C's; None where C's is zero (or either is not a number)."""
    if c != c or python != python or c <= 0:
        return None
    return python / c


def judge_c(run: dict[str, Any], empty_rt_missed: int) -> dict[str, dict[str, Any]]:
    """Each C target: its bound, the C node's value and whether the value is within it; the
    missed cycles' bound is ``empty_rt_missed``, the real-time empty loop's in the same condition."""
    bounds = {**C_TARGETS, "missed_cycles": float(empty_rt_missed)}
    out = {}
    for key, bound in bounds.items():
        value = float(run[key])
        out[key] = {"target": bound, "value": value, "met": bool(value <= bound)}
    return out


def _condition(name: str, s: CompareSettings, programs: dict[str, tuple[str, ...] | None],
               measure: Measure, baseline: Baseline, say: Callable[[str], None]) -> dict[str, Any]:
    out: dict[str, Any] = {"loadavg_before": ms.load_average()}
    cpu0, rt0 = ms.cpu_times(), ms.realtime_processes()
    for impl in IMPLS:
        say(f"loop {name}: {impl} controller at {s.rate_hz:g} Hz for {s.seconds:g} s ...")
        out[impl] = measure(s.rate_hz, s.seconds, pin=s.pin, program=programs[impl], baseline=False,
                            harness_rt=s.harness_rt)
    say(f"loop {name}: empty deadline loops, without and with the real-time set-up ...")
    out["empty_loop"] = baseline(s.rate_hz, s.seconds, s.pin)
    out["loadavg_after"] = ms.load_average()
    out["cpu_percent"] = ms.usage_percent(cpu0, ms.cpu_times())
    # seen before and after the runs, when none of the bench's controllers is running
    rt = {p["pid"]: p for p in rt0 + ms.realtime_processes()}
    out["other_realtime_processes"] = list(rt.values())
    return out


def compare(s: CompareSettings, say: Callable[[str], None], *, measure: Measure = loop.loop_timing,
            baseline: Baseline = empty_loops, load: LoadFactory = CpuLoad,
            programs: dict[str, tuple[str, ...] | None] | None = None,
            latency: Callable[[], CpuLatency] = CpuLatency) -> dict[str, Any]:
    """Both controllers, quiet then loaded (when ``load_procs`` > 0); the load is stopped on
    leaving its condition, also on an error or Ctrl-C. ``measure``, ``baseline``, ``load``,
    ``programs`` and ``latency`` are the real ones unless given (tests give fakes)."""
    if programs is None:
        say("building the C node (make -C ports/c node) ...")
        programs = {"python": None, "c": launch.controller_program("c")}
    if not s.pm_qos:
        return _compare(s, say, measure, baseline, load, programs, {"held": False})
    with latency() as held:
        return _compare(s, say, measure, baseline, load, programs, {"held": "us" in held.state, **held.state})


def _compare(s: CompareSettings, say: Callable[[str], None], measure: Measure, baseline: Baseline,
             load: LoadFactory, programs: dict[str, tuple[str, ...] | None], pm_qos: dict[str, Any]) -> dict[str, Any]:
    conditions = CONDITIONS if s.load_procs > 0 else CONDITIONS[:1]
    runs: dict[str, Any] = {}
    for name in conditions:
        if name == "loaded":
            # bounded in time too: the whole condition, with room for slow process starts
            bound = len(IMPLS) * (s.seconds + LOAD_MARGIN_S)
            with load(s.load_procs, bound):
                runs[name] = _condition(name, s, programs, measure, baseline, say)
        else:
            runs[name] = _condition(name, s, programs, measure, baseline, say)
    return {
        "settings": asdict(s), "bus": BUS,
        "load": {"procs": s.load_procs, "kind": "busy-loop processes", "nice": os.nice(0),
                 "cpus": os.cpu_count()},
        "machine": {"platform": platform.platform(), "machine": platform.machine(), "cpus": os.cpu_count()},
        "runs": runs, "cpu_dma_latency": pm_qos,
        "ratios": {c: {k: ratio(float(r["python"][k]), float(r["c"][k])) for k, _ in METRICS} for c, r in runs.items()},
        "c_targets": {c: judge_c(r["c"], r["empty_loop"]["rt"]["missed_cycles"]) for c, r in runs.items()},
    }


def _num(value: float) -> str:
    return "nan" if value != value else f"{value:.0f}"


def _ratio(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _target(key: str) -> str:
    if key == "missed_cycles":
        return "<= empty RT"
    bound = C_TARGETS.get(key)
    return "" if bound is None else f"<= {bound:g}"


def format_table(res: dict[str, Any]) -> str:
    """The side-by-side table: per condition Python, C and Python/C; the C target and whether met."""
    s, runs = res["settings"], res["runs"]
    conds = list(runs)
    head = f"{'':<30}" + "".join(f"{c + ': python':>16}{'c':>9}{'py/c':>7}" for c in conds)
    lines = [f"loop, Python and C controllers side by side: {s['rate_hz']:g} Hz, {s['seconds']:g} s each, {res['bus']}",
             head + f"   {'C target':<12}met ({'/'.join(conds)})", "-" * (len(head) + 30)]
    for key, label in METRICS:
        row = f"{label:<30}"
        for c in conds:
            row += f"{_num(float(runs[c]['python'][key])):>16}{_num(float(runs[c]['c'][key])):>9}"
            row += f"{_ratio(res['ratios'][c][key]):>7}"
        met = "/".join("yes" if res["c_targets"][c][key]["met"] else "NO" for c in conds) \
            if key in res["c_targets"][conds[0]] else ""
        lines.append(row + f"   {_target(key):<12}{met}")
    rows = [("cycles", lambda r, i: str(r[i]["cycles"])),
            ("latency samples", lambda r, i: str(r[i]["latency_samples"]))]
    for label, cell in rows:
        lines.append(f"{label:<30}" + "".join(f"{cell(runs[c], 'python'):>16}{cell(runs[c], 'c'):>9}{'':>7}"
                                              for c in conds))
    for kind, label in (("no_rt", "empty loop, no RT (us)"), ("rt", "empty loop, RT+pin (us)")):
        lines.append(f"{label:<30}" + "".join(
            ("/".join(_num(runs[c]["empty_loop"][kind][k]) for k in ("p50_us", "p99_us", "max_us"))
             + f", {runs[c]['empty_loop'][kind]['missed_cycles']} missed").rjust(32) for c in conds))
    lines.append(f"{'load average 1 min before/after':<30}" + "".join(
        "/".join(f"{r[k][0]:.2f}" if r[k] else "?" for k in ("loadavg_before", "loadavg_after")).rjust(32)
        for r in (runs[c] for c in conds)))
    lines.append(f"{'CPU busy/niced/steal (%)':<30}" + "".join(
        ("/".join(f"{r['cpu_percent'][k]:.0f}" for k in ("busy", "niced", "steal")) if r.get("cpu_percent")
         else "?").rjust(32) for r in (runs[c] for c in conds)))
    lines.append(f"{'other SCHED_FIFO/RR processes':<30}" + "".join(
        str(len(runs[c].get("other_realtime_processes", []))).rjust(32) for c in conds))
    py = runs[conds[0]]["python"]
    rtp = py.get("rt_priority") or f"denied ({py.get('rt_priority_denied')})"
    ld = res["load"]
    lines.append(f"controllers: SCHED_FIFO {rtp}, CPU affinity {py.get('cpu_affinity')}; machine: "
                 f"{res['machine']['cpus']} CPUs, {res['machine']['platform']}")
    q = res.get("cpu_dma_latency") or {}
    lines.append("CPU wake-up latency (PM QoS): " + (f"/dev/cpu_dma_latency held at {q['us']} us" if q.get("held")
                                                      else f"left alone{' (denied: ' + q['denied'] + ')' if 'denied' in q else ''}"))
    harness = [runs[c][i].get("harness") or {} for c in conds for i in IMPLS]
    h = next((x for x in harness if "denied" in x), harness[0])  # a refusal in any run shows
    lines.append("plant and broker: " + (f"SCHED_FIFO {h['rt_priority']}, CPUs {h.get('cpus')}" if h.get("rt_priority")
                                         else f"normal priority, unpinned{' (denied: ' + h['denied'] + ')' if 'denied' in h else ''}"))
    if "loaded" in runs:
        kind = ld["kind"] if ld["procs"] != 1 else ld["kind"].replace("processes", "process")
        lines.append(f"loaded: {ld['procs']} {kind} at nice {ld['nice']}, started before and stopped after "
                     "the loaded runs; quiet: the machine as it was (see its load average)")
    lines.append(f"empty loops: p50/p99/max lateness of an empty deadline loop, in the bench process (no RT, "
                 f"{min(s['seconds'], BASELINE_MAX_S):g} s) and with the controllers' SCHED_FIFO priority and CPU "
                 f"(RT+pin, {s['seconds']:g} s, as long as each controller)")
    return "\n".join(lines)
