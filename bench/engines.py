"""World benchmark: the same trial in PyBullet and in MuJoCo, the world's phases timed.

Run: ``python bench/engines.py [--repeats N] [--objects NAME ...]`` (needs ``pip install -e
'.[mujoco]'``). For each object of the paper's tables 1-3 it runs ``run_trial`` with the
paper's grasp (VC, pictures off, seed 0) in both worlds, the engines alternating so that a
busy machine slows both alike, and prints the median seconds of the phases the world does
(``scene``: build and settle; ``sensor``: render and the Kinect's noise; ``grasp``:
descend, close, hold; ``tactile``: probe the taxels) and of the whole trial, with the
ratio MuJoCo / PyBullet measured in the same run. No target: the engines are compared, not
held to a speed.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from summary import record

from pipeline.reports.tables import format_table

WORLDS = ("pybullet", "mujoco")
PHASES = ("scene", "sensor", "grasp", "tactile")
#: The objects of the paper's tables 1-3.
OBJECTS = ("cd_drive", "plastic_case", "salt_cylinder")


def timings(objects: tuple[str, ...], repeats: int) -> dict[str, dict[str, list[float]]]:
    """``world -> phase (and "trial") -> seconds`` of every run."""
    from pipeline.config import load_config
    from pipeline.registry import load_registry
    from pipeline.run.trial import run_trial

    registry = load_registry()
    seconds: dict[str, dict[str, list[float]]] = {world: {} for world in WORLDS}
    with tempfile.TemporaryDirectory() as folder:
        for name in objects:
            for k in range(repeats + 1):  # the first of each is a warm-up
                for world in WORLDS:
                    overrides = [
                        f"world.use={world}",
                        f"trial.object={name}",
                        "trial.gripper=pg70",
                        "trial.pictures=false",
                        "planner.top-parallel.strategy=paper",
                    ]
                    config = load_config(registry, overrides=overrides)
                    done = run_trial(config, registry, Path(folder) / f"{name}-{world}-{k}")
                    if k == 0:
                        continue
                    for phase in PHASES:
                        seconds[world].setdefault(phase, []).append(done.timings.get(phase, 0.0))
                    seconds[world].setdefault("trial", []).append(sum(done.timings.values()))
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--objects", nargs="+", default=list(OBJECTS))
    args = parser.parse_args()
    seconds = timings(tuple(args.objects), args.repeats)
    rows = []
    for phase in (*PHASES, "trial"):
        pybullet = statistics.median(seconds["pybullet"][phase])
        mujoco = statistics.median(seconds["mujoco"][phase])
        ratio = mujoco / pybullet if pybullet > 0.0 else float("nan")
        rows.append([phase, f"{pybullet:.3f}", f"{mujoco:.3f}", f"{ratio:.2f}"])
        record(f"world phase {phase}: MuJoCo / PyBullet", ratio, "x")
    runs = len(args.objects) * args.repeats
    print(f"median seconds over {runs} trials per world ({', '.join(args.objects)})")
    print(format_table(["phase", "pybullet", "mujoco", "mujoco / pybullet"], rows))


if __name__ == "__main__":
    main()
