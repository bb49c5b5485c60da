"""The sweep engine: run an experiment's tasks locally or on Dask, one JSONL row per task
(one module: the results file, resuming and the executors are one contract).

Every finished task is appended to the results file at once (written, flushed and fsynced),
so an interrupted or crashed sweep loses nothing it finished, and a re-run skips every task
whose row is already in the file and was made with the same params and config: each row
stores ``config_hash``, a hash of the task's params (where a trial keeps its files aside,
see :data:`~pipeline.experiments.LOCATION_PARAMS`) and of the sweep's ``fingerprint`` (the
config its trials read). A row of the same key with another hash is *stale*: a re-run
refuses, or with ``rerun_stale`` drops and re-runs it. Rows are produced the same way by
every executor, so
identical tasks give identical rows whether they ran in-process, in local worker processes
or on a Dask cluster (``run_one`` must be deterministic in its params).

A row is the JSON object ``{"key": ..., "params": ..., "config_hash": ..., **result}`` where
``result`` is what ``run_one`` returned (the engine's fields win over the same names in
``result``); a task that raised becomes ``{"key", "params", "config_hash", "error":
"<Type>: <message>"}`` and the sweep goes on. :func:`write_csv` turns rows into a flat CSV for
reports.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import csv
import functools
import hashlib
import json
import logging
import multiprocessing
import os
import shutil
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import IO, Any, Literal

from tqdm import tqdm

from pipeline.errors import ConfigError, InputError
from pipeline.experiments import LOCATION_PARAMS, SweepTask
from pipeline.io.outdir import SWEEP_ROWS_FILE, check_target, create_folder

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
    fingerprint: str = "",
    rerun_stale: bool = False,
    preload: Sequence[str] = (),
) -> list[dict]:
    # Ten parameters: what to run and where, then how, each keyword-only with a default.
    """Run every task not yet in ``results_path`` and return the rows of all ``tasks``.

    Args:
        tasks: the trials; keys must be unique. Their params must be JSON-serialisable;
            ``run_one`` receives them as they read back from JSON (lists, not tuples).
        run_one: a top-level (picklable) function from params to a JSON-serialisable dict.
        results_path: the JSONL results file; created with its folder if missing.
        workers: local worker processes (default ``os.cpu_count()``); 1 runs every task in
            this process, which is the easiest to debug. Ignored by the Dask executor.
        executor: ``"local"`` (a process pool, started with ``spawn``, or forked from a
            fork server with ``preload``) or ``"dask"``.
        scheduler: the Dask scheduler address (required for ``executor="dask"``).
        progress: show a tqdm progress bar on stderr.
        fingerprint: what else the rows depend on (a hash of the config the trials read).
        rerun_stale: drop and re-run stale rows (see the module doc) instead of refusing.
        preload: modules the local workers load before any task (an experiment's
            ``worker_imports``): imported once, in a fork server the workers are forked
            from, instead of once per worker. Empty: the workers are spawned.

    Returns:
        One row per task, in the order of ``tasks`` (rows of tasks finished by an earlier
        run included). Rows with an ``"error"`` key are tasks that raised.

    Raises:
        ValueError: duplicate task keys, params that are not JSON, a bad executor or a
            missing scheduler address.
        InputError: the results file has a corrupt line other than the last.
        ConfigError: the Dask scheduler cannot be reached, or stale rows without
            ``rerun_stale``.
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
    rows_by_key, pending = _finished_and_pending(tasks, results_path, fingerprint, rerun_stale)
    finished_before = len(tasks) - len(pending)

    # Connected before the progress bar starts: a scheduler that cannot be reached is then
    # the command's only line.
    client = _dask_client(scheduler) if executor == "dask" and pending else None
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
            _run_dask(client, pending, run_one)
            if client is not None
            else _run_local(pending, run_one, workers or os.cpu_count() or 1, preload)
        ) as lines,
    ):
        _append_rows(lines, results, bar, rows_by_key)
    return [rows_by_key[key] for key in keys]


def _append_rows(lines: Iterable[str], results: IO[str], bar: tqdm, rows: dict[str, dict]) -> None:
    """Append each row as it comes to the results file (flushed to disk: a row written is
    a row kept whatever ends the run) and to ``rows`` by key; count errors on the bar."""
    errors = 0
    for line in lines:
        results.write(line + "\n")
        results.flush()
        os.fsync(results.fileno())
        row = json.loads(line)
        rows[row["key"]] = row
        if "error" in row:
            errors += 1
            bar.set_postfix(errors=errors)
        bar.update()


