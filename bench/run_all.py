"""Run every benchmark in this folder, one after another, each printing its own table.

Run: ``python bench/run_all.py [NAME ...]`` (names without ``.py``; default: all but the
YCB one, which needs ``../shared/ycb``). Each benchmark runs in its own process so one's
imports and threads do not disturb the next.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT = ("estimator", "vc", "tactile", "trial", "sweep_overhead")


def main(names: list[str]) -> int:
    failed = []
    for name in names or DEFAULT:
        script = HERE / f"{name}.py"
        if not script.is_file():
            have = sorted(p.stem for p in HERE.glob("*.py") if p.stem != "run_all")
            print(f"no benchmark named '{name}' (have: {', '.join(have)})")
            return 2
        print(f"\n=== {name} ===", flush=True)
        if subprocess.run([sys.executable, str(script)]).returncode != 0:
            failed.append(name)
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
