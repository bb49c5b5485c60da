"""The output-folder policy of every command that writes a run's results.

* A run writes into a fresh staging folder beside its target (``.NAME.partial-XXXX`` in the
  same parent, so the final move is a rename on one file system) and the staging folder
  is moved into place when the run ends.
* An explicit target that exists and is not empty is refused before anything runs, unless
  ``overwrite`` is given and it holds an earlier run (:func:`holds_earlier_run`: what a
  symfuse command wrote); then it is replaced whole when the run ends, never mixed with
  the new files. A folder of anything else (a project, a user's data) is never replaced,
  whatever the options. A target that is a file is always refused.
* Without an explicit target each run gets a fresh default folder (:func:`fresh_folder`),
  so the same command can be typed twice.
* A run that fails before it wrote any result (no ``result.json`` in the staging folder:
  bad input, a plugin raising before the first result, Ctrl-C) leaves nothing behind; a run
  that fails after (exit 3, or a plugin raising mid-trial, which records the failure in
  ``result.json``) is moved into place with everything it wrote.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from pipeline.errors import ConfigError

#: The file whose presence marks a staging folder as holding a result worth keeping.
RESULT_FILE = "result.json"

#: The journal a sweep appends its rows to.
SWEEP_ROWS_FILE = "results.jsonl"

#: The documents at the top of a run's folder that name the ``symfuse`` version that wrote
#: them: a trial's or ``fuse``'s result, ``complete``'s list of the objects of a scene.
RUN_DOCUMENTS = (RESULT_FILE, "objects.json")


def holds_earlier_run(folder: Path) -> bool:
    """Whether ``folder`` holds what a symfuse command wrote: one of :data:`RUN_DOCUMENTS`
    or a sweep's ``results.jsonl``, whose rows are objects with a ``key``."""
    folder = Path(folder)
    try:
        for name in RUN_DOCUMENTS:
            if (folder / name).is_file():
                data = json.loads((folder / name).read_text(encoding="utf-8"))
                return isinstance(data, dict) and "symfuse" in data
        if (folder / SWEEP_ROWS_FILE).is_file():
            with (folder / SWEEP_ROWS_FILE).open(encoding="utf-8") as rows:
                first = json.loads(rows.readline() or "null")
            return isinstance(first, dict) and "key" in first
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return False


def fresh_folder(base: Path) -> Path:
    """``base`` if nothing is there yet, else the first free ``base-2``, ``base-3``, ..."""
    base = Path(base)
    candidate, number = base, 1
    while candidate.exists():
        number += 1
        candidate = base.with_name(f"{base.name}-{number}")
    return candidate


def check_target(
    target: Path,
    *,
    overwrite: bool,
    inputs: Sequence[Path] = (),
    replaceable: Callable[[Path], bool] = holds_earlier_run,
    option: str = "--out",
) -> None:
    """Refuse ``target`` (given as ``option``) unless it is absent, an empty folder, or
    ``overwrite`` is given and it is ``replaceable`` (by default: it holds an earlier run)
    and holds none of the run's ``inputs`` (replacing it would delete them).

    Raises:
        ConfigError: ``target`` is a file, a non-empty folder without ``overwrite``, a
            folder of something else, or holds an input.
    """
    target = Path(target)
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        raise ConfigError(f"{option} {target}: exists and is not a folder")
    occupied = target.is_dir() and any(target.iterdir())
    if occupied and not overwrite:
        raise ConfigError(
            f"{option} {target}: the folder exists and is not empty; pass --overwrite to "
            f"replace it, or choose another {option}"
        )
    if target.is_dir():
        if Path.cwd().resolve().is_relative_to(target.resolve()):
            raise ConfigError(
                f"{option} {target}: holds the current folder; choose another {option}"
            )
        inside = [path for path in inputs if Path(path).resolve().is_relative_to(target.resolve())]
        if inside:
            raise ConfigError(
                f"{option} {target}: holds the input {inside[0]}, which replacing it would "
                f"delete; choose another {option}"
            )
    if occupied and not replaceable(target):
        raise ConfigError(
            f"{option} {target}: the folder holds no earlier symfuse run, and --overwrite "
            f"replaces only those; choose another {option}"
        )


def has_result(folder: Path) -> bool:
    """Whether a run wrote its ``result.json`` into ``folder``."""
    return (Path(folder) / RESULT_FILE).is_file()


def create_folder(folder: Path, target: Path, option: str = "--out") -> Path:
    """Create ``folder`` with its parents (as needed for the output folder ``target``).

    Raises:
        ConfigError: naming ``target`` and why: a parent is a file, or cannot be written.
    """
    for path in (folder, *folder.parents):
        if path.exists() and not path.is_dir():
            raise ConfigError(f"{option} {target}: {path} is not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{option} {target}: cannot create {folder}: {exc.strerror}") from None
    return folder


def _staging_folder(target: Path, option: str) -> Path:
    """A new empty folder beside ``target`` (its parent created as needed).

    Raises:
        ConfigError: the parent cannot be created or written (read-only, not a folder).
    """
    parent = create_folder(target.parent, target, option)
    try:
        staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-", dir=parent))
    except OSError as exc:
        raise ConfigError(f"{option} {target}: cannot write in {parent}: {exc.strerror}") from None
    staging.chmod(0o777 & ~_umask())  # mkdtemp makes it private; a result folder is not
    return staging


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _move_into_place(
    staging: Path,
    target: Path,
    *,
    overwrite: bool,
    replaceable: Callable[[Path], bool],
    option: str,
) -> None:
    """Rename ``staging`` to ``target``; an existing ``target`` (allowed by ``overwrite``,
    or empty) is set aside first and deleted only once the new folder is in place."""
    old = None
    if target.exists():
        # Anything new since the run started?
        check_target(target, overwrite=overwrite, replaceable=replaceable, option=option)
        old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=target.parent))
        os.replace(target, old / target.name)
    os.replace(staging, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def staged_output(
    target: Path,
    *,
    overwrite: bool = False,
    inputs: Sequence[Path] = (),
    replaceable: Callable[[Path], bool] = holds_earlier_run,
    option: str = "--out",
) -> Iterator[Path]:
    """Stage a run's files beside ``target`` and move them into place when the run ends.

    Checks ``target`` first (:func:`check_target`, with the run's ``inputs`` and what
    ``overwrite`` may replace), so a refused target costs nothing.
    Yields the staging folder to write into. On normal exit it becomes ``target``; on an
    exception it becomes ``target`` only when it holds ``result.json`` (the run recorded
    how far it got), else it is deleted; the exception propagates either way.

    Raises:
        ConfigError: ``target`` is refused, or its parent cannot be written.
    """
    target = Path(target)
    check_target(target, overwrite=overwrite, inputs=inputs, replaceable=replaceable, option=option)
    staging = _staging_folder(target, option)
    try:
        yield staging
    except BaseException:
        if has_result(staging):
            _move_into_place(
                staging, target, overwrite=overwrite, replaceable=replaceable, option=option
            )
        else:
            shutil.rmtree(staging, ignore_errors=True)
        raise
    _move_into_place(staging, target, overwrite=overwrite, replaceable=replaceable, option=option)
