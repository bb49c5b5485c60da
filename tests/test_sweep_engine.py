"""The sweep engine: append-and-skip results file, resume, error rows, crash safety, CSV."""

from __future__ import annotations

import csv
import json
import os
import signal
import threading
from concurrent.futures.process import BrokenProcessPool

import numpy as np
import pytest
import sweep_toy

from pipeline.errors import ConfigError, InputError
from pipeline.experiments import SweepTask
from pipeline.experiments.sweep import read_rows, row_hash, run_sweep, write_csv


def make_tasks(count: int, **extra_by_x: dict) -> list[SweepTask]:
    """Tasks t00, t01, ... with x = index and a per-task seed; extra params by x."""
    return [
        SweepTask(f"t{x:02d}", {"x": x, "seed": 1000 + 7 * x, **extra_by_x.get(f"x{x}", {})})
        for x in range(count)
    ]


def expected_row(task: SweepTask) -> dict:
    """The row the engine must record: key, params, hash and the toy's own result, via JSON."""
    head = {"key": task.key, "params": dict(task.params), "config_hash": row_hash(task)}
    return json.loads(json.dumps(head | sweep_toy.run_one(dict(task.params))))


class CountingRunOne:
    """Wraps the toy in-process, recording which x it ran; can raise KeyboardInterrupt."""

    def __init__(self, interrupt_at_x: int | None = None) -> None:
        self.calls: list[int] = []
        self.interrupt_at_x = interrupt_at_x

    def __call__(self, params: dict) -> dict:
        if params["x"] == self.interrupt_at_x:
            raise KeyboardInterrupt
        self.calls.append(params["x"])
        return sweep_toy.run_one(params)


def file_lines(path) -> list[str]:
    text = path.read_text()
    assert text.endswith("\n")
    return text.splitlines()


def test_rows_follow_task_order_and_every_row_is_one_json_line(tmp_path):
    tasks = make_tasks(4)
    results = tmp_path / "out" / "results.jsonl"
    rows = run_sweep(tasks, sweep_toy.run_one, results, workers=1, progress=False)
    assert rows == [expected_row(task) for task in tasks]
    assert sorted(json.loads(line)["key"] for line in file_lines(results)) == [t.key for t in tasks]


def test_rerun_skips_finished_keys_and_runs_only_new_ones(tmp_path):
    results = tmp_path / "results.jsonl"
    first = CountingRunOne()
    run_sweep(make_tasks(5), first, results, workers=1, progress=False)
    assert first.calls == [0, 1, 2, 3, 4]

    second = CountingRunOne()
    rows = run_sweep(make_tasks(8), second, results, workers=1, progress=False)
    assert second.calls == [5, 6, 7]
    assert rows == [expected_row(task) for task in make_tasks(8)]
    assert len(file_lines(results)) == 8

    third = CountingRunOne()
    run_sweep(make_tasks(8), third, results, workers=1, progress=False)
    assert third.calls == []


def test_rows_made_with_another_config_or_params_are_stale(tmp_path):
    """A row is reused only when its task's params and the sweep's fingerprint match; a
    stale row is refused, or dropped and re-run with rerun_stale."""
    results = tmp_path / "r.jsonl"
    run_sweep(make_tasks(3), sweep_toy.run_one, results, workers=1, progress=False,
              fingerprint="config A")  # fmt: skip
    with pytest.raises(ConfigError, match=r"3 of 3 finished rows were made with other params"):
        run_sweep(make_tasks(3), sweep_toy.run_one, results, workers=1, progress=False,
                  fingerprint="config B")  # fmt: skip
    reseeded = make_tasks(3, x1={"seed": 5})
    with pytest.raises(ConfigError, match=r"1 of 3 finished rows .* \(first: t01\)"):
        run_sweep(reseeded, sweep_toy.run_one, results, workers=1, progress=False,
                  fingerprint="config A")  # fmt: skip
    counting = CountingRunOne()
    rows = run_sweep(reseeded, counting, results, workers=1, progress=False,
                     fingerprint="config A", rerun_stale=True)  # fmt: skip
    assert counting.calls == [1]
    assert rows[1]["params"]["seed"] == 5
    assert [row["key"] for row in read_rows(results)] == ["t00", "t02", "t01"]
    assert all(row["config_hash"] == row_hash(task, "config A")
               for row, task in zip(rows, reseeded, strict=True))  # fmt: skip


def test_where_a_trial_keeps_its_files_is_not_part_of_the_hash():
    here = SweepTask("t", {"x": 1, "trial_dir": "/a/trials/t"})
    moved = SweepTask("t", {"x": 1, "trial_dir": "/b/trials/t"})
    assert row_hash(here, "c") == row_hash(moved, "c") != row_hash(here, "d")


