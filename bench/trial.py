"""Trial benchmark: the default `symfuse trial` (CD drive, PG-70, Kinect), per phase.

Run: ``python bench/trial.py [--repeats N]``. Prints the median wall time of every phase of
``pipeline.trial.run_trial`` in one warm process (pictures on, and off as sweeps run them),
then the same trial as a fresh ``symfuse trial`` process with pictures off (interpreter
start and imports included). Targets: the process at most 1.5x the warm trial, measured in
the same run; the pictures (``rgb``, ``depth``, ``topdown`` and ``deviation`` PNGs) in at
most 0.4 s.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from commands import run_process
from summary import record

PROCESS_RATIO_TARGET = 1.5
PICTURES_TARGET_S = 0.4


def in_process(repeats: int, pictures: bool) -> tuple[dict[str, float], float, float]:
    """Median wall time of every phase, and median wall and CPU time of the whole trial."""
    from pipeline.config import load_config
    from pipeline.registry import load_registry
    from pipeline.trial import run_trial

    registry = load_registry()
    config = load_config(registry, overrides=[f"trial.pictures={str(pictures).lower()}"])
    phases: dict[str, list[float]] = {}
    totals, cpu = [], []
    with tempfile.TemporaryDirectory() as folder:
        run_trial(config, registry, Path(folder) / "warmup")
        for k in range(repeats):
            started, started_cpu = time.perf_counter(), time.process_time()
            record_ = run_trial(config, registry, Path(folder) / f"run{k}")
            totals.append(time.perf_counter() - started)
            cpu.append(time.process_time() - started_cpu)
            for phase, seconds in record_.timings.items():
                phases.setdefault(phase, []).append(seconds)
    medians = {p: statistics.median(v) for p, v in phases.items()}
    return medians, statistics.median(totals), statistics.median(cpu)


def whole_command(repeats: int) -> tuple[float, float]:
    """Median wall and CPU seconds of ``symfuse trial`` (pictures off) as a new process."""
    runs = []
    with tempfile.TemporaryDirectory() as folder:
        for k in range(repeats):
            command = [sys.executable, "-m", "pipeline.cli", "trial", "--out", f"{folder}/{k}"]
            runs.append(run_process([*command, "--set", "trial.pictures=false"]))
    return statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    with_pictures, total_pictures, cpu_pictures = in_process(args.repeats, pictures=True)
    without, total_without, cpu_without = in_process(args.repeats, pictures=False)
    command, command_cpu = whole_command(args.repeats)
    print(f"default trial, median of {args.repeats} (s)")
    print(f"{'phase':<12} {'pictures on':>12} {'pictures off':>13}")
    for phase in with_pictures:
        print(f"{phase:<12} {with_pictures[phase]:>12.3f} {without.get(phase, 0.0):>13.3f}")
    print(f"{'run_trial':<12} {total_pictures:>12.3f} {total_without:>13.3f}")
    print()
    ratio = command / total_without
    pictures = with_pictures.get("pictures", 0.0)
    # Processor times, less sensitive to a busy machine: the pictures' as the difference of
    # the two warm trials'.
    cpu_ratio = command_cpu / cpu_without
    pictures_cpu = cpu_pictures - cpu_without
    print(f"{'measure':<52} {'measured':>9} {'target':>7}  met")
    rows = [
        ("run_trial in a warm process, pictures off (s)", total_without, None),
        (
            f"`symfuse trial` as a new process, pictures off (s; cpu {command_cpu:.2f})",
            command,
            None,
        ),
        ("new process / warm run_trial", ratio, PROCESS_RATIO_TARGET),
        (f"the same in cpu time ({command_cpu:.2f} / {cpu_without:.2f} s)", cpu_ratio, None),
        ("pictures: the four PNGs of a trial (s)", pictures, PICTURES_TARGET_S),
        ("pictures, cpu (trial with less trial without) (s)", pictures_cpu, None),
    ]
    for label, value, target in rows:
        met = "" if target is None else ("yes" if value <= target else "no")
        shown = "" if target is None else f"{target:.1f}"
        print(f"{label:<52} {value:>9.2f} {shown:>7}  {met}")
    record(
        f"trial: new process / warm run_trial, pictures off ({command:.2f} / "
        f"{total_without:.2f} s; cpu {command_cpu:.2f} / {cpu_without:.2f} s = {cpu_ratio:.2f}x)",
        ratio,
        "x",
        PROCESS_RATIO_TARGET,
    )
    record(
        f"pictures: the four PNGs of a trial (cpu {pictures_cpu:.2f} s)",
        pictures,
        "s",
        PICTURES_TARGET_S,
    )


if __name__ == "__main__":
    main()
