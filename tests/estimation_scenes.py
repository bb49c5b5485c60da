"""Tiny synthetic scenes for the estimator tests: a cylinder seen from one side and
grasped by two opposed 6 x 14 taxel pads (helper module, not a test file)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.estimation.covariances import normal_ellipsoids
from pipeline.estimation.geometry import apply_bias
from pipeline.estimation.iekf import FusionProblem, GraspContacts

RADIUS_M = 0.04
HEIGHT_M = 0.10
PITCH_M = 0.0034


@dataclass(frozen=True)
class CylinderScene:
    """The camera sees the front (x < axis) half of a vertical cylinder whose symmetry
    plane in the camera's view is ``x = 0`` (``m_r = 0, m_theta = 0``); the hand touched the
    object after it moved by ``g_true``'s bias about ``pivot_m``."""

    points_m: np.ndarray
    pivot_m: np.ndarray
    g_true: np.ndarray
    axis_world_m: np.ndarray
    taxels_m: np.ndarray
    normals: np.ndarray
    pads: np.ndarray

    def surface_distance(self, world_points: np.ndarray) -> np.ndarray:
        """Distance (m) of points in the hand's frame to the true cylinder's side."""
        radial = np.linalg.norm(world_points[:, :2] - self.axis_world_m[:2], axis=1)
        return np.abs(radial - RADIUS_M)


def cylinder_scene(
    n_points: int,
    bias: tuple[float, float, float, float] = (0.03, 0.003, -0.002, 0.001),
    noise_m: float = 0.0005,
    contact_depth_m: float = 0.0006,
    seed: int = 0,
) -> CylinderScene:
    """Front half of the cylinder, sampled uniformly, plus the taxels of a grasp along x."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(np.pi / 2, 3 * np.pi / 2, n_points)
    height = rng.uniform(0.0, HEIGHT_M, n_points)
    points = np.column_stack([RADIUS_M * np.cos(angle), RADIUS_M * np.sin(angle), height])
    points += rng.normal(0.0, noise_m, points.shape)
    pivot = points.mean(axis=0)
    g_true = np.array([*bias, 0.0, 0.0])
    axis_world = apply_bias(np.zeros((1, 3)), g_true, pivot)[0]
    rows = (np.arange(14) - 6.5) * PITCH_M + HEIGHT_M / 2
    cols = (np.arange(6) - 2.5) * PITCH_M
    col_grid, row_grid = np.meshgrid(cols, rows)
    sag = RADIUS_M - np.sqrt(RADIUS_M**2 - col_grid**2)
    touching = (sag < contact_depth_m).ravel()
    taxels, normals, pads = [], [], []
    for sign, pad in ((-1.0, "left"), (1.0, "right")):
        grid = np.column_stack(
            [
                np.full(row_grid.size, axis_world[0] + sign * RADIUS_M),
                axis_world[1] + col_grid.ravel(),
                row_grid.ravel(),
            ]
        )[touching]
        taxels.append(grid)
        normals.append(np.tile([-sign, 0.0, 0.0], (len(grid), 1)))
        pads.append(np.full(len(grid), pad))
    return CylinderScene(
        points_m=points,
        pivot_m=pivot,
        g_true=g_true,
        axis_world_m=axis_world,
        taxels_m=np.concatenate(taxels),
        normals=np.concatenate(normals),
        pads=np.concatenate(pads),
    )


def fusion_problem(
    scene: CylinderScene,
    g_init: np.ndarray,
    prior_std: tuple[float, ...] = (0.05, 0.01, 0.01, 0.01, 0.0325, 0.17),
    point_std_m: float = 0.002,
    window_std_m: tuple[float, float] = (0.006, 0.0017),
    noise_std_m: tuple[float, float] = (0.001, 0.003),
    grasps: int = 1,
    reported_across_m: float | None = None,
    reported_pad_m: float | None = None,
) -> FusionProblem:
    """A :class:`FusionProblem` for the scene; ``grasps`` repeats the same contacts. With
    ``reported_across_m`` the reported covariance counts the taxels with that std across
    their normals (else with ``noise_std_m``), with ``reported_pad_m`` also with that error
    along the normals shared by each pad's taxels."""
    reported_noise = pad_errors = None
    if reported_across_m is not None:
        reported_noise = normal_ellipsoids(scene.normals, noise_std_m[0], reported_across_m)
    if reported_pad_m is not None:
        pad_errors = reported_pad_m * scene.normals
    contacts = GraspContacts(
        positions_m=scene.taxels_m,
        pads=scene.pads,
        window=normal_ellipsoids(scene.normals, *window_std_m),
        noise=normal_ellipsoids(scene.normals, *noise_std_m),
        reported_noise=reported_noise,
        pad_errors_m=pad_errors,
    )
    q = np.zeros((6, 6))
    q[[0, 1, 2, 3], [0, 1, 2, 3]] = [0.01**2, 0.002**2, 0.002**2, 0.002**2]
    return FusionProblem(
        points_m=scene.points_m,
        pivot_m=scene.pivot_m,
        g_init=np.asarray(g_init, float),
        covariance_init=np.diag(np.square(prior_std)),
        point_variance_m2=np.full(len(scene.points_m), point_std_m**2),
        grasps=(contacts,) * grasps,
        regrasp_noise=q,
    )
