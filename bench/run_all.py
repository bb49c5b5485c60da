"""Run every benchmark in this folder, one after another, each printing its own table, then
one summary table of every headline number beside its target.

Run: ``python bench/run_all.py [NAME ...] [--markdown FILE]`` (names without ``.py``;
default: all but the YCB one, which needs a folder of scans). Each benchmark runs in its own
process so one's imports and threads do not disturb the next; the rows it reports through
:func:`summary.record` are gathered in a temporary file. ``--markdown`` also writes the
summary with the machine it ran on (e.g. ``docs/performance.md``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from summary import SUMMARY_FILE

from pipeline.reports.tables import format_table

HERE = Path(__file__).resolve().parent
DEFAULT = ("commands", "trial", "model", "estimator", "vc", "tactile", "sweep_overhead")
NOT_BENCHMARKS = {"run_all", "summary"}


def machine(load_at_start: float | None = None) -> str:
    """One line: CPU model, cores, load (at the start of the run too, when given: a busy
    machine stretches every wall time), Python and numpy versions."""
    model = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    import numpy

    load = f"load average {load_average():.1f}"
    if load_at_start is not None:
        load = (
            f"load average {load_at_start:.1f} at the start of the run, "
            f"{load_average():.1f} at its end"
        )
    return (
        f"{model}, {os.cpu_count()} cores, {load}; {platform.system()} "
        f"{platform.release()}; Python {platform.python_version()}, numpy {numpy.__version__}"
    )


def load_average() -> float:
    """The one-minute load average (NaN where the system has none)."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def summary_rows(rows: list[dict]) -> list[list[str]]:
    table = []
    for row in rows:
        value, unit, target = row["value"], row["unit"], row["target"]
        shown = f"{value:.3g} {unit}" if unit != "x" else f"{value:.2f}x"
        if target is None:
            goal = met = ""
        else:
            goal = f"{'<=' if row['at_most'] else '>='} {target:g}{'' if unit == 'x' else ' '}"
            goal += "x" if unit == "x" else unit
            met = "yes" if row["met"] else "no"
        table.append([row["measure"], shown, goal, met])
    return table


def markdown(table: list[list[str]], failed: list[str], load_at_start: float) -> str:
    lines = [
        "# Performance",
        "",
        "The latest `tox -e bench` (`python bench/run_all.py --markdown docs/performance.md`):",
        "every headline number of the benchmarks in `bench/` beside its target. Each",
        "benchmark prints a fuller table of its own; the numbers are wall times unless",
        "a row says otherwise, medians of several runs, and ratios are measured in one run.",
        "Wall times stretch with the machine's load (named below); rows that give a",
        "processor time (cpu) show what the work itself cost.",
        "",
        f"Machine: {machine(load_at_start)}.",
        f"Date: {datetime.date.today().isoformat()}.",
        "",
        "| measure | measured | target | met |",
        "| --- | --- | --- | --- |",
        *(f"| {' | '.join(cell.replace('|', '/') for cell in row)} |" for row in table),
    ]
    if failed:
        lines += ["", f"Benchmarks that failed to run: {', '.join(failed)}."]
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run")
    parser.add_argument("--markdown", type=Path, metavar="FILE", help="write the summary here")
    args = parser.parse_args(argv)
    failed = []
    load_at_start = load_average()
    with tempfile.TemporaryDirectory() as folder:
        rows_file = Path(folder) / "summary.jsonl"
        rows_file.touch()
        environment = {**os.environ, SUMMARY_FILE: str(rows_file)}
        for name in args.names or DEFAULT:
            script = HERE / f"{name}.py"
            if not script.is_file() or name in NOT_BENCHMARKS:
                have = sorted(p.stem for p in HERE.glob("*.py") if p.stem not in NOT_BENCHMARKS)
                print(f"no benchmark named '{name}' (have: {', '.join(have)})")
                return 2
            print(f"\n=== {name} ===", flush=True)
            done = subprocess.run([sys.executable, str(script)], env=environment)
            if done.returncode != 0:
                failed.append(name)
        rows = [json.loads(line) for line in rows_file.read_text().splitlines() if line]
    table = summary_rows(rows)
    print("\n=== summary ===")
    print(f"machine: {machine(load_at_start)}")
    print(format_table(["measure", "measured", "target", "met"], table))
    if args.markdown:
        args.markdown.write_text(markdown(table, failed, load_at_start), encoding="utf-8")
        print(f"wrote {args.markdown}")
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
