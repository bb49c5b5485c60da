"""Start-up cost of the quick commands: ``symfuse --help``, ``plugins`` and ``config``.

Run: ``python bench/commands.py [--repeats N]``. Each command runs as a new process (what a
user waits for: interpreter start, imports, plugin discovery); prints the median wall time
and the median CPU time of the process (less sensitive to a busy machine). Target: each
under 0.5 s.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

from summary import record

TARGET_S = 0.5
COMMANDS = (["--help"], ["plugins"], ["config"])


def run_process(
    arguments: list[str], env: dict[str, str] | None = None, cwd: Path | None = None
) -> tuple[float, float]:
    """Wall and CPU (user + system) seconds of one run of ``arguments`` as a new process
    (in ``cwd`` with the environment ``env``, by default this process's)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(arguments, check=True, capture_output=True, env=env, cwd=cwd)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def median_run(arguments: list[str], repeats: int) -> tuple[float, float]:
    runs = [run_process(arguments) for _ in range(repeats)]
    return statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    run_process([sys.executable, "-m", "pipeline.cli", "--help"])  # warm the file cache
    print(f"quick commands as new processes, median of {args.repeats} (s)")
    print(f"{'command':<18} {'wall':>6} {'cpu':>6} {'target':>7}  met")
    for command in COMMANDS:
        wall, cpu = median_run([sys.executable, "-m", "pipeline.cli", *command], args.repeats)
        label = "symfuse " + " ".join(command)
        met = "yes" if wall <= TARGET_S else "no"
        print(f"{label:<18} {wall:>6.2f} {cpu:>6.2f} {TARGET_S:>7.1f}  {met}")
        record(f"`{label}` (wall; cpu {cpu:.2f} s)", wall, "s", TARGET_S)


if __name__ == "__main__":
    main()
