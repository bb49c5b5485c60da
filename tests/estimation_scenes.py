"""Tiny synthetic scenes for the estimator tests: a cylinder seen from one side and
grasped by two opposed 6 x 14 taxel pads, and a box on its edge whose mirror plane leans
(helper module, not a test file)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.estimation.correspondences import PointIndex, exclusive_sides, find_correspondences
from pipeline.estimation.covariances import normal_ellipsoids
from pipeline.estimation.geometry import apply_bias, invert_bias
from pipeline.estimation.iekf import FusionProblem, GraspContacts
from pipeline.estimation.measurement import freeze
from pipeline.geometry.poses import rotation_z

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
    scene: CylinderScene | LeaningBoxScene,
    g_init: np.ndarray,
    prior_std: tuple[float, ...] = (0.05, 0.01, 0.01, 0.01, 0.0325, 0.17),
    point_std_m: float = 0.002,
    window_std_m: tuple[float, float] = (0.006, 0.0017),
    noise_std_m: tuple[float, float] = (0.001, 0.003),
    grasps: int = 1,
    reported_across_m: float | None = None,
    reported_pad_m: float | None = None,
    facing: bool = False,
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
        normals=scene.normals if facing else None,
        reported_noise=reported_noise,
        pad_errors_m=pad_errors,
    )
    q = np.zeros((len(g_init), len(g_init)))
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


BOX_HALF_M = (0.03, 0.05, 0.04)
#: The leaning box's pads: (box axis, side, name). The front and back pads sit on the faces
#: parallel to the mirror plane, the others straddle it.
BOX_PADS = (
    (0, -1.0, "front"),
    (0, 1.0, "back"),
    (1, -1.0, "left"),
    (1, 1.0, "right"),
    (2, 1.0, "top"),
)


@dataclass(frozen=True)
class LeaningBoxScene:
    """A box on its edge: its mirror plane across its first axis leans, its unit normal
    ``(cos tilt, 0, sin tilt)`` (elevation ``tilt``) through the box's centre. The camera's
    cloud is the half on the normal's negative side; the hand touched the box after it
    moved by ``g_true``'s bias about ``pivot_m``, with one pad on each face of
    :data:`BOX_PADS` (the back face is the mirror image of the front one)."""

    points_m: np.ndarray
    pivot_m: np.ndarray
    g_true: np.ndarray
    rotation: np.ndarray
    centre_m: np.ndarray
    taxels_m: np.ndarray
    normals: np.ndarray
    pads: np.ndarray

    def surface_distance(self, world_points: np.ndarray) -> np.ndarray:
        """Distance (m) of points in the hand's frame from the true box's surface."""
        unbiased = invert_bias(world_points, self.g_true, self.pivot_m)
        local = np.abs((unbiased - self.centre_m) @ self.rotation) - np.array(BOX_HALF_M)
        outside = np.linalg.norm(np.maximum(local, 0.0), axis=1)
        return outside + np.abs(np.minimum(local.max(axis=1), 0.0))


def leaning_box_scene(
    n_points: int,
    tilt_rad: float,
    bias: tuple[float, float, float, float] = (0.03, 0.003, -0.002, 0.001),
    noise_m: float = 0.0005,
    seed: int = 0,
) -> LeaningBoxScene:
    """The front half of the box's surface, sampled uniformly by area, and 5 x 5 pads."""
    rng = np.random.default_rng(seed)
    half = np.array(BOX_HALF_M)
    c, s = np.cos(tilt_rad), np.sin(tilt_rad)
    rotation = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])  # box axes as columns
    centre = np.array([0.5, 0.02, 0.06])
    # Faces of the half x < 0: (axis, sign, extent along x).
    faces = [(0, -1.0, 1.0), (1, -1.0, 0.5), (1, 1.0, 0.5), (2, -1.0, 0.5), (2, 1.0, 0.5)]
    areas = []
    for axis, _, x_share in faces:
        others = [k for k in range(3) if k != axis]
        extents = [2 * half[k] * (x_share if k == 0 else 1.0) for k in others]
        areas.append(extents[0] * extents[1])
    counts = rng.multinomial(n_points, np.array(areas) / sum(areas))
    local = []
    for (axis, sign, _), count in zip(faces, counts, strict=True):
        sample = rng.uniform(-half, half, (count, 3))
        sample[:, 0] = -np.abs(sample[:, 0])
        sample[:, axis] = sign * half[axis]
        local.append(sample)
    points = np.concatenate(local) @ rotation.T + centre
    points += rng.normal(0.0, noise_m, points.shape)
    pivot = points.mean(axis=0)
    normal = rotation[:, 0]
    g_true = np.array([*bias, float(normal @ centre), 0.0, tilt_rad])
    grid = (np.arange(5) - 2.0) * PITCH_M
    u, v = (a.ravel() for a in np.meshgrid(grid, grid))
    taxels, normals, pads = [], [], []
    for axis, sign, pad in BOX_PADS:
        patch = np.zeros((len(u), 3))
        patch[:, axis] = sign * half[axis]
        others = [k for k in range(3) if k != axis]
        patch[:, others[0]], patch[:, others[1]] = u, v
        inward = np.zeros(3)
        inward[axis] = -sign
        taxels.append(apply_bias(patch @ rotation.T + centre, g_true, pivot))
        normals.append(np.tile(rotation_z(bias[0]) @ rotation @ inward, (len(u), 1)))
        pads.append(np.full(len(u), pad))
    return LeaningBoxScene(
        points_m=points,
        pivot_m=pivot,
        g_true=g_true,
        rotation=rotation,
        centre_m=centre,
        taxels_m=np.concatenate(taxels),
        normals=np.concatenate(normals),
        pads=np.concatenate(pads),
    )


