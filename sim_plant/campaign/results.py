"""One chunk's results as a table, judged by the campaign's criteria, and the results on disk.

A chunk's table has one row per (sample, calibration): ``index``, ``calibration``, every
parameter (a categorical as its name), every ``engine.METRICS`` figure, ``pass_<criterion>``
for each criterion and ``pass`` for all of them.  It is written as
``DIR/chunks/chunk-NNNNNN.parquet``, whole or not at all (a temporary file renamed), so a
chunk file that exists is complete: that is what resuming relies on.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import io
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from firmware_py import model_regulator as mr
from firmware_py.platform.files import write_atomic
from sim_plant.campaign import engine
from sim_plant.campaign.params import INDEX, NOISE_SEED, PARAMETERS, SampleSet
from sim_plant.campaign.spec import Campaign, calibration

CHUNK_DIR = "chunks"


def chunk_path(out: Path, chunk: int) -> Path:
    return out / CHUNK_DIR / f"chunk-{chunk:06d}.parquet"


def judge(metrics: dict[str, np.ndarray], criteria: dict[str, float]) -> dict[str, np.ndarray]:
    """``pass_<name>`` per criterion (figure <= bound; a NaN figure, a sensor fault's of a sample
    without one, has nothing to judge and passes) and ``pass``: all of them, and the car did not
    spin (a spun run's figures stop at the spin: they cannot clear it)."""
    out = {f"pass_{k}": (metrics[k] <= bound) | np.isnan(metrics[k]) for k, bound in criteria.items()}
    out["pass"] = np.logical_and.reduce([~metrics["spun"], *out.values()])
    return out


def calibrations(c: Campaign, base: Path) -> dict[str, mr.ControllerConfig | None]:
    """The campaign's calibrations by name, resolved here (a .cfg file need not be on a worker)."""
    return {name: calibration(name, base) for name in c.calibrations}


#: glibc's mallopt parameters and the values the batch engine wants: its arrays of 64 KiB to a
#: few MiB are freed and made again every step, so neither mapped nor trimmed each time.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_TRIM_BYTES, _MMAP_BYTES = 256 << 20, 64 << 20


@functools.cache
def tune_allocator() -> bool:
    """Keep freed arrays in this process's heap (glibc; elsewhere a no-op, False).

    A Dask nanny starts its worker with ``MALLOC_TRIM_THRESHOLD_=65536``, which also fixes the
    mmap threshold at 128 KiB: each of the engine's temporaries of a chunk's rows is then mapped
    and unmapped, every step (7x the page faults, a quarter more CPU, measured in
    docs/campaigns.md).  Set here, in the task, it holds for any cluster's workers."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        mallopt = libc.mallopt if libc is not None else None
    except (OSError, AttributeError):
        return False
    if mallopt is None:
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_BYTES)) and bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_BYTES))


def run_chunk(c: Campaign, s: SampleSet, configs: dict[str, mr.ControllerConfig | None]) -> bytes:
    """Every calibration over the samples ``s``: the chunk's table as Parquet bytes."""
    tune_allocator()
    tables = []
    for name, config in configs.items():
        metrics = engine.simulate(s, config, c.duration, record=False)
        cols: dict[str, object] = {INDEX: s[INDEX], "calibration": [name] * len(s)}
        for key, p in PARAMETERS.items():
            cols[key] = [p.choices[int(x)] for x in s[key]] if p.choices else s[key]
        cols[NOISE_SEED] = s[NOISE_SEED]
        cols.update(metrics)
        cols.update(judge(metrics, c.criteria))
        tables.append(pa.table(cols))
    buf = io.BytesIO()
    pq.write_table(pa.concat_tables(tables), buf)
    return buf.getvalue()


def write_chunk(out: Path, chunk: int, data: bytes) -> None:
    """The chunk's file, whole: written beside and renamed into place."""
    path = chunk_path(out, chunk)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, data)


def done_chunks(out: Path) -> set[int]:
    d = out / CHUNK_DIR
    if not d.is_dir():
        return set()
    return {int(p.stem.split("-")[1]) for p in d.glob("chunk-*.parquet")}


def read_all(out: Path) -> pa.Table:
    """Every chunk's rows in one table (sorted by chunk)."""
    files = sorted((out / CHUNK_DIR).glob("chunk-*.parquet"))
    if not files:
        raise FileNotFoundError(f"{out}: no results (no {CHUNK_DIR}/chunk-*.parquet): run `mrsteer campaign run` first")
    return pa.concat_tables([pq.read_table(f) for f in files])


def same_rows(a: pa.Table, b: pa.Table) -> bool:
    """Whether two results tables hold the same rows: ``Table.equals``, but a NaN figure (a sensor
    fault's of a sample without one, a spin's time without a spin) equal to a NaN."""
    if a.schema != b.schema or a.num_rows != b.num_rows:
        return False
    return all(np.array_equal(np.asarray(a[name]), np.asarray(b[name]),
                              equal_nan=pa.types.is_floating(a.schema.field(name).type))
               for name in a.column_names)
