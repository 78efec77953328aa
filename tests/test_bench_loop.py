"""The side-by-side loop bench: its ratios, its C targets, its table, and the CPU load it starts
and always stops. Orchestration is checked with fake measurements; no timing is asserted."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import pytest

from conftest import ctrl_c_reaches_it
from mrsteer_bench import loop_compare as lc, machine_state as ms
from mrsteer_bench.cpu_load import CpuLoad
from mrsteer_bench.loop import loop_timing, rt_loop_lateness
from mrsteer_cli.cli import main
from sim_plant.harness import launch

REPO = Path(__file__).resolve().parents[1]


def _alive(pid: int) -> bool:
    """Running and not a zombie (a reaped pid raises, a zombie has state Z)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _figures(impl: str, condition: str) -> dict[str, Any]:
    # Python four times C's lateness in the quiet run, twice under load; C misses its latency target loaded
    k = (4.0 if condition == "quiet" else 2.0) if impl == "python" else 1.0
    return {"implementation": impl, "cycles": 1000, "latency_samples": 990, "rt_priority": 50,
            "cpu_affinity": [1], "lateness_p50_us": 10.0 * k, "lateness_p99_us": 50.0 * k,
            "lateness_max_us": 300.0 * k, "missed_cycles": 3 if impl == "python" else 0,
            "latency_p50_us": 100.0 * k, "latency_p99_us": (400.0 if condition == "quiet" else 900.0) * k,
            "harness": {"rt_priority": 40, "cpus": [0]}}


class Recorder:
    """Fake measure, baseline and load: what was run, in which order, with the load on or off."""

    def __init__(self, fail_on: str | None = None) -> None:
        self.calls: list[tuple[str, str, bool]] = []
        self.load_on = False
        self.loads: list[tuple[int, float]] = []
        self.fail_on = fail_on
        self.harness_rt: list[bool] = []

    def measure(self, rate_hz: float, seconds: float, *, pin: bool, program: Any, baseline: bool,
                harness_rt: bool) -> dict[str, Any]:
        impl = "python" if program is None else "c"
        self.harness_rt.append(harness_rt)
        condition = "loaded" if self.load_on else "quiet"
        self.calls.append((impl, condition, baseline))
        if self.fail_on == f"{impl} {condition}":
            raise RuntimeError("controller failed")
        return _figures(impl, condition)

    def baseline(self, rate_hz: float, seconds: float, pin: bool) -> dict[str, dict[str, Any]]:
        self.calls.append(("empty", "loaded" if self.load_on else "quiet", False))
        return {"no_rt": {"p50_us": 1.0, "p99_us": 2.0, "max_us": 3.0, "missed_cycles": 0},
                "rt": {"p50_us": 4.0, "p99_us": 5.0, "max_us": 6.0, "missed_cycles": 7}}

    @contextmanager
    def load(self, procs: int, max_seconds: float) -> Iterator[None]:
        self.loads.append((procs, max_seconds))
        self.load_on = True
        try:
            yield
        finally:
            self.load_on = False


def _compare(rec: Recorder, procs: int = 2) -> dict[str, Any]:
    return lc.compare(lc.CompareSettings(500.0, 30.0, procs, pm_qos=False), lambda _: None, measure=rec.measure,
                      baseline=rec.baseline, load=rec.load, programs={"python": None, "c": ("mrs_node",)})


def test_ratio_is_python_over_c_and_undefined_without_a_c_figure() -> None:
    assert lc.ratio(300.0, 100.0) == pytest.approx(3.0)
    assert lc.ratio(0.0, 0.0) is None and lc.ratio(5.0, 0.0) is None
    assert lc.ratio(float("nan"), 1.0) is None and lc.ratio(1.0, float("nan")) is None


def test_c_targets_are_judged_at_their_bounds() -> None:
    at = {"lateness_p99_us": 100.0, "missed_cycles": 2, "latency_p99_us": 500.0}
    assert all(v["met"] for v in lc.judge_c(at, empty_rt_missed=2).values())
    over = lc.judge_c({"lateness_p99_us": 100.5, "missed_cycles": 3, "latency_p99_us": 501.0}, empty_rt_missed=2)
    assert not any(v["met"] for v in over.values())
    assert over["missed_cycles"] == {"target": 2.0, "value": 3.0, "met": False}
    assert over["latency_p99_us"]["target"] == 500.0
    # no missed cycle is allowed where the empty real-time loop missed none
    assert not lc.judge_c({**at, "missed_cycles": 1}, empty_rt_missed=0)["missed_cycles"]["met"]


