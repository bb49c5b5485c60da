"""Initialiser ``vc``: the plane hypothesis that best respects the depth image's free space."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from pipeline.api import (
    Bias,
    ConfigError,
    DepthObservation,
    PointCloud,
    StageFailure,
    SymmetryHypothesis,
    SymmetryInit,
    SymmetryInitialiser,
    SymmetryPlane,
    hookimpl,
    param,
)
from pipeline.api.perception import plane_grid, table_axes, visibility_violations


class VcInitialiser(SymmetryInitialiser):
    """VC (visibility constraints): the plane hypothesis with fewest mirrored points in free space.

    The O x D hypotheses are scored by the mirrored points they put in known free space.
    Hypotheses rotate the plane by up to ``max_angle_deg`` about z relative to the seed axis
    and shift it by up to ``max_offset_m`` from the cloud's centroid along the normal
    (docs/method.md §5); on a nearly round footprint (PCA axis length ratio
    ``sqrt(var_a / var_b)`` below ``round_axis_ratio``) the seed axis means nothing, so the
    orientations cover the whole +-90 deg at the same angular step. Each hypothesis
    mirrors the whole cloud, projects it into the depth image with the believed camera pose
    and counts the points lying more than ``tolerance_m`` in front of the measured depth at
    their pixel (table and background pixels are free space too; NaN pixels and points
    outside the image are unknown). Ranking:
    fewest violations, then smallest summed violation depth, then, among hypotheses still
    tied (typically several with no violation at all), the most compact completion
    (:func:`tie_spread`). ``SymmetryInit.hypotheses``
    holds every hypothesis, best first, with ``score`` = fraction of violating points. When
    even the best one exceeds ``max_violation_fraction``, every orientation (+-90 deg at
    the same step) is searched, and when the best of those exceeds
    ``max_violation_fraction_widened`` (a stricter bar: that second look tries twice the
    hypotheses, against the footprint's axes) the result is ``"rejected"``.
    ``refine`` keeps the proposal (zero bias, pivot at the cloud's centroid).

    With ``kind = "evidence"`` VC also fits a vertical rotation axis to the view and proposes
    it when the view supports it at least as well as the best plane
    (:func:`pipeline.symmetry.kinds.choose_kind`); the plane it hands the estimator then
    passes through the axis, facing the camera. When the vertical axis is not chosen, an
    axis of any direction (a body of revolution lying on its side) is proposed when the
    view supports it as well, less ``tilt_margin``; the plane handed on is then the
    vertical one through it. An axis refuted by a part off it (a mug's
    handle) proposes the plane through the axis and that part instead of the best plane,
    when the camera accepts it as well. It also searches mirror planes of any orientation
    and proposes a leaning one when the view supports it better by more than
    ``plane_margin``: the estimator fuses it (``init.symmetry``, kind ``"plane"``), and
    ``init.plane`` stays the best vertical plane. When no vertical plane passes
    (``"rejected"``) but a leaning one does, the rejection carries it and says so: such a
    plane can mirror the view onto itself (a prism's horizontal mid-plane) and complete
    nothing hidden.
    """

    name = "vc"
    needs_observation = True

    @dataclass(frozen=True)
    class Params:
        seed: Literal["major", "view"] = param(
            "major",
            "seed axis contained in the plane: 'major' = the PCA major axis (the paper), "
            "'view' = the PCA axis most perpendicular to the camera's horizontal view",
        )
        max_angle_deg: float = param(
            45.0, "largest plane rotation from the seed (deg)", at_least=0.0, at_most=90.0
        )
        round_axis_ratio: float = param(
            0.0,
            "footprint PCA axis ratio below which all orientations (+-90 deg) are searched "
            "(0 = never); a round object's single view has a ratio near 1, a box's or a car's "
            "above 2 (docs/results.md: the code's own choices)",
            at_least=0.0,
        )
        orientations: int = param(
            19, "number of orientations O (evenly spaced, inclusive)", at_least=1
        )
        max_offset_m: float = param(0.06, "largest plane shift from the centroid (m)", at_least=0.0)
        offsets: int = param(25, "number of offsets D (evenly spaced, inclusive)", at_least=1)
        tolerance_m: float = param(
            0.01,
            "how far in front of the measured depth a mirrored point may lie (m)",
            at_least=0.0,
        )
        max_violation_fraction: float = param(
            0.2,
            "reject when the best hypothesis has a larger fraction of violating points",
            at_least=0.0,
            at_most=1.0,
        )
        max_violation_fraction_widened: float = param(
            0.1,
            "reject a plane only the every-orientation search found (after no plane near "
            "the footprint's axes passed max_violation_fraction) when its fraction of "
            "violating points is larger",
            at_least=0.0,
            at_most=1.0,
        )
        kind: Literal["vertical-plane", "evidence"] = param(
            "vertical-plane",
            "the kind of symmetry proposed: 'vertical-plane' (the paper's) or 'evidence' "
            "(the vertical plane, a rotation axis of any direction or a leaning plane, "
            "whichever the view supports: docs/symmetry.md)",
        )
        max_profile_rms_m: float = param(
            0.003,
            "kind = 'evidence': the largest RMS of the view's slices about an axis candidate's "
            "circles (m)",
            above=0.0,
        )
        kind_margin: float = param(
            0.02,
            "kind = 'evidence': how much larger a share of points in seen free space the "
            "axis completion may have than the plane's and still be chosen",
            at_least=0.0,
            at_most=1.0,
        )
        plane_margin: float = param(
            0.02,
            "kind = 'evidence': how much smaller a share of points in seen free space or "
            "below the table a leaning mirror plane's completion must have than the level "
            "choice's to be chosen (the penalty for its third parameter); 1: never",
            at_least=0.0,
            at_most=1.0,
        )
        tilt_margin: float = param(
            0.0,
            "kind = 'evidence': the penalty for a rotation axis' two further parameters when "
            "it is not vertical (a body of revolution lying on its side): it is chosen when "
            "its sweep's share of points in seen free space or below the table is at most "
            "the level choice's plus kind_margin minus this; 1: vertical axes only",
            at_least=0.0,
            at_most=1.0,
        )

    @classmethod
    def check_params(cls, params: Params) -> None:
        super().check_params(params)
        p = params
        if p.max_angle_deg == 0.0 and p.orientations > 1:
            # The orientations would all be the seed's, and on a round footprint the angular
            # step that extends them to +-90 deg would be 0.
            raise ConfigError(
                f"config key 'initialiser.{cls.name}.max_angle_deg' ({p.max_angle_deg}) must be "
                f"> 0 when orientations ({p.orientations}) > 1"
            )

    def propose(self, cloud: PointCloud, observation: DepthObservation | None) -> SymmetryInit:
        # The hypotheses are generated, scored against the view and ranked in one pass over
        # the same arrays, then the kind of symmetry is chosen on them.
        p = self.params
        if observation is None:
            raise StageFailure("initialiser 'vc' needs the depth image (observation is None)")
        axes = table_axes(cloud.points)
        seed_normal = axes.minor
        if p.seed == "view":
            view = axes.centroid_m - np.asarray(observation.T_robot_camera)[:3, 3]
            if abs(view[:2] @ axes.major[:2]) > abs(view[:2] @ axes.minor[:2]):
                seed_normal = axes.major
        seed_rad = float(np.arctan2(seed_normal[1], seed_normal[0]))
        variance_major, variance_minor = axes.variances_m2
        # On a round footprint the seed axis means nothing: every orientation is searched.
        every = p.orientations > 1 and variance_major < p.round_axis_ratio**2 * variance_minor
        hypotheses = self._ranked(cloud, observation, axes.centroid_m, seed_rad, every)
        narrow = p.orientations > 1 and p.max_angle_deg < 90.0 and not every
        limit, bar = p.max_violation_fraction, "max_violation_fraction"
        if hypotheses[0].score > limit and narrow:
            # No plane near the seed is supported: the object's mirror plane may lie across
            # its major axis (a banana, curved in the view, mirrors end to end), so every
            # orientation is tried before the view is said to support none.
            # That second look, over twice the hypotheses and against the footprint's axes,
            # passes a wrong plane more easily (an L-shaped block's diagonal mirrors one leg
            # onto the other, most of it hidden behind the object), so it has its own bar.
            every = True
            limit, bar = p.max_violation_fraction_widened, "max_violation_fraction_widened"
            hypotheses = self._ranked(cloud, observation, axes.centroid_m, seed_rad, every)
        best = hypotheses[0]
        bias = Bias(pivot_m=axes.centroid_m)
        choice = None
        if p.kind == "evidence":
            # The axis fit needs scipy: listing the plugins must not load it.
            from pipeline.api.symmetry import vc_kind

            choice = vc_kind(cloud.points, observation, best.plane, p)
        if best.score > limit:
            searched = " (every orientation)" if every else ""
            reason = (
                f"the best of {len(hypotheses)} plane hypotheses{searched} puts "
                f"{best.score:.0%} of the mirrored points in seen free space or out of "
                f"view ({bar} = {limit:.0%}): no "
                "mirror plane the view supports, or the true one is nearly parallel to "
                "the viewing direction"
            )
            leaning = choice is not None and choice.symmetry.kind == "plane"
            if leaning:
                # Not proposed: where no vertical plane passes, the plane the wide search
                # finds can mirror the view onto itself and complete nothing hidden (an
                # L-shaped block's horizontal mid-plane, a true symmetry of any prism).
                reason += (
                    "; a leaning mirror plane is supported (init.symmetry), but it is not "
                    "proposed where no vertical plane passes"
                )
            return SymmetryInit(
                plane=best.plane,
                bias=bias,
                hypotheses=hypotheses,
                status="rejected",
                reason=reason,
                symmetry=choice.symmetry if leaning else None,
                kind_scores=choice.scores if choice is not None else {},
            )
        if choice is None:
            return SymmetryInit(plane=best.plane, bias=bias, hypotheses=hypotheses)
        symmetry = choice.symmetry if choice.symmetry.kind != "vertical-plane" else None
        return SymmetryInit(
            choice.plane, bias, hypotheses, symmetry=symmetry, kind_scores=choice.scores
        )

    def _ranked(
        self,
        cloud: PointCloud,
        observation: DepthObservation,
        centroid_m: np.ndarray,
        seed_rad: float,
        every_orientation: bool,
    ) -> tuple[SymmetryHypothesis, ...]:
        """Every hypothesis of the grid about the seed normal ``seed_rad`` and the cloud's
        ``centroid_m`` (frame R), best first; ``every_orientation`` extends the
        orientations to +-90 deg at the same step."""
        p = self.params
        max_angle_deg, orientations = p.max_angle_deg, p.orientations
        if every_orientation:
            step_deg = 2.0 * max_angle_deg / (orientations - 1)
            orientations = int(np.ceil(180.0 / step_deg)) + 1
            max_angle_deg = 90.0
        grid = plane_grid(
            seed_rad,
            centroid_m,
            max_angle_rad=np.deg2rad(max_angle_deg),
            orientations=orientations,
            max_offset_m=p.max_offset_m,
            offsets=p.offsets,
        )
        violations, depth_sum = visibility_violations(
            cloud.points,
            grid.theta_rad.ravel(),
            grid.offset_m.ravel(),
            observation.depth_m,
            observation.intrinsics,
            observation.T_robot_camera,
            tolerance_m=p.tolerance_m,
        )
        theta, offset = grid.theta_rad.ravel(), grid.offset_m.ravel()
        out_of_view = mirrored_out_of_view(
            cloud.points, theta, offset, observation.intrinsics, observation.T_robot_camera
        )
        violations = violations + np.rint(out_of_view * len(cloud)).astype(np.int64)
        camera = np.asarray(observation.T_robot_camera)[:3, 3]
        in_front = camera_side_share(cloud.points, theta, offset, camera) < MIN_CAMERA_SIDE_SHARE
        violations = np.where(in_front, len(cloud), violations)
        spread = tie_spread(cloud.points, theta, offset, violations, depth_sum)
        order = np.lexsort((spread, depth_sum, violations))
        return tuple(
            SymmetryHypothesis(
                plane=SymmetryPlane(float(theta[i]), float(offset[i])),
                score=float(violations[i]) / len(cloud),
                violations=int(violations[i]),
            )
            for i in order
        )


#: Least share of the cloud on the camera's side of a plane hypothesis: a plane in front of
#: every visible point would mirror the object toward the camera, where it was not seen.
MIN_CAMERA_SIDE_SHARE = 0.02


#: Points of the cloud (an even subsample) the out-of-view and in-front checks look at.
CHECK_POINTS = 500


def check_sample(points_m: np.ndarray) -> np.ndarray:
    """At most about :data:`CHECK_POINTS` of the cloud, evenly spread over its order."""
    return np.asarray(points_m)[:: max(1, len(points_m) // CHECK_POINTS)]


def mirrored_out_of_view(
    points_m: np.ndarray,
    theta_rad: np.ndarray,
    offset_m: np.ndarray,
    intrinsics,
    T_robot_camera: np.ndarray,
) -> np.ndarray:
    """``(H,)`` share of the cloud (:func:`check_sample`) each hypothesis mirrors outside
    the image or behind the camera. The camera's view there says nothing for or against
    those points, but an object standing in view has its hidden side in view too: a plane
    that throws part of it out of the picture is not the object's (a can in front of a box
    mirrored toward the camera lands below the image).

    Mirroring is affine, so in camera coordinates ``q' = q - 2 (n . p - m) R^T n``."""
    points = check_sample(points_m)
    T = np.asarray(T_robot_camera, dtype=np.float64)
    q = (points - T[:3, 3]) @ T[:3, :3]
    normals = np.column_stack([np.cos(theta_rad), np.sin(theta_rad), np.zeros(len(theta_rad))])
    twice_signed = 2.0 * (normals[:, :2] @ points[:, :2].T - offset_m[:, None])
    normals_camera = normals @ T[:3, :3]
    x, y, z = (q[None, :, k] - twice_signed * normals_camera[:, k, None] for k in range(3))
    k = intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        u = k.fx * x / z + k.cx
        v = k.fy * y / z + k.cy
    inside = (z > 0.0) & (u > -0.5) & (u < k.width - 0.5) & (v > -0.5) & (v < k.height - 0.5)
    return 1.0 - inside.mean(axis=1)


def camera_side_share(
    points_m: np.ndarray, theta_rad: np.ndarray, offset_m: np.ndarray, camera_m: np.ndarray
) -> np.ndarray:
    """``(H,)`` share of the cloud (:func:`check_sample`) on the camera's side of each
    vertical plane hypothesis."""
    normals = np.column_stack([np.cos(theta_rad), np.sin(theta_rad)])
    signed = normals @ check_sample(points_m)[:, :2].T - offset_m[:, None]
    camera_side = np.sign(normals @ np.asarray(camera_m)[:2] - offset_m)
    return np.mean(signed * camera_side[:, None] > 0.0, axis=1)


def tie_spread(
    points_m: np.ndarray,
    theta_rad: np.ndarray,
    offset_m: np.ndarray,
    violations: np.ndarray,
    depth_sum_m: np.ndarray,
) -> np.ndarray:
    """Mean distance of the cloud from each plane hypothesis tied with the best one (m); 0
    for the others.

    The camera rejects a mirror image only where it lies in seen free space, so a plane far
    behind a round object, whose mirror image hides in the object's shadow, passes as well
    as the right one: on a cylinder several hypotheses of the default grid have no
    violation at all, and the grid's order alone would decide. Between hypotheses the camera
    cannot tell apart, the one whose mirror image lies closest to the seen points completes
    the smallest object that explains the view, the least that must be assumed about the
    hidden side.

    Args:
        points_m: ``(N, 3)`` the cloud, frame R.
        theta_rad, offset_m: ``(H,)`` the hypotheses' planes ``{p : n(theta) . p = offset}``.
        violations, depth_sum_m: ``(H,)`` their violation counts and summed depths.
    """
    best = np.lexsort((depth_sum_m, violations))[0]
    tied = np.flatnonzero((violations == violations[best]) & (depth_sum_m == depth_sum_m[best]))
    spread = np.zeros(len(theta_rad))
    if len(tied) > 1:
        normals = np.stack([np.cos(theta_rad[tied]), np.sin(theta_rad[tied])])
        distances = np.abs(np.asarray(points_m)[:, :2] @ normals - offset_m[tied])
        spread[tied] = distances.mean(axis=0)
    return spread


@hookimpl
def symfuse_register_stages(registry):
    registry.add(VcInitialiser)