def frozen_measurement(problem: FusionProblem, g: np.ndarray, points: np.ndarray):
    """The first grasp's correspondences found under ``g`` and frozen (the measurement one
    iteration linearises), each taxel on one side only."""
    contacts = problem.grasps[0]
    found = find_correspondences(
        PointIndex(points),
        points,
        g,
        problem.pivot_m,
        contacts.positions_m,
        contacts.window,
        problem.covariance_init,
        alternative=False,
    )
    return freeze(exclusive_sides(found), contacts.positions_m, contacts.noise)


def one_step_and_filterpy(problem: FusionProblem, g: np.ndarray, points: np.ndarray):
    """One structured IEKF step from ``g`` on the first grasp, and the same update by
    filterpy's dense EKF: ``(ours_state, ours_covariance, ekf_state, ekf_covariance)``,
    each state ``g`` followed by the points."""
    from filterpy.kalman import ExtendedKalmanFilter

    from pipeline.estimation.dense import DenseCovariance
    from pipeline.estimation.measurement import linearise
    from pipeline.estimation.structured import StructuredCovariance, block_diagonal

    measurement = frozen_measurement(problem, g, points)
    lin = linearise(measurement, g, points, problem.pivot_m, with_points=True)
    covariance = StructuredCovariance(problem.covariance_init, problem.point_variance_m2)
    gain = covariance.gain(lin, measurement.noise)
    delta_g, moved, delta_p = gain.step(measurement.observation() - lin.prediction)
    covariance.commit(gain, with_points=True)
    ours = np.concatenate([g + delta_g, points.ravel()])
    ours[len(g) :].reshape(-1, 3)[moved] += delta_p

    n = len(points)
    jacobian = np.hstack([lin.bias_plane_jacobian, lin.point_jacobian.dense(n)])
    ekf = ExtendedKalmanFilter(dim_x=len(g) + 3 * n, dim_z=len(jacobian))
    ekf.x = np.concatenate([g, points.ravel()])[:, None]
    ekf.P = DenseCovariance(problem.covariance_init, problem.point_variance_m2).matrix
    ekf.R = block_diagonal(measurement.noise)
    prediction = lin.prediction[:, None]
    ekf.update(measurement.observation()[:, None], lambda x: jacobian, lambda x: prediction)
    return ours, covariance.dense(), ekf.x[:, 0], ekf.P


def structured_and_dense(problem: FusionProblem):
    """Stages 1-2 fused with the structured covariance and with the dense reference (8
    iterations at most), checked to agree in status, iterations and covariance:
    ``(structured, dense)``."""
    from pipeline.estimation.dense import DenseCovariance
    from pipeline.estimation.iekf import IekfSettings, fuse

    settings = IekfSettings(max_iterations=8)
    structured = fuse(problem, settings)
    dense = fuse(problem, settings, covariance_model=DenseCovariance)
    for ours, reference in zip(structured, dense, strict=True):
        assert ours.status == reference.status
        assert ours.iterations == reference.iterations
        np.testing.assert_allclose(ours.covariance, reference.covariance, atol=1e-12)
    return structured, dense