def test_the_real_time_empty_loop_runs_as_long_as_each_controller(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: dict[str, float] = {}
    monkeypatch.setattr(lc.loop, "bare_loop_lateness", lambda hz, s: seen.setdefault("no_rt", s) and {})
    monkeypatch.setattr(lc.loop, "rt_loop_lateness", lambda hz, s, pin: seen.setdefault("rt", s) and {})
    lc.empty_loops(500.0, 30.0, True)
    assert seen == {"no_rt": lc.BASELINE_MAX_S, "rt": 30.0}


def test_compare_runs_both_controllers_quiet_then_under_the_load() -> None:
    rec = Recorder()
    res = _compare(rec)
    assert rec.calls == [("python", "quiet", False), ("c", "quiet", False), ("empty", "quiet", False),
                         ("python", "loaded", False), ("c", "loaded", False), ("empty", "loaded", False)]
    assert len(rec.loads) == 1 and rec.loads[0][0] == 2 and rec.loads[0][1] > 2 * 30.0 and not rec.load_on
    assert res["ratios"]["quiet"]["lateness_p99_us"] == pytest.approx(4.0)
    assert res["ratios"]["loaded"]["latency_p50_us"] == pytest.approx(2.0)
    assert res["ratios"]["quiet"]["missed_cycles"] is None  # C missed none
    assert res["c_targets"]["quiet"]["latency_p99_us"]["met"] is True
    assert res["c_targets"]["loaded"]["latency_p99_us"]["met"] is False
    # the C node's 0 missed cycles against the fake empty real-time loop's 7
    assert res["c_targets"]["quiet"]["missed_cycles"] == {"target": 7.0, "value": 0.0, "met": True}
    assert res["runs"]["loaded"]["c"]["implementation"] == "c" and len(res["runs"]["quiet"]["loadavg_before"]) == 3


def test_no_load_procs_means_the_quiet_condition_only() -> None:
    rec = Recorder()
    res = _compare(rec, procs=0)
    assert list(res["runs"]) == ["quiet"] and rec.loads == [] and len(rec.calls) == 3
    assert "loaded" not in lc.format_table(res)


def test_the_load_is_stopped_when_a_loaded_run_fails() -> None:
    rec = Recorder(fail_on="c loaded")
    with pytest.raises(RuntimeError, match="controller failed"):
        _compare(rec)
    assert rec.loads and not rec.load_on


def test_table_shows_both_controllers_the_ratio_and_the_targets() -> None:
    table = lc.format_table(_compare(Recorder()))
    rows = {line[:30].strip(): line[30:].split() for line in table.splitlines()}
    # quiet: python, c, py/c, loaded: python, c, py/c, target, met
    assert rows["lateness p99 (us)"] == ["200", "50", "4.00", "100", "50", "2.00", "<=", "100", "yes/yes"]
    assert rows["latency p99 (us)"] == ["1600", "400", "4.00", "1800", "900", "2.00", "<=", "500", "yes/NO"]
    assert rows["missed cycles"] == ["3", "0", "-", "3", "0", "-", "<=", "empty", "RT", "yes/yes"]
    assert rows["empty loop, RT+pin (us)"] == ["4/5/6,", "7", "missed"] * 2
    assert "2 busy-loop processes" in table and "fallback bus" in table and "SCHED_FIFO 50" in table
    assert "plant and broker: SCHED_FIFO 40, CPUs [0]" in table


def test_the_harness_runs_at_real_time_priority_unless_asked_not_to() -> None:
    rec = Recorder()
    _compare(rec)
    assert rec.harness_rt == [True] * 4
    plain = Recorder()
    lc.compare(lc.CompareSettings(500.0, 30.0, 0, harness_rt=False, pm_qos=False), lambda _: None, measure=plain.measure,
               baseline=plain.baseline, load=plain.load, programs={"python": None, "c": ("mrs_node",)})
    assert plain.harness_rt == [False, False]


def test_the_cpu_latency_bound_is_written_held_and_released(tmp_path: Path) -> None:
    import struct

    from mrsteer_bench.cpu_latency import CpuLatency

    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    with CpuLatency(0, dev) as held:
        assert held.state == {"us": 0} and held.fd is not None
        assert os.readlink(f"/proc/self/fd/{held.fd}") == str(dev)  # open while held
    assert held.fd is None and struct.unpack("i", dev.read_bytes()) == (0,)
    with CpuLatency(0, tmp_path / "none") as missing:
        assert "denied" in missing.state and "none" in missing.state["denied"] and missing.fd is None
    with pytest.raises(ValueError, match="latency bound"):
        CpuLatency(-1)


def test_compare_holds_the_cpu_latency_bound_unless_asked_not_to() -> None:
    entered: list[bool] = []

    class Fake:
        state = {"us": 0}

        def __enter__(self) -> "Fake":
            entered.append(True)
            return self

        def __exit__(self, *exc: object) -> None:
            entered.append(False)

    rec = Recorder()
    res = lc.compare(lc.CompareSettings(500.0, 30.0, 2), lambda _: None, measure=rec.measure, baseline=rec.baseline,
                     load=rec.load, programs={"python": None, "c": ("mrs_node",)}, latency=Fake)
    assert entered == [True, False] and res["cpu_dma_latency"] == {"held": True, "us": 0}
    assert "/dev/cpu_dma_latency held at 0 us" in lc.format_table(res)
    res = lc.compare(lc.CompareSettings(500.0, 30.0, 0, pm_qos=False), lambda _: None, measure=rec.measure,
                     baseline=rec.baseline, load=rec.load, programs={"python": None, "c": ("mrs_node",)}, latency=Fake)
    assert entered == [True, False] and res["cpu_dma_latency"] == {"held": False}
    assert "CPU wake-up latency (PM QoS): left alone" in lc.format_table(res)


def test_a_harness_process_gets_sched_fifo_on_every_thread_and_its_cpus() -> None:
    from mrsteer_bench import loop

    child = subprocess.Popen([sys.executable, "-c", "import threading, time\n"
                              "threading.Thread(target=time.sleep, args=(30,), daemon=True).start()\n"
                              "time.sleep(30)\n"])
    try:
        deadline = time.monotonic() + 30.0
        while len(os.listdir(f"/proc/{child.pid}/task")) < 2:  # its second thread is up
            assert time.monotonic() < deadline and child.poll() is None
            time.sleep(0.02)
        cpus = {os.cpu_count() - 1} if (os.cpu_count() or 1) > 1 else {0}
        got = loop.realtime_process(child.pid, loop.HARNESS_RT_PRIORITY, cpus)
        if "denied" in got:
            pytest.skip(f"SCHED_FIFO not permitted here: {got['denied']}")
        tids = [int(t) for t in os.listdir(f"/proc/{child.pid}/task")]
        assert len(tids) == 2 and got == {"rt_priority": loop.HARNESS_RT_PRIORITY, "cpus": sorted(cpus)}
        for tid in tids:
            assert os.sched_getscheduler(tid) == os.SCHED_FIFO
            assert os.sched_getparam(tid).sched_priority == loop.HARNESS_RT_PRIORITY
            assert os.sched_getaffinity(tid) == cpus
    finally:
        child.kill()
        child.wait()
    assert loop.realtime_process(child.pid, 40, None)["rt_priority"] == 0  # gone: said, not raised


def test_a_refused_thread_puts_the_others_back_and_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    from mrsteer_bench import loop

    calls: list[tuple[int, int]] = []

    def setscheduler(tid: int, policy: int, param: object) -> None:
        calls.append((tid, policy))
        if tid == 13 and policy == os.SCHED_FIFO:
            raise PermissionError(1, "Operation not permitted")
        if tid == 12:
            raise ProcessLookupError(3, "No such process")  # ended meanwhile: skipped, not a refusal

    monkeypatch.setattr(loop.os, "listdir", lambda path: ["11", "12", "13"])
    monkeypatch.setattr(loop.os, "sched_setscheduler", setscheduler)
    monkeypatch.setattr(loop.os, "sched_setaffinity", lambda tid, cpus: None)
    got = loop.realtime_process(99, 40, {0})
    assert got["rt_priority"] == 0 and "not permitted" in got["denied"]
    assert calls == [(11, os.SCHED_FIFO), (12, os.SCHED_FIFO), (13, os.SCHED_FIFO), (11, os.SCHED_OTHER)]


def test_cpu_load_starts_its_processes_and_stops_them() -> None:
    with CpuLoad(2, 60.0) as load:
        pids = load.pids()
        assert len(pids) == 2 and load.running() == 2 and all(_alive(p) for p in pids)
        # the same niceness as the bench (field 19 of /proc/PID/stat)
        assert all(int(Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[16]) == os.nice(0)
                   for p in pids)
    assert load.running() == 0 and not any(_alive(p) for p in pids)


def test_cpu_load_is_stopped_on_ctrl_c_and_ends_by_itself() -> None:
    with pytest.raises(KeyboardInterrupt):
        with CpuLoad(1, 60.0) as load:
            pids = load.pids()
            raise KeyboardInterrupt
    assert pids and not any(_alive(p) for p in pids)
    bounded = CpuLoad(1, 0.3)
    bounded.start()
    end = time.monotonic() + 20.0
    while bounded.running() and time.monotonic() < end:
        time.sleep(0.05)
    assert bounded.running() == 0  # its own time bound ended it, nobody stopped it
    bounded.stop()


def test_cpu_load_rejects_unbounded_settings() -> None:
    with pytest.raises(ValueError, match=">= 0"):
        CpuLoad(-1, 10.0)
    with pytest.raises(ValueError, match="> 0 s"):
        CpuLoad(1, 0.0)


@pytest.mark.parametrize("argv,needle", [(["--loop-seconds", "0"], "--loop-seconds"),
                                         (["--load-procs", "-1"], "--load-procs"),
                                         (["--loop-rate-hz", "0"], "--loop-rate-hz")])
def test_bench_loop_options_reject_bad_values(argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--only", "loop", *argv])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and needle in err and len(err.splitlines()) == 1


def test_loop_benchmark_reads_the_c_nodes_stats() -> None:
    r = loop_timing(500.0, 1.5, pin=False, program=launch.controller_program("c"), baseline=False)
    assert r["implementation"] == "c" and r["cycles"] > 300 and r["latency_samples"] > 100
    assert r["gc_disabled_in_loop"] is False and "baseline_lateness_p99_us" not in r
    assert 0.0 <= r["lateness_p50_us"] <= r["lateness_p99_us"] <= r["lateness_max_us"]
    assert 0.0 < r["latency_p50_us"] <= r["latency_p99_us"]


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def test_interrupted_bench_stops_the_load_and_its_nodes() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "mrsteer_bench", "--only", "loop", "--loop-seconds", "0.5",
                             "--load-procs", "1"], cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, preexec_fn=ctrl_c_reaches_it)
    assert proc.stderr is not None
    try:
        for line in proc.stderr:  # the loaded condition has started once its first run is announced
            if "loop loaded" in line:
                break
        time.sleep(0.3)
        started = _children(proc.pid)
        assert started  # the busy loop at least
        proc.send_signal(signal.SIGINT)  # Ctrl-C to the bench alone, not its process group
        rest = proc.stderr.read()
        assert proc.wait(30) == 130 and "interrupted" in rest
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not any(_alive(p) for p in started)


