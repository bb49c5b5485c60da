"""Trial benchmark: the default `symfuse trial` (CD drive, PG-70, Kinect), per phase.

Run: ``python bench/trial.py [--repeats N]``. Prints the median wall time of every phase of
``pipeline.trial.run_trial`` in one warm process (pictures on, and off as sweeps may run),
then the whole ``symfuse trial`` command as a fresh process (interpreter start and imports
included). Target: a default trial end to end under 3 s.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 3.0


def in_process(repeats: int, pictures: bool) -> tuple[dict[str, float], float]:
    from pipeline.config import load_config
    from pipeline.registry import load_registry
    from pipeline.trial import run_trial

    registry = load_registry()
    config = load_config(registry, overrides=[f"trial.pictures={str(pictures).lower()}"])
    phases: dict[str, list[float]] = {}
    totals = []
    with tempfile.TemporaryDirectory() as folder:
        run_trial(config, registry, Path(folder) / "warmup")
        for k in range(repeats):
            started = time.perf_counter()
            record = run_trial(config, registry, Path(folder) / f"run{k}")
            totals.append(time.perf_counter() - started)
            for phase, seconds in record.timings.items():
                phases.setdefault(phase, []).append(seconds)
    return {p: statistics.median(v) for p, v in phases.items()}, statistics.median(totals)


def whole_command(repeats: int) -> float:
    seconds = []
    with tempfile.TemporaryDirectory() as folder:
        for k in range(repeats):
            started = time.perf_counter()
            subprocess.run(
                [sys.executable, "-m", "pipeline.cli", "trial", "--out", f"{folder}/{k}"],
                check=True,
                capture_output=True,
            )
            seconds.append(time.perf_counter() - started)
    return statistics.median(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with_pictures, total_pictures = in_process(args.repeats, pictures=True)
    without, total_without = in_process(args.repeats, pictures=False)
    command = whole_command(args.repeats)
    print(f"default trial, median of {args.repeats} (s)")
    print(f"{'phase':<12} {'pictures on':>12} {'pictures off':>13}")
    for phase in with_pictures:
        print(f"{phase:<12} {with_pictures[phase]:>12.3f} {without.get(phase, 0.0):>13.3f}")
    print(f"{'run_trial':<12} {total_pictures:>12.3f} {total_without:>13.3f}")
    print()
    print(f"{'measure':<44} {'seconds':>8} {'target':>7}  met")
    rows = [
        ("run_trial in a warm process, pictures on", total_pictures),
        ("run_trial in a warm process, pictures off", total_without),
        ("`symfuse trial` as a new process", command),
    ]
    for label, seconds in rows:
        met = "yes" if seconds < TARGET_S else "no"
        print(f"{label:<44} {seconds:>8.2f} {TARGET_S:>7.1f}  {met}")


if __name__ == "__main__":
    main()
