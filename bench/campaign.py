"""Validation campaign throughput: the batch engine on a Dask LocalCluster against the scalar
firmware loop, and two workers against one.

* **campaign**: ``SAMPLES`` scenarios of 5 s at 500 Hz on the realistic car (every
  disturbance kind, the shipped calibration) through ``mrsteer campaign run``'s runner on a
  LocalCluster of one worker per core, wall time from the start of the cluster to the last
  Parquet file;
* **scalar baseline**: ``campaign.reference.run`` (the firmware's ``step()`` driving the scalar
  realistic car, the batch engine's oracle) on a few of the same samples, timed in the same
  run and scaled to the campaign's size;
* **scaling**: a smaller campaign on LocalClusters of 1 and 2 workers started beforehand, so
  the ratio is the chunks' work, not the clusters' start-up.

Each figure comes with its CPU seconds (the workers' from ``getrusage(RUSAGE_CHILDREN)`` once
their cluster has closed; the scalar loop's ``process_time``) and the machine's load average:
on a machine shared with other work the wall times say how much of it the run got, the CPU
seconds what the run itself costs.
"""

from __future__ import annotations

import os
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from sim_plant.campaign import params, reference, runner, sampling, spec

TEMPLATE = """
name = "bench"
samples = {samples}
seed = 2026
duration = 5.0
chunk = {chunk}
calibrations = ["shipped"]
[parameters]
v = {{ uniform = [5.0, 40.0] }}
mu = {{ uniform = [0.2, 1.0] }}
mass = {{ uniform = [1296.0, 1800.0] }}
disturbance = {{ choice = ["yaw_moment", "split_mu_braking", "side_wind", "blowout"] }}
onset = {{ uniform = [0.3, 1.0] }}
yaw_moment = {{ uniform = [-5000.0, 5000.0] }}
mu_split = {{ uniform = [0.1, 0.4] }}
wind_force = {{ uniform = [-2500.0, 2500.0] }}
blowout_wheel = {{ choice = ["fl", "fr", "rl", "rr"] }}
actuator_tau = {{ uniform = [0.010, 0.040] }}
noise_density = {{ loguniform = [0.005, 0.05] }}
bias = {{ uniform = [-0.5, 0.5] }}
reaction_time = {{ uniform = [0.5, 2.0] }}
"""


def _children_cpu() -> float:
    """CPU seconds of this process's finished children (a LocalCluster's workers once closed)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _timed_run(c: spec.Campaign, out: Path, **kw: Any) -> float:
    t0 = time.perf_counter()
    runner.run(c, out, out / "results", **kw)
    return time.perf_counter() - t0


def _scaling(samples: int, chunk: int, tmp: Path) -> dict[str, float]:
    """The same campaign on 1 and 2 workers; per run its wall time and its workers' CPU
    seconds, whose ratio is the cores the run got (on a machine shared with other work, fewer
    than its workers: that, not the campaign's parallelism, is then what bounds the speed-up)."""
    from distributed import LocalCluster

    c = spec.parse(TEMPLATE.format(samples=samples, chunk=chunk), "scaling.toml")
    wall, cpu = {}, {}
    for n in (1, 2):
        cpu0 = _children_cpu()
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                          silence_logs=40) as cluster:
            wall[n] = _timed_run(c, tmp / f"scale{n}", scheduler=cluster.scheduler_address)
        cpu[n] = _children_cpu() - cpu0
    return {"samples": samples, "chunk": chunk, "one_worker_s": wall[1], "two_workers_s": wall[2],
            "speedup": wall[1] / wall[2], "one_worker_cpu_s": cpu[1], "two_workers_cpu_s": cpu[2],
            "one_worker_cores": cpu[1] / wall[1], "two_workers_cores": cpu[2] / wall[2],
            "loadavg_1min": os.getloadavg()[0]}


QUICK_SAMPLES = 512  # --quick: the campaign and the scaling run (a smoke run: its figures are noisier)


def campaign_bench(quick: bool) -> dict[str, Any]:
    """The campaign (wall time and its workers' CPU seconds), the scalar loop (wall and CPU), the
    scaling, and the machine's load average before and after."""
    load_before = os.getloadavg()[0]
    n = QUICK_SAMPLES if quick else 100_000
    workers = os.cpu_count() or 1
    # chunks a multiple of the workers (100,000 in 8 of 12,500: 4 each), so none idles at the end
    chunk = QUICK_SAMPLES // 4 if quick else -(-n // (4 * workers))
    n_scalar = 1 if quick else 6
    c = spec.parse(TEMPLATE.format(samples=n, chunk=chunk), "bench.toml")
    with tempfile.TemporaryDirectory(prefix="mrsteer-bench-campaign-") as d:
        tmp = Path(d)
        cpu0 = _children_cpu()
        t_batch = _timed_run(c, tmp / "full", workers=workers)
        cpu_batch = _children_cpu() - cpu0
        s = sampling.samples(c, np.arange(n_scalar))
        cfg = spec.calibration("shipped")
        t0, c0 = time.perf_counter(), time.process_time()
        for i in range(n_scalar):
            reference.run(params.scenario_for(s.row(i), c.duration), cfg)
        per_scalar = (time.perf_counter() - t0) / n_scalar
        per_scalar_cpu = (time.process_time() - c0) / n_scalar
        load_mid = os.getloadavg()[0]
        scaling = _scaling(QUICK_SAMPLES if quick else 32768, QUICK_SAMPLES // 4 if quick else 4096, tmp)
    steps = int(round(c.duration / spec.TS)) + 1
    return {"name": "validation campaign", "samples": n, "chunk": chunk, "duration_s": c.duration,
            "rate_hz": 1.0 / spec.TS, "workers": workers, "ours_s": t_batch, "ours_cpu_s": cpu_batch,
            "sample_steps_per_s": n * steps / t_batch, "sample_steps_per_cpu_s": n * steps / cpu_batch,
            "baseline_s": per_scalar * n, "baseline_cpu_s": per_scalar_cpu * n,
            "baseline_name": f"campaign.reference.run (firmware step() and the scalar "
            f"realistic car) on {n_scalar} samples, scaled", "speedup": per_scalar * n / t_batch,
            "speedup_cpu": per_scalar_cpu / cpu_batch * n,
            "loadavg_1min": [load_before, load_mid, os.getloadavg()[0]],
            "scaling": scaling, "target": "100,000 x 5 s at 500 Hz in <= 120 s; >= 100x the scalar loop; "
            "2 workers >= 1.7x 1 worker"}
