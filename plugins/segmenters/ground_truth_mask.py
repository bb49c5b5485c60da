"""Segmenter ``ground-truth-mask``: the simulator's object mask, minus near-table points."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from pipeline.api import (
    DepthObservation,
    PluginError,
    PointCloud,
    Segmenter,
    StageFailure,
    backproject_depth,
    hookimpl,
    param,
)
from pipeline.api.perception import resolve_table


class GroundTruthMask(Segmenter):
    """Object pixels from the source's ground-truth mask, without points near the table.

    Segmentation errors are taken out of an experiment this way; the points less than
    ``min_height_m`` above the table are still dropped so the cloud matches what the
    paper's segmentation keeps. The table comes from the observation's known height, or
    from RANSAC over the pixels outside the mask.
    """

    name = "ground-truth-mask"

    @dataclass(frozen=True)
    class Params:
        table: Literal["auto", "known", "ransac"] = param(
            "auto",
            "table plane: 'known' = observation.table_height_m, 'ransac' = fit the pixels "
            "outside the mask, 'auto' = known when the observation has it, else RANSAC",
        )
        min_height_m: float = param(
            0.02, "drop points closer than this to the table (m)", at_least=0.0
        )
        min_object_points: int = param(
            50, "fail when fewer object points than this remain", at_least=1
        )
        ransac_inlier_m: float = param(
            0.005, "RANSAC: distance from the plane of an inlier (m)", above=0.0
        )
        ransac_iterations: int = param(200, "RANSAC: random point triples tried", at_least=1)
        ransac_seed: int = param(0, "RANSAC: seed of its random generator", at_least=0)

    def segment(self, observation: DepthObservation) -> PointCloud:
        p = self.params
        if observation.object_mask is None:  # a configuration that cannot work: exit 2
            raise PluginError(
                "segmenter 'ground-truth-mask': the sensor source gives no object mask "
                "(only simulated sources do); use segmenter 'table-cluster'"
            )
        points, pixels = backproject_depth(
            observation.depth_m, observation.intrinsics, observation.T_robot_camera
        )
        on_object = np.asarray(observation.object_mask, dtype=bool)[pixels[:, 0], pixels[:, 1]]
        try:
            table = resolve_table(
                points[~on_object],
                observation.table_height_m,
                p.table,
                np.random.default_rng(p.ransac_seed),
                inlier_distance_m=p.ransac_inlier_m,
                iterations=p.ransac_iterations,
            )
        except ValueError as error:
            raise StageFailure(f"segmenter 'ground-truth-mask': no table plane: {error}") from error
        keep = on_object & (table.height_m(points) >= p.min_height_m)
        if keep.sum() < p.min_object_points:
            raise StageFailure(
                f"segmenter 'ground-truth-mask': {int(keep.sum())} masked points are at least "
                f"{p.min_height_m * 1000:.0f} mm above the table (< min_object_points = "
                f"{p.min_object_points}; {int(on_object.sum())} masked pixels with depth)"
            )
        return PointCloud(
            points[keep],
            "robot",
            pixels[keep],
            observation.T_robot_camera[:3, 3],
            table.z_at(points[keep, :2].mean(axis=0)),
        )


@hookimpl
def symfuse_register_stages(registry):
    registry.add(GroundTruthMask)
