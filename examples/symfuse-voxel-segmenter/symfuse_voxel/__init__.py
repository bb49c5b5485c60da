"""symfuse plugin: segment the object as the largest connected voxel component.

Back-projects the depth image into the robot frame, drops everything less than
``min_height_m`` above the table, voxelises the rest and keeps the largest 26-connected
component of occupied voxels. Unlike a DBSCAN segmenter its cost does not depend on point
density, only on the occupied volume.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from pipeline import hookimpl
from pipeline.errors import StageFailure
from pipeline.params import param
from pipeline.perception.depth import backproject_depth
from pipeline.stages import Segmenter
from pipeline.types import DepthObservation, PointCloud


def dominant_height(z_m: np.ndarray, bin_m: float) -> float:
    """Height (m) of the most populated horizontal slab: the table when none is given."""
    edges = np.arange(z_m.min(), z_m.max() + 2 * bin_m, bin_m)
    counts, edges = np.histogram(z_m, bins=edges)
    peak = int(np.argmax(counts))
    return float(0.5 * (edges[peak] + edges[peak + 1]))


class VoxelGridSegmenter(Segmenter):
    """Largest 26-connected voxel component above the table (numpy/scipy only)."""

    name = "voxel-grid"

    @dataclass(frozen=True)
    class Params:
        voxel_m: float = param(0.005, "voxel edge length (m)")
        min_height_m: float = param(0.02, "drop points closer than this to the table (m)")
        max_cells: int = param(50_000_000, "refuse voxel grids larger than this many cells")

    def segment(self, observation: DepthObservation) -> PointCloud:
        points, pixels = backproject_depth(
            observation.depth_m, observation.intrinsics, observation.T_robot_camera
        )
        if len(points) == 0:
            raise StageFailure("voxel-grid: the depth image has no valid pixels")
        table_z = observation.table_height_m
        if table_z is None:
            table_z = dominant_height(points[:, 2], self.params.voxel_m)
        above = points[:, 2] > table_z + self.params.min_height_m
        points, pixels = points[above], pixels[above]
        if len(points) == 0:
            raise StageFailure(
                f"voxel-grid: nothing is more than {self.params.min_height_m} m above the table"
            )
        cells = np.floor((points - points.min(axis=0)) / self.params.voxel_m).astype(np.int64)
        shape = tuple(int(v) for v in cells.max(axis=0) + 1)
        if np.prod(shape, dtype=np.float64) > self.params.max_cells:
            raise StageFailure(
                f"voxel-grid: {shape} voxels exceed max_cells={self.params.max_cells}; "
                "raise voxel_m"
            )
        occupied = np.zeros(shape, dtype=bool)
        occupied[tuple(cells.T)] = True
        labels, count = ndimage.label(occupied, structure=np.ones((3, 3, 3), dtype=bool))
        sizes = np.bincount(labels[tuple(cells.T)], minlength=count + 1)
        largest = int(np.argmax(sizes[1:]) + 1)
        keep = labels[tuple(cells.T)] == largest
        return PointCloud(points=points[keep], frame="robot", pixels=pixels[keep])


@hookimpl
def symfuse_register_stages(registry):
    registry.add(VoxelGridSegmenter)