def test_interrupt_keeps_finished_rows_and_reraises(tmp_path):
    results = tmp_path / "results.jsonl"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(make_tasks(6), CountingRunOne(interrupt_at_x=3), results, progress=False,
                  workers=1)  # fmt: skip
    assert [row["key"] for row in read_rows(results)] == ["t00", "t01", "t02"]

    resumed = CountingRunOne()
    rows = run_sweep(make_tasks(6), resumed, results, workers=1, progress=False)
    assert resumed.calls == [3, 4, 5]
    assert rows == [expected_row(task) for task in make_tasks(6)]


def test_a_raising_task_becomes_an_error_row_and_the_sweep_goes_on(tmp_path):
    tasks = make_tasks(4, x2={"fail": True})
    rows = run_sweep(tasks, sweep_toy.run_one, tmp_path / "r.jsonl", workers=1, progress=False)
    assert rows[2] == {"key": "t02", "params": dict(tasks[2].params),
                       "config_hash": row_hash(tasks[2]),
                       "error": "ValueError: x=2 is not allowed"}  # fmt: skip
    assert [row for i, row in enumerate(rows) if i != 2] == [
        expected_row(task) for i, task in enumerate(tasks) if i != 2
    ]


def test_a_result_that_is_not_a_dict_becomes_an_error_row(tmp_path):
    rows = run_sweep(make_tasks(1), lambda params: [params["x"]], tmp_path / "r.jsonl",
                     workers=1, progress=False)  # fmt: skip
    assert rows[0]["error"] == "TypeError: run_one returned list, not a dict"


def test_numpy_values_in_results_are_written_as_plain_json(tmp_path):
    def run_one(params: dict) -> dict:
        return {"scalar": np.float64(0.25), "count": np.int64(3), "vector": np.array([1.5, 2.0])}

    rows = run_sweep(make_tasks(1), run_one, tmp_path / "r.jsonl", workers=1, progress=False)
    assert rows[0] == {"key": "t00", "params": {"x": 0, "seed": 1000},
                       "config_hash": row_hash(make_tasks(1)[0]), "scalar": 0.25,
                       "count": 3, "vector": [1.5, 2.0]}  # fmt: skip


def test_truncated_last_line_is_dropped_and_its_task_rerun(tmp_path):
    results = tmp_path / "results.jsonl"
    run_sweep(make_tasks(3), sweep_toy.run_one, results, workers=1, progress=False)
    text = results.read_text()
    cut = len(text) - len(text.splitlines()[-1]) // 2 - 1  # half of the last line survives
    results.write_text(text[:cut])
    survivors = [json.loads(line)["key"] for line in text[:cut].splitlines()[:-1]]

    rerun = CountingRunOne()
    rows = run_sweep(make_tasks(3), rerun, results, workers=1, progress=False)
    assert len(rerun.calls) == 3 - len(survivors) == 1
    assert rows == [expected_row(task) for task in make_tasks(3)]
    assert sorted(json.loads(line)["key"] for line in file_lines(results)) == ["t00", "t01", "t02"]


def test_complete_last_line_without_newline_is_kept(tmp_path):
    results = tmp_path / "results.jsonl"
    run_sweep(make_tasks(2), sweep_toy.run_one, results, workers=1, progress=False)
    results.write_text(results.read_text().rstrip("\n"))

    rerun = CountingRunOne()
    run_sweep(make_tasks(3), rerun, results, workers=1, progress=False)
    assert rerun.calls == [2]
    assert [json.loads(line)["key"] for line in file_lines(results)] == ["t00", "t01", "t02"]


def test_a_corrupt_line_before_the_last_is_an_input_error(tmp_path):
    results = tmp_path / "results.jsonl"
    results.write_text('{"key": "t00"}\nnot json\n{"key": "t01"}\n')
    with pytest.raises(InputError, match=r"results\.jsonl:2"):
        run_sweep(make_tasks(2), sweep_toy.run_one, results, workers=1, progress=False)


def test_invalid_arguments_raise_value_error(tmp_path):
    results = tmp_path / "r.jsonl"
    duplicated = [SweepTask("a", {"x": 1, "seed": 1}), SweepTask("a", {"x": 2, "seed": 2})]
    with pytest.raises(ValueError, match="duplicate task keys: a"):
        run_sweep(duplicated, sweep_toy.run_one, results, progress=False)
    with pytest.raises(ValueError, match="scheduler"):
        run_sweep(make_tasks(1), sweep_toy.run_one, results, executor="dask", progress=False)
    with pytest.raises(ValueError, match="task bad: params are not JSON"):
        run_sweep([SweepTask("bad", {"x": object()})], sweep_toy.run_one, results, progress=False)
    assert not results.exists() or results.read_text() == ""


