"""Speed of the segmentation kernels on the catalogue scenes.

Each catalogue object stands on the table in PyBullet (yaw 0.4 rad) and the simulated
Kinect sees it once; on that scene cloud the script times, best of ``--repeats`` runs:
the RANSAC table fit on the whole scene, DBSCAN (the table-cluster segmenter's defaults,
10 mm / 10 points) on the points 20 mm or more above the table, and voxel subsampling of
those points at 2 and 5 mm. It prints one row per object and the totals.

    python bench/segmentation.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from summary import record

from pipeline.catalogue.objects import list_objects, load_object
from pipeline.params import build
from pipeline.perception.clustering import dbscan_labels, voxel_subsample_indices
from pipeline.perception.depth import backproject_depth
from pipeline.perception.table import fit_table_ransac, table_from_height
from plugins.sensors.pybullet_kinect import PybulletKinect
from plugins.worlds.pybullet_world import Pybullet


def best_of(repeats: int, function, *args) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function(*args)
        times.append(time.perf_counter() - started)
    return min(times)


def scene_points(name: str) -> tuple[np.ndarray, float]:
    with Pybullet.create(load_object(name), None, yaw=0.4, seed=1) as world:
        observation = PybulletKinect(build(PybulletKinect.Params, {}, "sensor")).observe(world)
    points, _ = backproject_depth(
        observation.depth_m, observation.intrinsics, observation.T_robot_camera
    )
    return points, observation.table_height_m


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    dbscan_labels(np.zeros((20, 3)), 0.01, 10)  # load open3d outside the timings
    columns = ("scene", "above", "ransac", "dbscan", "voxel 2mm", "voxel 5mm")
    print(" | ".join(columns))
    totals = np.zeros(4)
    for info in list_objects():
        points, table_height_m = scene_points(info.name)
        above = points[table_from_height(table_height_m).height_m(points) >= 0.02]
        seconds = np.array(
            [
                best_of(args.repeats, fit_table_ransac, points, np.random.default_rng(0)),
                best_of(args.repeats, dbscan_labels, above, 0.01, 10),
                best_of(args.repeats, voxel_subsample_indices, above, 0.002),
                best_of(args.repeats, voxel_subsample_indices, above, 0.005),
            ]
        )
        totals += seconds
        cells = " | ".join(f"{1e3 * s:.1f} ms" for s in seconds)
        print(f"{info.name} ({len(points)} points) | {len(above)} | {cells}")
    print("total | | " + " | ".join(f"{1e3 * s:.0f} ms" for s in totals))
    record("segmentation kernels on the catalogue scenes", totals.sum(), "s")


if __name__ == "__main__":
    main()
