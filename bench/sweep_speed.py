"""Sweep speed against a baseline: ``symfuse sweep table3 --workers 2`` on this tree and on
an earlier revision, in one run.

Run: ``python bench/sweep_speed.py [--baseline REV] [--rounds N] [--experiment NAME]``.
The baseline revision (default: where this branch left ``main``) is unpacked with
``git archive`` into a temporary folder and run with this environment's interpreter and
libraries, its own ``pipeline`` and ``plugins`` first on the import path, and its own
plugin entry points (a revision whose plugins lived in other modules finds them: the
unpacked tree gets the distribution metadata its ``pyproject.toml`` declares). The two sweeps
run in turn, ``rounds`` times each (baseline first), each as a new ``symfuse sweep``
process into a fresh folder; the table gives every run's trials per minute (wall) and
processor seconds per trial (the sweep and its workers, user + system), and the ratios of
this tree's medians to the baseline's. The machine's load changes both alike only when
they run close together: read the processor time first on a busy machine.

It also compares the sweeps' rows: every field but the times (``timings``, ``seconds``)
and the trial folders' places (``pipeline.experiments.LOCATION_PARAMS``) must be equal,
trial by trial; the rows that differ are listed with the fields they differ in.

Target (issue 41): this tree's trials per minute at least twice the baseline's.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import tomllib
from pathlib import Path

from summary import record

from pipeline.experiments import LOCATION_PARAMS

ROOT = Path(__file__).resolve().parent.parent
THROUGHPUT_TARGET = 2.0
#: ``prctl`` option: orphaned descendants are re-parented to the caller (Linux).
PR_SET_CHILD_SUBREAPER = 36
#: Row fields that hold times: they differ between any two runs.
TIME_FIELDS = frozenset({"timings", "seconds"})


def default_baseline() -> str:
    """Where this branch left ``main``: ``git merge-base HEAD main``."""
    done = subprocess.run(
        ["git", "merge-base", "HEAD", "main"], cwd=ROOT, capture_output=True, text=True
    )
    if done.returncode != 0:
        sys.exit(f"sweep_speed: no merge base with main ({done.stderr.strip()}); pass --baseline")
    return done.stdout.strip()


def unpack(revision: str, folder: Path) -> Path:
    """The tree of ``revision`` (``git archive``) unpacked into ``folder``."""
    archive = folder / "baseline.tar"
    with archive.open("wb") as out:
        subprocess.run(["git", "archive", revision], cwd=ROOT, stdout=out, check=True)
    tree = folder / "baseline"
    with tarfile.open(archive) as tar:
        tar.extractall(tree, filter="data")
    declare_entry_points(tree)
    return tree


def declare_entry_points(tree: Path) -> None:
    """Give the unpacked ``tree`` the distribution metadata (name, version, entry points)
    of its ``pyproject.toml``: first on the import path, it is the ``symfuse`` distribution
    whose plugins the baseline's sweep loads, not this environment's editable install."""
    project = tomllib.loads((tree / "pyproject.toml").read_text())["project"]
    info = tree / f"{project['name']}-{project['version']}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n"
    )
    lines = []
    for group, points in project.get("entry-points", {}).items():
        lines += [f"[{group}]", *(f"{name} = {target}" for name, target in points.items()), ""]
    (info / "entry_points.txt").write_text("\n".join(lines))


def adopt_orphans() -> None:
    """Make this process the reaper of its orphaned descendants (Linux): a sweep's fork
    server outlives the sweep by a moment and is no child of it, so its processor time and
    its workers' reach ``RUSAGE_CHILDREN`` only when this process waits for it."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        sys.exit(f"sweep_speed: cannot become a subreaper (errno {ctypes.get_errno()})")


def reap_descendants() -> None:
    """Wait for every descendant left over (see :func:`adopt_orphans`)."""
    while True:
        try:
            os.waitpid(-1, 0)
        except ChildProcessError:
            return


