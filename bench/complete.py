"""``symfuse complete`` per scene, warm: what one capture costs once the process is running.

Run: ``python bench/complete.py [--repeats N] [CAPTURE ...]``. In one process, after one
warm-up run of each capture, the median wall and CPU time of
``pipeline.run.completion.complete_scene`` (read the capture, support plane, segmentation,
every object's initialisation and completion: what ``symfuse complete`` does between its
imports and its files) over ``--repeats`` runs, split into the sensor (reading and the
support plane), the segmenter and the objects' completion. The captures: those named, else
the Kinect capture in ``tests/data`` and the first ``--osd K`` PCDs of the folder
``$SYMFUSE_CAPTURES`` names (skipped when unset).

Target (issue 43): at most 3.0 s per scene. The machine is shared, so the CPU time (all
threads) is printed beside the wall time and checked against the target too: on a loaded
machine the wall time says more about the load than about the code.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

from summary import record

#: Warm ``complete`` per scene (s).
SCENE_TARGET_S = 3.0
#: Environment variable naming a folder of recorded captures (``*.pcd``).
CAPTURES_ENV = "SYMFUSE_CAPTURES"
DEFAULT_CAPTURE = Path(__file__).resolve().parent.parent / "tests/data/kinect_laptop_box_floor.pcd"


def captures(named: list[str], osd: int) -> list[Path]:
    """The captures to time: ``named``, else the test data's and ``osd`` of the folder."""
    if named:
        return [Path(name) for name in named]
    found = [DEFAULT_CAPTURE] if DEFAULT_CAPTURE.is_file() else []
    folder = os.environ.get(CAPTURES_ENV, "").strip()
    if folder:
        found += sorted(Path(folder).glob("*.pcd"))[:osd]
    return found


def timed_scene(registry, path: Path) -> dict[str, tuple[float, float]]:
    """Wall and CPU seconds of each phase of one ``complete_scene`` on ``path``."""
    from pipeline.cli.complete import DEFAULTS
    from pipeline.config import load_config
    from pipeline.run.completion import complete_object, segment_scene

    config = load_config(
        registry,
        overrides=['sensor.use="recorded"', f"sensor.recorded.path={json.dumps(str(path))}"],
        command_defaults=("symfuse complete", DEFAULTS),
    )
    clocks = [(time.perf_counter(), time.process_time())]

    def lap() -> None:
        clocks.append((time.perf_counter(), time.process_time()))

    observation = config.create(registry, "sensor").observe(None)
    lap()
    segmenter = config.create(registry, "segmenter")
    observation, clouds, _ = segment_scene(segmenter, observation)
    lap()
    for index, cloud in enumerate(clouds):
        complete_object(config, registry, index, cloud, observation, (), ())
    lap()
    phases = ("sensor", "segmenter", "objects")
    result = {
        phase: (clocks[k + 1][0] - clocks[k][0], clocks[k + 1][1] - clocks[k][1])
        for k, phase in enumerate(phases)
    }
    result["complete"] = (clocks[-1][0] - clocks[0][0], clocks[-1][1] - clocks[0][1])
    return result


def main() -> None:
    from pipeline.registry import load_registry

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("captures", nargs="*", metavar="CAPTURE")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--osd", type=int, default=4, help="captures of $SYMFUSE_CAPTURES")
    args = parser.parse_args()
    registry = load_registry()
    paths = captures(args.captures, args.osd)
    print(f"warm symfuse complete per scene, median of {args.repeats} (s, wall / cpu)")
    print(f"{'capture':<34} {'sensor':>13} {'segmenter':>13} {'objects':>13} {'complete':>13}")
    worst_cpu = worst_wall = 0.0
    for path in paths:
        timed_scene(registry, path)  # warm-up: imports, caches
        runs = [timed_scene(registry, path) for _ in range(args.repeats)]
        medians = {
            phase: tuple(statistics.median(run[phase][k] for run in runs) for k in range(2))
            for phase in runs[0]
        }
        cells = "".join(f" {wall:>6.2f}/{cpu:<6.2f}" for wall, cpu in medians.values())
        print(f"{path.name[:34]:<34}{cells}")
        worst_wall = max(worst_wall, medians["complete"][0])
        worst_cpu = max(worst_cpu, medians["complete"][1])
    print()
    rows = [
        ("warm `symfuse complete`, slowest scene, cpu (s)", worst_cpu),
        ("warm `symfuse complete`, slowest scene, wall (s)", worst_wall),
    ]
    print(f"{'measure':<60} {'measured':>9} {'target':>7}  met")
    for label, value in rows:
        met = "yes" if value <= SCENE_TARGET_S else "no"
        print(f"{label:<60} {value:>9.2f} {SCENE_TARGET_S:>7.1f}  {met}")
        record(label, value, "s", SCENE_TARGET_S)


if __name__ == "__main__":
    main()