def _finished_and_pending(
    tasks: Sequence[SweepTask], results_path: Path, fingerprint: str, rerun_stale: bool
) -> tuple[dict[str, dict], list[tuple[str, str, str]]]:
    """The rows ``results_path`` holds by key, and the tasks still to run as ``(key,
    params as JSON, row hash)``; stale rows (module doc) are dropped from the file to be
    run again when ``rerun_stale``.

    Raises:
        ConfigError: stale rows without ``rerun_stale``.
    """
    hashes = {task.key: row_hash(task, fingerprint) for task in tasks}
    rows_by_key = {row["key"]: row for row in read_rows(results_path)}
    stale = [key for key, row in rows_by_key.items() if row.get("config_hash") != hashes.get(key)]
    stale = [key for key in stale if key in hashes]
    if stale and not rerun_stale:
        raise ConfigError(
            f"{results_path}: {len(stale)} of {len(rows_by_key)} finished rows were made with "
            f"other params or config (first: {stale[0]}); pass --overwrite to re-run them"
        )
    if stale:
        _log.warning("%s: re-running %d stale rows", results_path, len(stale))
        for key in stale:
            del rows_by_key[key]
        _rewrite(results_path, rows_by_key.values())
    pending = [
        (task.key, _json_params(task), hashes[task.key])
        for task in tasks
        if task.key not in rows_by_key
    ]
    return rows_by_key, pending


# ---------------------------------------------------------------- the sweep's folder


@contextlib.contextmanager
def prepare_sweep_folder(
    out: Path, keys: Sequence[str], *, overwrite: bool, inputs: Sequence[Path] = ()
) -> Iterator[Path]:
    """The sweep's output folder, under the output-folder policy (:mod:`pipeline.io.outdir`)
    adapted to a resumable journal: rows are appended in place.

    A folder whose ``results.jsonl`` holds only rows of ``keys`` is resumed. Any other
    non-empty folder is refused, or with ``overwrite`` emptied first (never mixed). A folder
    this call created or emptied is removed again when the block raises before any row.

    Raises:
        ConfigError: ``out`` is a file, holds ``inputs`` or the current folder, is a
            non-empty folder of another sweep (or none) without ``overwrite``, or cannot be
            created.
    """
    out = Path(out)
    results = out / SWEEP_ROWS_FILE
    fresh = not out.exists()
    check_target(out, overwrite=True, inputs=inputs)
    if out.is_dir() and any(out.iterdir()):
        known = set(keys)
        foreign = [row["key"] for row in read_rows(results) if row["key"] not in known]
        if foreign or not results.exists():
            what = (
                f"holds {len(foreign)} rows that are not tasks of this sweep (first: {foreign[0]})"
                if foreign
                else "exists, is not empty and holds no sweep (results.jsonl)"
            )
            if not overwrite:
                raise ConfigError(f"--out {out}: {what}; pass --overwrite to replace it")
            shutil.rmtree(out)
            fresh = True
    create_folder(out, out)
    try:
        yield out
    except BaseException:
        if fresh and not read_rows(results):
            shutil.rmtree(out, ignore_errors=True)
        raise


def settings_section(
    tasks: Sequence[SweepTask],
    config: Mapping[str, Any],
    changed: Mapping[str, Any],
    sections: Sequence[str],
) -> str:
    """The ``## Configuration`` section of ``report.md``: what the trials started from
    (``config``, the sweep's resolved config; ``changed``, where it differs from the
    defaults), which sections they read, and the per-task settings of the experiment that
    win over it, beside the config's own values."""
    from pipeline.config import dotted_value, parse_override

    lines = [
        "## Configuration",
        "",
        "Every trial starts from `config.toml` (the defaults, `--config` files and `--set` "
        "values of this sweep). Changed from the defaults: "
        + (
            ", ".join(f"`{k} = {json.dumps(v)}`" for k, v in flatten_row(changed).items())
            or "nothing"
        )
        + ".",
    ]
    if set(sections) != set(config):
        lines.append(f"The trials read only [{'], ['.join(sections)}].")
    values: dict[str, list[str]] = {}
    for task in tasks:
        for text in task.settings:
            ((key, value),) = flatten_row(parse_override(text)).items()
            value = json.dumps(value)
            if value not in values.setdefault(key, []):
                values[key].append(value)
    own = {key: json.dumps(dotted_value(config, key)) for key in values}
    replaced = {key: seen for key, seen in values.items() if seen != [own[key]]}
    if replaced:
        lines += [
            "",
            "The experiment sets these per task where they differ from `config.toml` (its "
            "values win):",
            "",
            "| key | the experiment's values | config.toml |",
            "|---|---|---|",
        ]
        for key, seen in replaced.items():
            shown = ", ".join(seen) if len(seen) <= 4 else f"{len(seen)} values"
            lines.append(f"| `{key}` | {shown} | {own[key]} |")
    return "\n".join(lines) + "\n"


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


