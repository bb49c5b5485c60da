"""Segmenter ``table-cluster``: table plane, height filter, largest cluster."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from pipeline.api import (
    ConfigError,
    DepthObservation,
    PointCloud,
    Segmenter,
    StageFailure,
    backproject_depth,
    check_ordered,
    hookimpl,
    param,
)
from pipeline.api.perception import (
    TablePlane,
    measure_table,
    resolve_table,
    segment_image,
    segment_points,
)


class TableCluster(Segmenter):
    """Table plane (RANSAC or known height), drop points near it, keep the largest cluster.

    The paper's segmentation (section 6.2.1): every point too close to the table is
    removed, the rest is clustered (DBSCAN, or Euclidean clustering) and the
    largest cluster is the object (``segment_objects`` also keeps every other cluster of at
    least ``min_object_points`` points and ``min_object_area_m2`` of visible surface).
    Output points are in the robot frame with their pixels and the camera's position.

    Too close to the table (``cut``): with ``"fit"``, the table plane is refitted to the
    scene's own table points (:func:`~pipeline.perception.table.measure_table`) and a
    point is cut when it is less than ``cut_sigmas`` times the table's height scatter at
    its distance from the camera (and ``min_cut_m``) above that plane: objects a
    centimetre tall stay, and completed models reach down to the table. ``"fixed"`` cuts
    at ``min_height_m`` above the given plane, the paper's rule.
    """

    name = "table-cluster"

    @dataclass(frozen=True)
    class Params:
        table: Literal["auto", "known", "ransac"] = param(
            "auto",
            "table plane: 'known' = observation.table_height_m, 'ransac' = fit it, "
            "'auto' = known when the observation has it, else RANSAC",
        )
        cut: Literal["fit", "fixed"] = param(
            "fit",
            "which points are the table's: 'fit' = closer to the plane refitted to the "
            "table's points than cut_sigmas times their scatter at that distance from the "
            "camera, 'fixed' = closer than min_height_m to the table plane",
        )
        cut_sigmas: float = param(
            3.0,
            "cut = 'fit': the cut in robust standard deviations of the table's heights",
            above=0.0,
        )
        min_cut_m: float = param(
            0.002,
            "cut = 'fit': never cut lower than this (m): the table of a noise-free view "
            "scatters by rounding errors only, less than anything stands on it",
            at_least=0.0,
        )
        min_height_m: float = param(
            0.02, "cut = 'fixed': drop points closer than this to the table (m)", at_least=0.0
        )
        max_height_m: float = param(
            1.0, "drop points higher than this above the table (m)", above=0.0
        )
        method: Literal["auto", "dbscan", "euclidean", "convex"] = param(
            "auto",
            "clustering: DBSCAN, Euclidean (single linkage, min_points ignored), convex "
            "regions of the depth image cut at concave creases and depth steps (objects that "
            "touch or stand on each other come apart), or auto: DBSCAN for a trial's one "
            "object (the paper's rule), convex for every object of a scene (symfuse complete)",
        )
        eps_m: float = param(0.01, "neighbourhood radius of the clustering (m)", above=0.0)
        min_points: int = param(
            10, "DBSCAN: neighbours (self included) of a core point", at_least=1
        )
        voxel_m: float = param(
            0.0, "voxel side for subsampling before clustering (m; 0 = off)", at_least=0.0
        )
        min_object_points: int = param(
            50, "fail when the largest cluster is smaller than this", at_least=1
        )
        min_object_area_m2: float = param(
            0.002,
            "segment_objects: drop clusters that show the camera less surface than this (m^2; "
            "each pixel counts its footprint at its depth; 0.002 = a 4.5 cm square): debris, "
            "cable ends, fragments of objects cut by the image edge",
            at_least=0.0,
        )
        ransac_inlier_m: float = param(
            0.005, "RANSAC: distance from the plane of an inlier (m)", above=0.0
        )
        ransac_iterations: int = param(200, "RANSAC: random point triples tried", at_least=1)
        ransac_seed: int = param(0, "RANSAC: seed of its random generator", at_least=0)

    @classmethod
    def check_params(cls, params: Params) -> None:
        super().check_params(params)
        check_ordered(params, f"segmenter.{cls.name}", "min_height_m", "max_height_m")
        if params.cut == "fit" and params.min_height_m != cls.Params().min_height_m:
            raise ConfigError(
                f"config key 'segmenter.{cls.name}.min_height_m' is read with cut = 'fixed' "
                f"only (the cut follows the table's fit): set segmenter.{cls.name}.cut = "
                "'fixed' as well"
            )

    def segment(self, observation: DepthObservation) -> PointCloud:
        method = "dbscan" if self.params.method == "auto" else self.params.method
        return self._objects(observation, method)[0]

    def segment_objects(self, observation: DepthObservation) -> tuple[PointCloud, ...]:
        """Every cluster of at least ``min_object_points`` points, the largest first."""
        method = "convex" if self.params.method == "auto" else self.params.method
        return self._objects(observation, method)

    def _objects(self, observation: DepthObservation, method: str) -> tuple[PointCloud, ...]:
        p = self.params
        points, pixels = backproject_depth(
            observation.depth_m, observation.intrinsics, observation.T_robot_camera
        )
        if len(points) == 0:
            raise StageFailure("segmenter 'table-cluster': the depth image has no valid pixel")
        try:
            table = resolve_table(
                points,
                observation.table_height_m,
                p.table,
                np.random.default_rng(p.ransac_seed),
                inlier_distance_m=p.ransac_inlier_m,
                iterations=p.ransac_iterations,
            )
        except ValueError as error:
            raise StageFailure(f"segmenter 'table-cluster': no table plane: {error}") from error
        table, min_height_m, cut_text = self._cut(points, observation, table)
        if method == "convex":
            result = segment_image(
                observation.depth_m,
                observation.intrinsics,
                observation.T_robot_camera,
                table,
                backprojected=(points, pixels),
                min_height_m=min_height_m,
                max_height_m=p.max_height_m,
                eps_m=p.eps_m,
                min_points=p.min_points,
            )
        else:
            result = segment_points(
                points,
                table,
                min_height_m=min_height_m,
                max_height_m=p.max_height_m,
                eps_m=p.eps_m,
                min_points=1 if method == "euclidean" else p.min_points,
                voxel_m=p.voxel_m,
            )
        if len(result.indices) < p.min_object_points:
            raise StageFailure(
                f"segmenter 'table-cluster': largest cluster has {len(result.indices)} points "
                f"(< min_object_points = {p.min_object_points}); {result.above_table} points "
                f"were {cut_text}-{p.max_height_m * 1000:.0f} mm above the table, in "
                f"{result.clusters} clusters"
            )
        k = observation.intrinsics

        def area_m2(indices: np.ndarray) -> float:
            """The surface the points ``indices`` show the camera (m^2): each pixel's
            footprint at its depth."""
            depth = observation.depth_m[pixels[indices, 0], pixels[indices, 1]]
            return float((depth.astype(np.float64) ** 2 / (k.fx * k.fy)).sum())

        viewpoint = observation.T_robot_camera[:3, 3]
        return tuple(
            PointCloud(
                points[indices],
                "robot",
                pixels[indices],
                viewpoint,
                table.z_at(points[indices, :2].mean(axis=0)),
            )
            for rank, indices in enumerate(result.objects)
            if len(indices) >= p.min_object_points
            and (rank == 0 or area_m2(indices) >= p.min_object_area_m2)
        )

    def _cut(
        self, points: np.ndarray, observation: DepthObservation, table: TablePlane
    ) -> tuple[TablePlane, float | np.ndarray, str]:
        """The plane heights are measured from, the cut (m; one, or one per point) and
        the cut's words for an error message."""
        p = self.params
        if p.cut == "fixed":
            return table, p.min_height_m, f"{p.min_height_m * 1000:.0f}"
        viewpoint = observation.T_robot_camera[:3, 3]
        ranges = np.linalg.norm(points - viewpoint, axis=1)
        try:
            fit = measure_table(points, viewpoint, table, p.ransac_inlier_m, ranges_m=ranges)
        except ValueError as error:
            raise StageFailure(
                f"segmenter 'table-cluster': cannot measure the table ({error}); "
                "cut = 'fixed' cuts at min_height_m instead"
            ) from error
        scatter = fit.sigma_at(ranges)
        cut = np.maximum(p.cut_sigmas * scatter, p.min_cut_m)
        return fit.plane, cut, f"{cut.min() * 1000:.1f}..{cut.max() * 1000:.1f}"


@hookimpl
def symfuse_register_stages(registry):
    registry.add(TableCluster)
