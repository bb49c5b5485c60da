"""The sweep engine on a Dask cluster gives the rows the local executor gives."""

from __future__ import annotations

import pytest
import sweep_toy

from pipeline.errors import ConfigError
from pipeline.experiments import SweepTask
from pipeline.experiments.sweep import read_rows, run_sweep

distributed = pytest.importorskip("distributed")


def make_tasks(count: int) -> list[SweepTask]:
    return [
        SweepTask(f"t{x:02d}", {"x": x, "seed": 31 * x + 5, "fail": x == 3}) for x in range(count)
    ]


def test_dask_cluster_rows_equal_local_rows_and_resume_works(tmp_path):
    tasks = make_tasks(8)
    local = run_sweep(tasks, sweep_toy.run_one, tmp_path / "local.jsonl", workers=2,
                      progress=False)  # fmt: skip
    assert local[3]["error"] == "ValueError: x=3 is not allowed"

    results = tmp_path / "dask.jsonl"
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
    ):
        first = run_sweep(tasks[:5], sweep_toy.run_one, results, executor="dask",
                          scheduler=cluster.scheduler_address, progress=False)  # fmt: skip
        rows = run_sweep(tasks, sweep_toy.run_one, results, executor="dask",
                         scheduler=cluster.scheduler_address, progress=False)  # fmt: skip

    assert first == local[:5]
    assert rows == local
    assert sorted(row["key"] for row in read_rows(results)) == [task.key for task in tasks]
    assert len(results.read_text().splitlines()) == len(tasks)


def test_an_unreachable_scheduler_is_a_config_error_naming_it(tmp_path):
    import dask

    with (
        dask.config.set({"distributed.comm.timeouts.connect": "1s"}),
        pytest.raises(ConfigError, match=r"--scheduler tcp://127\.0\.0\.1:9: cannot connect"),
    ):
        run_sweep(make_tasks(2), sweep_toy.run_one, tmp_path / "r.jsonl", executor="dask",
                  scheduler="tcp://127.0.0.1:9", progress=False)  # fmt: skip


def test_a_malformed_scheduler_address_is_a_config_error_naming_the_option(tmp_path):
    with pytest.raises(ConfigError, match=r"--scheduler nonsense: cannot connect"):
        run_sweep(make_tasks(2), sweep_toy.run_one, tmp_path / "r.jsonl", executor="dask",
                  scheduler="nonsense", progress=False)  # fmt: skip