def row_hash(task: SweepTask, fingerprint: str = "") -> str:
    """The ``config_hash`` of ``task``'s row: SHA-256 (hex, first 16 digits) of its params
    without the :data:`~pipeline.experiments.LOCATION_PARAMS`, and of ``fingerprint``."""
    params = {k: v for k, v in _json_params(task).items() if k not in LOCATION_PARAMS}
    text = json.dumps({"params": params, "fingerprint": fingerprint}, sort_keys=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def _rewrite(results_path: Path, rows: Iterable[dict]) -> None:
    """Replace the results file by ``rows`` atomically (a crash keeps the old file)."""
    partial = results_path.with_name(results_path.name + ".partial")
    with partial.open("w", encoding="utf-8") as handle:
        for row in rows:
            handle.write(json.dumps(row) + "\n")
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(partial, results_path)


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


def run_task(run_one: RunOne, key: str, params: dict, config_hash: str = "") -> str:
    """Run one task and return its result row as one JSON line (no newline).

    Exceptions raised by ``run_one`` (or by encoding its result) become an error row; this
    is the function every executor ships to its workers.
    """
    head = {"key": key, "params": params, "config_hash": config_hash}
    try:
        result = run_one(params)
        if not isinstance(result, Mapping):
            raise TypeError(f"run_one returned {type(result).__name__}, not a dict")
        fields = {name: value for name, value in result.items() if name not in head}
        return json.dumps({**head, **fields}, default=_json_default)
    except Exception as exc:
        return _error_line(head, exc)


def _error_line(head: dict, exc: BaseException) -> str:
    message = str(exc).splitlines()[0] if str(exc) else ""
    error = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    return json.dumps({**head, "error": error})


# ---------------------------------------------------------------- executors


Pending = list[tuple[str, dict, str]]  # key, params, config hash


def _run_local(
    pending: Pending, run_one: RunOne, workers: int, preload: Sequence[str]
) -> Iterator[str]:
    if workers <= 1 or len(pending) <= 1:
        for task in pending:
            yield run_task(run_one, *task)
        return
    pool = concurrent.futures.ProcessPoolExecutor(
        max_workers=min(workers, len(pending)), mp_context=_worker_context(preload)
    )
    broken: BrokenProcessPool | None = None
    try:
        futures = [pool.submit(run_task, run_one, *task) for task in pending]
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


def _worker_context(preload: Sequence[str]) -> multiprocessing.context.BaseContext:
    """How the local workers start: spawned (a fresh interpreter each), or with
    ``preload`` forked from a fork server that imported those modules once. The fork
    server is a fresh interpreter too: the workers inherit none of this process's state
    (its threads, its open files, a progress bar), only the modules it loaded."""
    if not preload:
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(preload))
    return context


def _dask_client(scheduler: str) -> Any:
    """A Dask client connected to ``scheduler``.

    Raises:
        ImportError: dask.distributed is not installed.
        ConfigError: the address is malformed or the scheduler cannot be reached.
    """
    try:
        from dask.distributed import Client
    except ImportError as exc:
        raise ImportError(
            "the dask executor needs dask.distributed (pip install 'symfuse[dask]')"
        ) from exc
    try:
        return Client(scheduler)
    except (OSError, ValueError, TypeError) as exc:
        raise ConfigError(f"--scheduler {scheduler}: cannot connect ({exc})") from exc


def _run_dask(client: Any, pending: Pending, run_one: RunOne) -> Iterator[str]:
    from dask.distributed import as_completed

    with client:
        keys, params, hashes = zip(*pending, strict=True)
        futures = client.map(functools.partial(run_task, run_one), keys, params, hashes, pure=False)
        params_by_future = dict(zip(futures, pending, strict=True))
        try:
            for future in as_completed(futures):
                yield _dask_line(future, *params_by_future[future])
        except BaseException:
            client.cancel([future for future in futures if not future.done()])
            raise


def _dask_line(future: Any, key: str, params: dict, config_hash: str) -> str:
    """The row of a finished Dask future; a task that killed its workers becomes an error
    row (it is the task's fault), anything else about the cluster propagates."""
    from distributed.scheduler import KilledWorker

    try:
        return future.result()
    except KilledWorker as exc:
        return _error_line({"key": key, "params": params, "config_hash": config_hash}, exc)


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
