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
"""

from __future__ import annotations

import os
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


def _timed_run(c: spec.Campaign, out: Path, **kw: Any) -> float:
    t0 = time.perf_counter()
    runner.run(c, out, out / "results", **kw)
    return time.perf_counter() - t0


def _scaling(samples: int, chunk: int, tmp: Path) -> dict[str, float]:
    from distributed import LocalCluster

    c = spec.parse(TEMPLATE.format(samples=samples, chunk=chunk), "scaling.toml")
    times = {}
    for n in (1, 2):
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                          silence_logs=40) as cluster:
            times[n] = _timed_run(c, tmp / f"scale{n}", scheduler=cluster.scheduler_address)
    return {"samples": samples, "one_worker_s": times[1], "two_workers_s": times[2],
            "speedup": times[1] / times[2]}


def campaign_bench(quick: bool) -> dict[str, Any]:
    n = 4096 if quick else 100_000
    chunk = 1024 if quick else 16384
    n_scalar = 2 if quick else 6
    workers = os.cpu_count() or 1
    c = spec.parse(TEMPLATE.format(samples=n, chunk=chunk), "bench.toml")
    with tempfile.TemporaryDirectory(prefix="mrsteer-bench-campaign-") as d:
        tmp = Path(d)
        t_batch = _timed_run(c, tmp / "full", workers=workers)
        s = sampling.samples(c, np.arange(n_scalar))
        cfg = spec.calibration("shipped")
        t0 = time.perf_counter()
        for i in range(n_scalar):
            reference.run(params.scenario_for(s.row(i), c.duration), cfg)
        per_scalar = (time.perf_counter() - t0) / n_scalar
        scaling = _scaling(4096 if quick else 32768, 1024 if quick else 4096, tmp)
    steps = int(round(c.duration / spec.TS)) + 1
    return {"name": "validation campaign", "samples": n, "duration_s": c.duration, "rate_hz": 1.0 / spec.TS,
            "workers": workers, "ours_s": t_batch, "sample_steps_per_s": n * steps / t_batch,
            "baseline_s": per_scalar * n, "baseline_name": f"campaign.reference.run (firmware step() and the scalar "
            f"realistic car) on {n_scalar} samples, scaled", "speedup": per_scalar * n / t_batch,
            "scaling": scaling, "target": "100,000 x 5 s at 500 Hz in <= 120 s; >= 100x the scalar loop; "
            "2 workers >= 1.7x 1 worker"}