def run_sweep(tree: Path, experiment: str, workers: int, out: Path) -> tuple[float, float]:
    """Wall and processor seconds (the sweep process and every process it started, its
    workers and a fork server included) of one sweep of the code in ``tree``."""
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]),
    }
    command = [sys.executable, "-m", "pipeline.cli", "sweep", experiment]
    command += ["--workers", str(workers), "--out", str(out)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(command, env=env, cwd=tree, check=True, capture_output=True)
    wall = time.perf_counter() - started
    reap_descendants()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def rows(folder: Path) -> dict[str, dict]:
    """The sweep's rows by task key, without their times and the trial folders' places."""
    found = {}
    for line in (folder / "results.jsonl").read_text().splitlines():
        row = json.loads(line)
        row["params"] = {k: v for k, v in row.get("params", {}).items() if k not in LOCATION_PARAMS}
        found[row["key"]] = {k: v for k, v in row.items() if k not in TIME_FIELDS}
    return found


def differing(base: dict[str, dict], new: dict[str, dict]) -> dict[str, list[str]]:
    """Task key -> the fields its two rows differ in (NaN equals NaN); ``["row"]`` for a
    key only one sweep has."""

    def same(a: object, b: object) -> bool:
        return a == b or (isinstance(a, float) and isinstance(b, float) and a != a and b != b)

    found = {}
    for key in sorted(set(base) | set(new)):
        if key not in base or key not in new:
            found[key] = ["row"]
            continue
        fields = set(base[key]) | set(new[key])
        changed = sorted(f for f in fields if not same(base[key].get(f), new[key].get(f)))
        if changed:
            found[key] = changed
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="git revision to compare with (default: merge base)")
    parser.add_argument("--rounds", type=int, default=1, help="sweeps of each tree")
    parser.add_argument("--experiment", default="table3")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    revision = args.baseline or default_baseline()
    adopt_orphans()
    load_start = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="symfuse-sweep-speed-") as folder:
        trees = {"baseline": unpack(revision, Path(folder)), "this tree": ROOT}
        runs: dict[str, list[tuple[float, float]]] = {name: [] for name in trees}
        found: dict[str, dict[str, dict]] = {}
        for k in range(args.rounds):
            for name, tree in trees.items():
                out = Path(folder) / f"{name.replace(' ', '_')}{k}"
                runs[name].append(run_sweep(tree, args.experiment, args.workers, out))
                found[name] = rows(out)
        trials = len(found["this tree"])
        changed = differing(found["baseline"], found["this tree"])
    load_end = os.getloadavg()[0]

    short = revision[:10]
    print(
        f"symfuse sweep {args.experiment} --workers {args.workers}: {trials} trials, "
        f"baseline {short}, load average {load_start:.1f} -> {load_end:.1f}"
    )
    print(f"{'tree':<10} {'round':>5} {'wall s':>8} {'trials/min':>10} {'cpu s/trial':>11}")
    medians = {}
    for name, measured in runs.items():
        for k, (wall, cpu) in enumerate(measured):
            print(
                f"{name:<10} {k:>5} {wall:>8.1f} {60 * trials / wall:>10.1f} {cpu / trials:>11.2f}"
            )
        medians[name] = (
            60 * trials / statistics.median(w for w, _ in measured),
            statistics.median(c for _, c in measured) / trials,
        )
    speed = medians["this tree"][0] / medians["baseline"][0]
    cpu = medians["baseline"][1] / medians["this tree"][1]
    print(f"trials per minute, this tree / baseline: {speed:.2f}x (target {THROUGHPUT_TARGET:g}x)")
    print(f"processor time per trial, baseline / this tree: {cpu:.2f}x")
    print(f"rows equal but for their times: {trials - len(changed)} of {trials}")
    for key, fields in changed.items():
        print(f"  {key}: {', '.join(fields[:8])}{' ...' if len(fields) > 8 else ''}")
    label = f"sweep {args.experiment} on {args.workers} workers against {short}"
    record(
        f"{label}: trials per minute, ratio (cpu per trial {cpu:.2f}x)",
        speed,
        "x",
        THROUGHPUT_TARGET,
        at_most=False,
    )
    record(f"{label}: rows that differ but for their times", len(changed), "rows", 0)


if __name__ == "__main__":
    main()
