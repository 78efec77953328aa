"""A campaign on a dask.distributed LocalCluster of two worker processes, as --scheduler runs it."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq
import pytest

from sim_plant.campaign import results, runner, spec

distributed = pytest.importorskip("distributed")

TEXT = """
samples = 6
seed = 9
duration = 0.3
chunk = 2
calibrations = ["shipped"]
[parameters]
v = { uniform = [10.0, 30.0] }
disturbance = { choice = ["yaw_moment", "blowout"] }
onset = { uniform = [0.05, 0.2] }
"""


@pytest.mark.slow
def test_local_cluster_with_two_workers_matches_the_in_process_run(tmp_path: Path) -> None:
    c = spec.parse(TEXT, "d.toml")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=40) as cluster:
        with distributed.Client(cluster) as client, distributed.get_task_stream(client) as stream:
            res = runner.run(c, tmp_path, tmp_path / "dask", scheduler=cluster.scheduler_address)
        assert res.workers == 2
        assert len({t["worker"] for t in stream.data}) == 2, "both workers ran chunks"
    assert res.ran == 3
    runner.run(c, tmp_path, tmp_path / "local", workers=0)
    for k in range(c.chunks):
        assert results.same_rows(pq.read_table(results.chunk_path(tmp_path / "dask", k)),
                                 pq.read_table(results.chunk_path(tmp_path / "local", k)))
