"""The deviation floor: a stage's points with the true bias and the true mirror plane, scored
against a tilted, turned box where every point's distance is known by hand."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from pipeline.metrics.evaluation import GroundTruth, deviation_floor
from pipeline.types import Bias, StageEstimate, Symmetry, SymmetryPlane

CENTRE = np.array([0.5, 0.0, 0.04])
EXTENTS = (0.04, 0.12, 0.08)
NOISE_M = 0.0005


def _motion() -> np.ndarray:
    """The object's motion since the view: turned 20 deg, tipped 2 deg, moved."""
    motion = np.eye(4)
    motion[:3, :3] = Rotation.from_euler("zx", [20.0, 2.0], degrees=True).as_matrix()
    motion[:3, 3] = np.array([0.01, -0.02, 0.003]) + CENTRE - motion[:3, :3] @ CENTRE
    return motion


def _stage() -> StageEstimate:
    """The box's front face seen from -x, every point NOISE_M off it (in and out in turn),
    with the estimate's plane and bias near the truth."""
    y, z = np.meshgrid(np.linspace(-0.05, 0.05, 21), np.linspace(0.01, 0.07, 13))
    off = np.where(np.arange(y.size) % 2 == 0, NOISE_M, -NOISE_M)
    x0 = CENTRE[0] - EXTENTS[0] / 2
    points = np.column_stack([x0 - off, y.ravel(), z.ravel()])
    plane = SymmetryPlane(theta_rad=0.01, offset_m=CENTRE[0])
    bias = Bias(yaw_rad=np.radians(19.0), pivot_m=points.mean(axis=0))
    return StageEstimate(
        stage=2,
        plane=plane,
        bias=bias,
        covariance=np.eye(6),
        points=points,
        completed=np.vstack([bias.apply(points), bias.apply(plane.mirror(points))]),
        iterations=1,
        status="converged",
        seconds=0.0,
    )


def _truth(motion: np.ndarray | None) -> GroundTruth:
    box = trimesh.creation.box(extents=EXTENTS)
    box.apply_translation(CENTRE)
    moved = np.eye(4) if motion is None else motion
    planes = (
        Symmetry("vertical-plane", [1.0, 0.0, 0.0], CENTRE),
        Symmetry("vertical-plane", [0.0, 1.0, 0.0], CENTRE),
    )
    return GroundTruth(
        vertices=np.asarray(box.vertices) @ moved[:3, :3].T + moved[:3, 3],
        faces=np.asarray(box.faces),
        symmetry="planar",
        plane=None,
        axis_xy_m=CENTRE[:2],
        cloud_motion=motion,
        symmetries=tuple(plane.transformed(moved) for plane in planes),
    )


def test_the_floor_is_the_points_own_error_on_a_tipped_box():
    floor = deviation_floor(_stage(), _truth(_motion()))
    # Each point lies NOISE_M from the front face; its mirror image as far from the back.
    assert floor.count == 2 * 21 * 13
    assert floor.min == pytest.approx(NOISE_M, abs=1e-7)
    assert floor.max == pytest.approx(NOISE_M, abs=1e-7)


def test_no_floor_without_the_cloud_motion():
    assert deviation_floor(_stage(), _truth(None)) is None
