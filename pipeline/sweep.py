"""The sweep engine: run an experiment's tasks locally or on Dask, one JSONL row per task.

Every finished task is appended to the results file at once (written, flushed and fsynced),
so an interrupted or crashed sweep loses nothing it finished, and a re-run skips every task
whose key is already in the file. Rows are produced the same way by every executor, so
identical tasks give identical rows whether they ran in-process, in local worker processes
or on a Dask cluster (``run_one`` must be deterministic in its params).

A row is the JSON object ``{"key": ..., "params": ..., **result}`` where ``result`` is what
``run_one`` returned (``key`` and ``params`` are set by the engine and win over the same
names in ``result``); a task that raised becomes ``{"key", "params", "error": "<Type>:
<message>"}`` and the sweep goes on. :func:`write_csv` turns rows into a flat CSV for
reports.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import csv
import functools
import json
import logging
import multiprocessing
import os
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, Literal

from tqdm import tqdm

from .errors import ConfigError, InputError
from .experiments import SweepTask

_log = logging.getLogger(__name__)

Executor = Literal["local", "dask"]
RunOne = Callable[[dict], dict]


def run_sweep(
    tasks: Sequence[SweepTask],
    run_one: RunOne,
    results_path: Path,
    *,
    workers: int | None = None,
    executor: Executor = "local",
    scheduler: str | None = None,
    progress: bool = True,
) -> list[dict]:
    """Run every task not yet in ``results_path`` and return the rows of all ``tasks``.

    Args:
        tasks: the trials; keys must be unique. Their params must be JSON-serialisable;
            ``run_one`` receives them as they read back from JSON (lists, not tuples).
        run_one: a top-level (picklable) function from params to a JSON-serialisable dict.
        results_path: the JSONL results file; created with its folder if missing.
        workers: local worker processes (default ``os.cpu_count()``); 1 runs every task in
            this process, which is the easiest to debug. Ignored by the Dask executor.
        executor: ``"local"`` (a process pool, started with ``spawn``) or ``"dask"``.
        scheduler: the Dask scheduler address (required for ``executor="dask"``).
        progress: show a tqdm progress bar on stderr.

    Returns:
        One row per task, in the order of ``tasks`` (rows of tasks finished by an earlier
        run included). Rows with an ``"error"`` key are tasks that raised.

    Raises:
        ValueError: duplicate task keys, params that are not JSON, a bad executor or a
            missing scheduler address.
        InputError: the results file has a corrupt line other than the last.
        ConfigError: the Dask scheduler cannot be reached.
        KeyboardInterrupt: after cancelling pending tasks; finished rows are kept.
    """
    keys = [task.key for task in tasks]
    duplicates = sorted(key for key, count in Counter(keys).items() if count > 1)
    if duplicates:
        raise ValueError(f"duplicate task keys: {', '.join(duplicates[:5])}")
    if executor not in ("local", "dask"):
        raise ValueError(f"unknown executor '{executor}' (use 'local' or 'dask')")
    if executor == "dask" and not scheduler:
        raise ValueError("the dask executor needs a scheduler address (e.g. tcp://host:8786)")

    results_path = Path(results_path)
    results_path.parent.mkdir(parents=True, exist_ok=True)
    rows_by_key = {row["key"]: row for row in read_rows(results_path)}
    pending = [(task.key, _json_params(task)) for task in tasks if task.key not in rows_by_key]
    finished_before = len(tasks) - len(pending)

    with (
        results_path.open("a", encoding="utf-8") as results,
        tqdm(
            total=len(tasks),
            initial=finished_before,
            desc=results_path.stem,
            unit="task",
            disable=not progress,
        ) as bar,
        contextlib.closing(
            _run_dask(pending, run_one, scheduler)  # type: ignore[arg-type]
            if executor == "dask"
            else _run_local(pending, run_one, workers or os.cpu_count() or 1)
        ) as lines,
    ):
        errors = 0
        for line in lines:
            results.write(line + "\n")
            results.flush()
            os.fsync(results.fileno())
            row = json.loads(line)
            rows_by_key[row["key"]] = row
            if "error" in row:
                errors += 1
                bar.set_postfix(errors=errors)
            bar.update()
    return [rows_by_key[key] for key in keys]


# ---------------------------------------------------------------- results file


def read_rows(results_path: Path) -> list[dict]:
    """The rows of a JSONL results file, in file order; [] when it does not exist.

    A last line cut short by a crash is dropped and the file truncated to the rows before
    it (a complete last line that only lacks its newline is kept and the newline added).
    When a key appears twice, the first row wins.

    Raises:
        InputError: a line other than the last is not a JSON object with a ``key``.
    """
    results_path = Path(results_path)
    if not results_path.exists():
        return []
    data = results_path.read_bytes()
    lines = data.split(b"\n")
    last_number = max((n for n, raw in enumerate(lines, start=1) if raw.strip()), default=0)
    rows: list[dict] = []
    seen: set[str] = set()
    position = 0  # byte offset of the current line
    for number, raw in enumerate(lines, start=1):
        if raw.strip():
            row = _parse_line(raw)
            if row is None:
                if number != last_number:
                    raise InputError(
                        f"{results_path}:{number}: not a JSON result row with a 'key'; "
                        "fix or delete the line"
                    )
                _log.warning("%s:%d: dropping a truncated last line", results_path, number)
                _truncate(results_path, position)
                return rows
            if row["key"] not in seen:
                seen.add(row["key"])
                rows.append(row)
        position += len(raw) + 1
    if data and not data.endswith(b"\n"):
        with results_path.open("ab") as handle:
            handle.write(b"\n")
    return rows


def _parse_line(raw: bytes) -> dict | None:
    try:
        row = json.loads(raw)
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(row, dict) or not isinstance(row.get("key"), str):
        return None
    return row


def _truncate(path: Path, size: int) -> None:
    with path.open("r+b") as handle:
        handle.truncate(size)
        handle.flush()
        os.fsync(handle.fileno())


# ---------------------------------------------------------------- one task, any executor


def _json_params(task: SweepTask) -> dict:
    try:
        return json.loads(json.dumps(dict(task.params), allow_nan=True))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"task {task.key}: params are not JSON-serialisable ({exc})") from exc


def _json_default(value: Any) -> Any:
    """Encode numpy scalars and arrays (common in results) as plain JSON values."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def run_task(run_one: RunOne, key: str, params: dict) -> str:
    """Run one task and return its result row as one JSON line (no newline).

    Exceptions raised by ``run_one`` (or by encoding its result) become an error row; this
    is the function every executor ships to its workers.
    """
    try:
        result = run_one(params)
        if not isinstance(result, Mapping):
            raise TypeError(f"run_one returned {type(result).__name__}, not a dict")
        fields = {name: value for name, value in result.items() if name not in ("key", "params")}
        return json.dumps({"key": key, "params": params, **fields}, default=_json_default)
    except Exception as exc:
        return _error_line(key, params, exc)