def test_machine_state_reads_cpu_times_and_realtime_processes(tmp_path: Path) -> None:
    stat = tmp_path / "stat"
    stat.write_text("cpu  100 50 30 800 20 0 0 0 0 0\ncpu0 1 2 3 4 5 6 7 8 0 0\n")
    before = ms.cpu_times(stat)
    stat.write_text("cpu  160 110 50 900 30 0 0 50 0 0\n")
    use = ms.usage_percent(before, ms.cpu_times(stat))
    # over 300 ticks: idle+iowait 110, niced 60, steal 50
    assert use == pytest.approx({"busy": 100 * 190 / 300, "niced": 20.0, "steal": 100 * 50 / 300})
    assert ms.usage_percent(before, before) is None and ms.cpu_times(tmp_path / "absent") is None

    def proc(pid: int, policy: int, prio: int, cmd: bytes) -> None:
        d = tmp_path / "proc" / str(pid)
        d.mkdir(parents=True)
        rest = ["S"] + ["0"] * 36 + [str(prio), str(policy), "0"]  # fields 3..42
        (d / "stat").write_text(f"{pid} (name with ) paren) " + " ".join(rest))
        (d / "cmdline").write_bytes(cmd)

    proc(10, 1, 50, b"mrs_node\x00--rate-hz\x00500\x00")
    proc(11, 0, 0, b"python\0")  # SCHED_OTHER
    proc(12, 1, 99, b"")  # a kernel thread
    proc(13, 2, 5, b"rr\0")
    found = sorted(ms.realtime_processes(tmp_path / "proc"), key=lambda p: p["pid"])
    assert [(p["pid"], p["policy"], p["rt_priority"]) for p in found] == [(10, "fifo", 50), (13, "rr", 5)]
    assert found[0]["command"] == "mrs_node --rate-hz 500"
    assert ms.realtime_processes(tmp_path / "proc", exclude=frozenset({10, 13})) == []


def test_real_time_empty_loop_runs_with_the_controllers_set_up() -> None:
    r = rt_loop_lateness(500.0, 0.5, pin=True)
    assert r["rt_priority"] == 50 or "rt_priority_denied" in r
    assert 0.0 <= r["p50_us"] <= r["p99_us"] <= r["max_us"] and r["missed_cycles"] >= 0
    ncpu = os.cpu_count() or 1
    if ncpu > 1 and "cpu_denied" not in r:
        assert r["cpu_affinity"] == [ncpu - 1]


def test_the_plain_machine_flag_turns_both_set_ups_off() -> None:
    from mrsteer_bench.run import build_parser, loop_settings_of

    plain = loop_settings_of(build_parser().parse_args(["--loop-plain-machine", "--load-procs", "1"]))
    assert (plain.harness_rt, plain.pm_qos, plain.load_procs) == (False, False, 1)
    default = loop_settings_of(build_parser().parse_args([]))
    assert default.harness_rt and default.pm_qos