@pytest.mark.parametrize("preload", [(), ("sweep_toy",)], ids=["spawned", "forked"])
def test_process_pool_gives_the_same_rows_as_in_process(tmp_path, preload):
    """Workers spawned, or forked from a fork server that loaded ``preload`` once."""
    tasks = make_tasks(6, x4={"fail": True})
    in_process = run_sweep(tasks, sweep_toy.run_one, tmp_path / "a.jsonl", workers=1,
                           progress=False)  # fmt: skip
    pooled = run_sweep(tasks, sweep_toy.run_one, tmp_path / "b.jsonl", workers=2,
                       progress=False, preload=preload)  # fmt: skip
    assert pooled == in_process
    assert sorted(file_lines(tmp_path / "b.jsonl")) == sorted(file_lines(tmp_path / "a.jsonl"))


def test_a_dying_worker_keeps_finished_rows_and_a_rerun_completes(tmp_path):
    results = tmp_path / "results.jsonl"
    crashing = make_tasks(6, x5={"die_after_s": 2.0})
    with pytest.raises(BrokenProcessPool):
        run_sweep(crashing, sweep_toy.run_one, results, workers=2, progress=False)
    assert {row["key"] for row in read_rows(results)} == {f"t{x:02d}" for x in range(5)}

    rows = run_sweep(make_tasks(6), sweep_toy.run_one, results, workers=2, progress=False)
    assert rows == [expected_row(task) for task in make_tasks(6)]
    assert len(file_lines(results)) == 6


@pytest.mark.slow
def test_ctrl_c_during_a_pool_run_keeps_finished_rows_and_reraises(tmp_path):
    results = tmp_path / "results.jsonl"
    # 3 s of work on two workers, interrupted once the first row is written: the interrupt
    # lands mid-run however long the workers take to start on a busy machine.
    slow = [SweepTask(t.key, {**t.params, "sleep_s": 0.25}) for t in make_tasks(24)]
    done = threading.Event()
    pressed: list[int] = []  # rows written at each press

    def interrupt_after_the_first_row():
        # Pressed again every 0.2 s until the sweep stops, as a user would.
        while not done.wait(0.02):
            if results.exists() and (rows := len(results.read_text().splitlines())):
                pressed.append(rows)
                os.kill(os.getpid(), signal.SIGINT)
                if done.wait(0.2):
                    return

    # A process started as a background job of a shell without job control inherits SIGINT
    # ignored (the test then failed in such runs); a terminal's Ctrl-C is what is tested.
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    watcher = threading.Thread(target=interrupt_after_the_first_row)
    watcher.start()
    interrupted = False
    try:
        try:
            run_sweep(slow, sweep_toy.run_one, results, workers=2, progress=False)
        finally:  # the watcher stops before the outer handler: a press in flight is caught
            done.set()
            watcher.join()
    except KeyboardInterrupt:
        interrupted = True
    finally:
        signal.signal(signal.SIGINT, inherited)
    assert interrupted, (
        f"no KeyboardInterrupt: presses at {pressed} rows written, "
        f"{len(read_rows(results))} rows at the end, "
        f"SIGINT handler {signal.getsignal(signal.SIGINT)!r}"
    )
    kept = read_rows(results)
    assert len(kept) < len(slow)
    assert all(row == expected_row(slow[int(row["key"][1:])]) for row in kept)

    rows = run_sweep(slow, sweep_toy.run_one, results, workers=2, progress=False)
    assert rows == [expected_row(task) for task in slow]


def test_write_csv_flattens_nested_dicts_with_dotted_columns(tmp_path):
    rows = [
        {"key": "a", "params": {"x": 1, "grid": {"r_m": 0.01}}, "value": 2.5, "draws": [1, 2]},
        {"key": "b", "params": {"x": 2, "grid": {"r_m": 0.02}}, "error": "ValueError: no"},
    ]
    path = write_csv(rows, tmp_path / "sub" / "table.csv")
    with path.open(newline="") as handle:
        reader = csv.DictReader(handle)
        table = list(reader)
    assert reader.fieldnames == ["key", "params.x", "params.grid.r_m", "value", "draws", "error"]
    assert table[0] == {"key": "a", "params.x": "1", "params.grid.r_m": "0.01", "value": "2.5",
                        "draws": "[1, 2]", "error": ""}  # fmt: skip
    assert table[1]["value"] == "" and table[1]["error"] == "ValueError: no"
