"""Running a campaign: chunks of samples as tasks on a Dask cluster, results per chunk on disk.

``run`` writes into the output directory the campaign file (``campaign.toml``) and then one
Parquet file per chunk as each chunk finishes (``results``).  A directory that already holds
the same campaign (same file contents) is resumed: only the chunks without a file run.  A
directory holding another campaign is refused.

Where the chunks run (``dask.distributed``):

* ``scheduler`` given: the cluster at that address (``tcp://host:8786``); the workers need
  mrsteer installed, and send each chunk's table back, so no shared file system is needed;
* else ``workers`` >= 1: a ``LocalCluster`` of that many single-threaded worker processes
  (default: one per core);
* ``workers`` = 0: in this process, no Dask (for debugging and tiny runs).

The client generates the design (``sampling``) and sends each task its chunk's samples.
Progress (samples done, rate, ETA) goes to ``progress`` as each chunk completes.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from firmware_py.platform.files import write_atomic
from sim_plant.campaign import results, sampling
from sim_plant.campaign.spec import Campaign, SpecError

SPEC_FILE = "campaign.toml"


@dataclass(frozen=True)
class RunSummary:
    chunks: int
    ran: int  # chunks computed in this run (the others were already on disk)
    samples: int
    seconds: float
    workers: int


def prepare(c: Campaign, out: Path, resume: bool) -> set[int]:
    """The output directory made ready; the chunks already done (resuming)."""
    spec = out / SPEC_FILE
    if out.exists() and not out.is_dir():
        raise SpecError(f"--out {out} exists and is not a directory")
    if spec.exists():
        if spec.read_text() != c.text:
            raise SpecError(f"{out} holds another campaign ({SPEC_FILE} differs): choose another --out")
        return results.done_chunks(out)
    if resume:
        raise SpecError(f"--resume: {out} holds no campaign to resume")
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(spec, c.text)
    return set()


def chunk_rows(c: Campaign, chunk: int) -> np.ndarray:
    return np.arange(chunk * c.chunk, min(c.samples, (chunk + 1) * c.chunk))


def run(c: Campaign, base: Path, out: Path, scheduler: str | None = None, workers: int | None = None,
        resume: bool = False, progress: Callable[[int, int, float], None] | None = None) -> RunSummary:
    """Run the chunks of ``c`` not yet in ``out`` (``base``: where its .cfg paths are relative to)."""
    done = prepare(c, out, resume)
    todo = [k for k in range(c.chunks) if k not in done]
    total = c.samples * len(c.calibrations)
    done_samples = sum(chunk_rows(c, k).size for k in done) * len(c.calibrations)
    t0 = time.monotonic()
    configs = results.calibrations(c, base)
    design = sampling.unit_design(c, np.arange(c.samples)) if c.sampling == "lhs" and todo else None

    def chunk_samples(k: int):
        rows = chunk_rows(c, k)
        return sampling.samples(c, rows, None if design is None else design[rows])

    def finished(k: int, data: bytes) -> None:
        nonlocal done_samples
        results.write_chunk(out, k, data)
        done_samples += chunk_rows(c, k).size * len(c.calibrations)
        if progress is not None:
            progress(done_samples, total, time.monotonic() - t0)

    if progress is not None:
        progress(done_samples, total, 0.0)
    if not todo:
        return RunSummary(c.chunks, 0, c.samples, 0.0, 0)
    if workers == 0 and scheduler is None:
        for k in todo:
            finished(k, results.run_chunk(c, chunk_samples(k), configs))
        return RunSummary(c.chunks, len(todo), c.samples, time.monotonic() - t0, 1)
    n_workers = _run_dask(c, configs, todo, chunk_samples, finished, scheduler, workers)
    return RunSummary(c.chunks, len(todo), c.samples, time.monotonic() - t0, n_workers)


def _run_dask(c: Campaign, configs: dict, todo: list[int], chunk_samples, finished, scheduler: str | None,
              workers: int | None) -> int:
    """The chunks on a Dask cluster, at most two per worker in flight (the design stays here)."""
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=50)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        pending = list(todo)
        futures = {}

        def submit():
            k = pending.pop(0)
            fut = client.submit(results.run_chunk, c, chunk_samples(k), configs, key=f"campaign-{c.digest}-{k}",
                                pure=False)
            futures[fut] = k
            return fut

        for _ in range(min(len(pending), 2 * n_workers)):
            submit()
        queue = as_completed(list(futures))
        for fut in queue:
            k = futures.pop(fut)
            finished(k, fut.result())
            if pending:
                queue.add(submit())
        return n_workers
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