def _error_line(key: str, params: dict, exc: BaseException) -> str:
    message = str(exc).splitlines()[0] if str(exc) else ""
    error = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    return json.dumps({"key": key, "params": params, "error": error})


# ---------------------------------------------------------------- executors


def _run_local(pending: list[tuple[str, dict]], run_one: RunOne, workers: int) -> Iterator[str]:
    if workers <= 1 or len(pending) <= 1:
        for key, params in pending:
            yield run_task(run_one, key, params)
        return
    pool = concurrent.futures.ProcessPoolExecutor(
        max_workers=min(workers, len(pending)), mp_context=multiprocessing.get_context("spawn")
    )
    broken: BrokenProcessPool | None = None
    try:
        futures = [pool.submit(run_task, run_one, key, params) for key, params in pending]
        for future in concurrent.futures.as_completed(futures):
            if isinstance(future.exception(), BrokenProcessPool):
                broken = broken or future.exception()  # keep yielding the finished ones
                continue
            yield future.result()
    except BaseException:  # KeyboardInterrupt, or the caller closing the generator
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
    if broken is not None:
        broken.add_note(
            "a worker process died (e.g. a crash in a native library); finished rows are "
            "kept: re-run to resume, or use --workers 1 to find the task"
        )
        raise broken


def _run_dask(pending: list[tuple[str, dict]], run_one: RunOne, scheduler: str) -> Iterator[str]:
    if not pending:
        return
    try:
        from dask.distributed import Client, as_completed
    except ImportError as exc:
        raise ImportError(
            "the dask executor needs dask.distributed (pip install 'symfuse[dask]')"
        ) from exc
    try:
        client = Client(scheduler)
    except OSError as exc:
        raise ConfigError(f"dask scheduler {scheduler}: cannot connect ({exc})") from exc
    with client:
        keys, params = zip(*pending, strict=True)
        futures = client.map(functools.partial(run_task, run_one), keys, params, pure=False)
        params_by_future = dict(zip(futures, pending, strict=True))
        try:
            for future in as_completed(futures):
                yield _dask_line(future, *params_by_future[future])
        except BaseException:
            client.cancel([future for future in futures if not future.done()])
            raise


def _dask_line(future: Any, key: str, params: dict) -> str:
    """The row of a finished Dask future; a task that killed its workers becomes an error
    row (it is the task's fault), anything else about the cluster propagates."""
    from distributed.scheduler import KilledWorker

    try:
        return future.result()
    except KilledWorker as exc:
        return _error_line(key, params, exc)


# ---------------------------------------------------------------- CSV for reports


def flatten_row(row: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts flattened to dotted names: ``{"a": {"b": 1}} -> {"a.b": 1}``."""
    flat: dict[str, Any] = {}
    for name, value in row.items():
        column = f"{prefix}{name}"
        if isinstance(value, Mapping):
            flat.update(flatten_row(value, prefix=f"{column}."))
        else:
            flat[column] = value
    return flat


def write_csv(rows: Iterable[Mapping[str, Any]], path: Path) -> Path:
    """Write rows as CSV with dotted column names for nested dicts; returns ``path``.

    Columns appear in first-seen order; a row lacking a column leaves the cell empty;
    lists are written as JSON text and None as an empty cell.
    """
    flat_rows = [flatten_row(row) for row in rows]
    columns: dict[str, None] = {}
    for flat in flat_rows:
        columns.update(dict.fromkeys(flat))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(columns), restval="")
        writer.writeheader()
        for flat in flat_rows:
            writer.writerow({name: _csv_cell(value) for name, value in flat.items()})
    return path


def _csv_cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, list | tuple):
        return json.dumps(value)
    return value
