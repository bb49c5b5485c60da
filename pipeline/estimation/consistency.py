"""Self-diagnosis: does a completed model explain the contacts and the camera's view?

Two checks, each a statistical test at a false-alarm probability ``alpha`` whose scales come
from the measurement model, never from a particular object:

* **Taxels.** Every taxel in contact should lie on the model's surface. Its residual is the
  vector from the taxel to the local surface of the completed model (:func:`surface_residuals`)
  and its normalised innovation squared ``NIS_i = d_i^T (R_i + s^2 I)^-1 d_i`` weighs it by
  the taxel's measurement noise ``R_i`` plus the model surface's own uncertainty ``s`` (one
  cloud point's std). The residual lies along the surface normal, so a consistent taxel's NIS
  is about chi-square with one degree of freedom. Taxels of one pad touch one patch and err
  together (a model 2 mm off moves every taxel of the pad by 2 mm), so they are not
  independent samples: each pad contributes the *mean* NIS of its taxels, one degree of
  freedom, and the statistic ``(1/P) sum_pads mean NIS`` is compared with
  ``chi2_P(1 - alpha) / P`` (:func:`pad_test`).
* **Free space.** A model point that lies in front of what the camera measured on its ray is
  in space the camera saw empty. The model is compared with the image in the camera's frame
  (front points ``p`` and mirrored points ``f_m(p)``, before the bias), and a point counts as
  a violation when it is further in front than the one-sided ``1 - alpha`` quantile of the
  difference of two noisy depths (the measurement and the model point, each with the cloud's
  std): ``z_(1-alpha) sqrt(2) s``. The model contradicts the view when more than
  ``free_space_fraction`` of its points do so (an allowance for the completion near the
  silhouette, where a mirror image of a slightly asymmetric object grazes the visible
  outline).

The kernels are pure: arrays in, numbers out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

# The quantiles straight from scipy.special (what scipy.stats' norm.ppf and chi2.ppf
# evaluate): importing scipy.stats would take longer than a trial's estimate.
from scipy.special import gammaincinv, ndtri

from pipeline.errors import FELL_BACK_STATUSES, estimate_failed
from pipeline.estimation.after_view_term import MEASURED, normalised_innovation
from pipeline.estimation.geometry import invert_side, mirror, side_linear_part, state_normal
from pipeline.estimation.iekf import GraspContacts
from pipeline.perception.visibility import free_space_depths
from pipeline.types import Consistency, DepthObservation, StageEstimate

#: Model points around a taxel that define the local surface it is compared with.
SURFACE_NEIGHBOURS = 8
#: A side's patch further than this from a taxel's pre-image is not searched for (m).
SIDE_SEARCH_M = 0.03
#: A patch whose second principal spread is below this fraction of its first is a line.
FLAT_PATCH_RATIO = 0.1
#: A fused stage that hit the iteration cap is selected over a consistent Stage 0 only when
#: its taxel statistic is at most this share of Stage 0's (docs/method.md §9).
CAPPED_NIS_SHARE = 0.5


@dataclass(frozen=True)
class ConsistencySettings:
    """Thresholds of the self-diagnosis.

    Attributes:
        alpha: false-alarm probability of each test (taxels, free space).
        surface_std_m: std of the model surface (one cloud point's noise), m.
        free_space_fraction: largest share of the model's points allowed in seen free space.
    """

    alpha: float = 0.001
    surface_std_m: float = 0.002
    free_space_fraction: float = 0.02

    @property
    def free_space_tolerance_m(self) -> float:
        """How far in front of the measured surface a model point may lie (m)."""
        return float(ndtri(1.0 - self.alpha) * np.sqrt(2.0) * self.surface_std_m)


def surface_residuals(
    taxels_m: np.ndarray,
    model_m: np.ndarray,
    neighbours: int = SURFACE_NEIGHBOURS,
    tree: cKDTree | None = None,
) -> np.ndarray:
    """Vector from each taxel to the local surface of a model point cloud, (M, 3) metres.

    The local surface is spanned at the centroid ``c`` of the taxel's ``neighbours`` nearest
    model points by their principal directions: the largest always, the second when its
    spread is at least :data:`FLAT_PATCH_RATIO` of the largest (a patch on a single scan
    line spans a line, not a plane, and then the offset across it counts in full). The
    residual is the part of ``c - T`` off that span, plus, for a taxel beyond the edge of
    the patch, the part of its in-span offset that exceeds the patch's radius, so a taxel
    off the side of the model is not measured as touching it.

    Args:
        taxels_m: ``(M, 3)`` taxel positions.
        model_m: ``(N, 3)`` model points, ``N >= 3``.
        neighbours: patch size (at most ``N``).
        tree: a KD-tree over ``model_m`` when the caller has one.
    """
    taxels = np.asarray(taxels_m, dtype=float)
    model = np.asarray(model_m, dtype=float)
    if len(taxels) == 0:
        return np.zeros((0, 3))
    k = min(neighbours, len(model))
    _, nearest = (cKDTree(model, balanced_tree=False) if tree is None else tree).query(taxels, k=k)
    return _patch_residuals(taxels, model[nearest.reshape(len(taxels), k)])


def _patch_residuals(taxels: np.ndarray, patch: np.ndarray) -> np.ndarray:
    """:func:`surface_residuals` of taxels ``(M, 3)`` from their patches ``(M, k, 3)``."""
    centroid = patch.mean(axis=1)
    spread = patch - centroid[:, None, :]
    variances, vectors = np.linalg.eigh(np.einsum("mki,mkj->mij", spread, spread))
    flat = variances[:, 1] >= FLAT_PATCH_RATIO**2 * variances[:, 2]
    span = np.stack([vectors[:, :, 2], np.where(flat[:, None], vectors[:, :, 1], 0.0)], axis=1)
    offset = centroid - taxels
    tangential = np.einsum("msi,ms->mi", span, np.einsum("msi,mi->ms", span, offset))
    in_span = np.einsum("msi,mki->mks", span, spread)
    radius = np.linalg.norm(in_span, axis=2).max(axis=1)
    length = np.linalg.norm(tangential, axis=1)
    beyond = np.clip(length - radius, 0.0, None) / np.where(length > 0.0, length, 1.0)
    return offset - tangential + beyond[:, None] * tangential


def model_residuals(
    taxels_m: np.ndarray,
    points_m: np.ndarray,
    g: np.ndarray,
    pivot_m: np.ndarray,
    tree: cKDTree | None = None,
) -> np.ndarray:
    """:func:`surface_residuals` against the completed model ``{f_b(p)} u {f_mb(p)}``
    without building it, (M, 3) in the hand's frame.

    Both maps are isometries, so each taxel is compared with the points ``p`` at its
    pre-image under either side and the residual is mapped back by the side's linear part;
    the nearer side's residual counts.

    Args:
        taxels_m: ``(M, 3)`` taxel positions, frame R.
        points_m: ``(N, 3)`` the model's points ``p`` (unbiased).
        g: ``(b_theta, b_x, b_y, b_z, m_r, m_theta)``.
        pivot_m: the bias pivot.
        tree: a KD-tree over ``points_m``, or over positions each within millimetres of
            them (the patches are picked by index and take ``points_m``'s coordinates).
    """
    points = np.asarray(points_m, dtype=float)
    tree = cKDTree(points, balanced_tree=False) if tree is None else tree
    k = min(SURFACE_NEIGHBOURS, len(points))
    sides = [
        (invert_side(taxels_m, g, pivot_m, back), side_linear_part(g, back))
        for back in (False, True)
    ]
    # A side whose patch lies beyond the bound is not the taxel's side (bounded queries are
    # cheap; far ones would visit most of the tree); a taxel far from both is searched fully.
    found = [
        tree.query(preimages, k=k, distance_upper_bound=SIDE_SEARCH_M) for preimages, _ in sides
    ]
    reach = np.stack([distance[:, -1] if k > 1 else distance for distance, _ in found])
    lost = ~np.isfinite(reach).any(axis=0)
    if lost.any():
        for (preimages, _), (distance, nearest) in zip(sides, found, strict=True):
            distance[lost], nearest[lost] = tree.query(preimages[lost], k=k)
    best = np.full((len(taxels_m), 3), np.inf)
    for (preimages, linear), (_, nearest) in zip(sides, found, strict=True):
        usable = nearest.reshape(len(taxels_m), k)[:, -1] < len(points)
        if not usable.any():
            continue
        residual = np.full_like(best, np.inf)
        patch = points[nearest.reshape(len(taxels_m), k)[usable]]
        residual[usable] = _patch_residuals(preimages[usable], patch) @ linear.T
        nearer = np.linalg.norm(residual, axis=1) < np.linalg.norm(best, axis=1)
        best[nearer] = residual[nearer]
    return best


def normalised_innovations(
    residuals_m: np.ndarray, noise: np.ndarray, surface_std_m: float
) -> np.ndarray:
    """``d_i^T (R_i + s^2 I)^-1 d_i`` for each residual ``d_i``, (M,).

    Args:
        residuals_m: ``(M, 3)`` taxel-to-surface vectors.
        noise: ``(M, 3, 3)`` taxel measurement covariances ``R_i`` (m^2).
        surface_std_m: std of the model surface ``s`` (m).
    """
    covariance = np.asarray(noise, dtype=float) + surface_std_m**2 * np.eye(3)[None]
    solved = np.linalg.solve(covariance, residuals_m[:, :, None])[:, :, 0]
    return np.einsum("mi,mi->m", residuals_m, solved)


def pad_test(nis: np.ndarray, groups: np.ndarray, alpha: float) -> tuple[float, float]:
    """The pad-averaged NIS and its ``1 - alpha`` threshold.

    Args:
        nis: ``(M,)`` per-taxel NIS.
        groups: ``(M,)`` pad label of each taxel (one group per pad and grasp).
        alpha: false-alarm probability.

    Returns:
        ``(1/P) sum_pads mean_pad(nis)`` and ``chi2_P(1 - alpha) / P`` for ``P`` pads; NaN and
        inf when there is no taxel.
    """
    if len(nis) == 0:
        return float("nan"), float("inf")
    _, group = np.unique(np.asarray(groups), return_inverse=True)
    pads = int(group.max()) + 1
    means = np.bincount(group, weights=nis, minlength=pads) / np.bincount(group, minlength=pads)
    return float(means.mean()), float(2.0 * gammaincinv(pads / 2, 1.0 - alpha) / pads)


def plane_turn_test(
    g: np.ndarray, g_init: np.ndarray, covariance_init: np.ndarray, alpha: float
) -> tuple[float, float]:
    """A fused leaning plane's turn from the initialiser's normal and its bound (rad).

    The prior lets the normal turn by ``s = sqrt(P0[m_phi, m_phi])`` in any direction on
    the sphere (:func:`.problem.plane_angle_stds`), so the turn ``t`` between the fused
    and the initial normal (the sign of a normal carries no meaning) has ``(t / s)^2``
    about chi-square with two degrees of freedom when the touch agrees with the camera;
    the bound is its ``1 - alpha`` quantile (the posterior moves the mean by less than the
    prior's spread, so the test errs on the side of passing). Beyond it the taxels pulled
    the plane where the camera's view does not put it (docs/method.md §1).
    """
    cosine = abs(float(state_normal(g) @ state_normal(g_init)))
    turn = float(np.arccos(min(cosine, 1.0)))
    spread = float(np.sqrt(covariance_init[6, 6]))
    return turn, float(np.sqrt(2.0 * gammaincinv(1.0, 1.0 - alpha))) * spread


def after_view_test(
    grasps: Sequence[GraspContacts], grasp_g: Sequence[np.ndarray], alpha: float
) -> tuple[float, float] | None:
    """The after-views' agreement with a stage's bias: the sum over the grasps with an
    after-view measurement of its normalised innovation at the state ``grasp_g[k]`` the
    grasp's taxels are compared under (:func:`~.after_view_term.normalised_innovation`),
    and its ``1 - alpha`` bound, chi-square with three degrees of freedom per view; None
    when no grasp has one.

    Like the taxel test it weighs the residual by the measurement's own noise, not by the
    stage's uncertainty: the question is whether the bias the touch settled on is a motion
    the camera could have seen.
    """
    views = [
        (contacts.after_view, g_k)
        for contacts, g_k in zip(grasps, grasp_g, strict=True)
        if contacts.after_view is not None
    ]
    if not views:
        return None
    statistic = sum(normalised_innovation(view, g_k) for view, g_k in views)
    dof = len(MEASURED) * len(views)
    return float(statistic), float(2.0 * gammaincinv(dof / 2, 1.0 - alpha))


def free_space_count(depths_m: np.ndarray, tolerance_m: float) -> int:
    """Points further than ``tolerance_m`` in front of the measured surface (see
    :func:`pipeline.perception.visibility.free_space_depths`)."""
    return int(np.count_nonzero(np.asarray(depths_m) > tolerance_m))


def model_free_space_count(
    points_m: np.ndarray, g: np.ndarray, view: DepthObservation, tolerance_m: float
) -> int:
    """How many points of the model as the camera saw it (``p`` and ``f_m(p)``, frame R
    before the bias) lie further than ``tolerance_m`` in front of the measurement."""
    seen = np.vstack([points_m, mirror(points_m, g)])
    depths = free_space_depths(seen, view.depth_m, view.intrinsics, view.T_robot_camera)
    return free_space_count(depths, tolerance_m)


def assess(
    points_m: np.ndarray,
    g: np.ndarray,
    grasp_g: Sequence[np.ndarray],
    pivot_m: np.ndarray,
    grasps: Sequence[GraspContacts],
    view: DepthObservation | None,
    settings: ConsistencySettings,
    tree: cKDTree | None = None,
) -> Consistency:
    """Both checks on one stage's model.

    Args:
        points_m: ``(N, 3)`` the stage's points ``p_n`` (unbiased, frame R).
        g: the stage's final state; its plane completes the model seen by the camera.
        grasp_g: the state ``g`` each grasp's taxels are compared under (the bias differs
            between grasps when the object was re-grasped).
        pivot_m: the bias pivot.
        grasps: the taxels in contact, with their noise ``R``.
        view: the camera's depth image, or None to skip the free-space check.
        settings: the thresholds.
        tree: as for :func:`model_residuals` (every stage can share one tree).
    """
    residuals, nis, groups = [], [], []
    for k, (g_k, contacts) in enumerate(zip(grasp_g, grasps, strict=True)):
        if len(contacts.positions_m) == 0:
            continue
        d = model_residuals(contacts.positions_m, points_m, g_k, pivot_m, tree)
        residuals.append(d)
        nis.append(normalised_innovations(d, contacts.noise, settings.surface_std_m))
        groups.append(np.char.add(f"{k}:", np.asarray(contacts.pads, dtype=str)))
    checks, failures = [], []
    rms_m, statistic, bound = float("nan"), float("nan"), float("inf")
    if residuals:
        checks.append("taxels")
        stacked = np.concatenate(residuals)
        rms_m = float(np.sqrt(np.mean(np.sum(stacked**2, axis=1))))
        statistic, bound = pad_test(np.concatenate(nis), np.concatenate(groups), settings.alpha)
        if not statistic <= bound:
            failures.append(
                f"taxels {rms_m * 1e3:.1f} mm off the model (NIS {statistic:.1f} > {bound:.1f})"
            )
    violations = limit = None
    if view is not None:
        checks.append("free_space")
        violations = model_free_space_count(points_m, g, view, settings.free_space_tolerance_m)
        limit = int(np.floor(settings.free_space_fraction * 2 * len(points_m)))
        if violations > limit:
            failures.append(
                f"{violations} model points in space the camera saw empty (limit {limit})"
            )
    return Consistency(
        checks=tuple(checks),
        taxel_rms_m=rms_m,
        nis=statistic,
        nis_threshold=bound,
        free_space_violations=violations,
        free_space_limit=limit,
        consistent=not failures,
        reason="; ".join(failures),
    )


def with_after_view_test(
    stage: StageEstimate, grasps: Sequence[GraspContacts], alpha: float
) -> StageEstimate:
    """``stage`` with :func:`after_view_test`'s statistic and bound in its consistency: a
    fused stage's only (Stage 0's bias is the initialiser's, not an estimate), when it was
    assessed and some grasp has an after-view."""
    if stage.stage == 0 or stage.consistency is None or len(stage.grasp_g) != len(grasps):
        return stage
    test = after_view_test(grasps, stage.grasp_g, alpha)
    if test is None:
        return stage
    statistic, bound = test
    checked = replace(stage.consistency, after_view_nis=statistic, after_view_threshold=bound)
    return replace(stage, consistency=checked)


def select_stage(stages: Sequence[StageEstimate]) -> tuple[int, str]:
    """The stage the evidence supports best, and why (docs/method.md §9).

    The last stage stands while its model is consistent with the evidence: between two
    models that both pass, the tests cannot say which is closer to the truth. Unless it is
    a bounded hypothesis (:attr:`~pipeline.types.Hypothesis.bounded`) while Stage 0 is
    consistent: its step passes only because it was shortened until it did, so the
    evidence supports no part of it over Stage 0, which is selected. Nor when it hit the
    iteration cap (``max_iterations``) while Stage 0 is consistent and it removed less than
    half of Stage 0's taxel misfit (:data:`CAPPED_NIS_SHARE`): an iteration that did not
    settle claims only what it explains, and a touch it explains barely better than the
    initialiser's model does not support giving that model up. When it is inconsistent, or
    its bias contradicts the after-views (not
    :attr:`~pipeline.types.Consistency.supported`: the touch and the camera's second look
    disagree on how the object moved, so the bias that fits the pads misplaces the object
    away from them; the after-views' statistic counts in the excess, Stage 0 has none),
    the camera ranks first: a model that puts matter where the camera saw
    none is wrong in its shape whatever the taxels say, while taxels off a model the camera
    accepts may be the object's motion between seeing and touching, or the camera's pose
    error (the bias, which Stage 0 does not estimate), or a part that symmetry cannot
    complete (a handle). Among the stages the image accepts, the one with the smallest
    :attr:`~pipeline.types.Consistency.excess` is selected (the later one on a tie); when
    it accepts none, the one with the fewest points in seen free space for its limit, then
    the smallest excess. So fusion never makes the model worse than vision alone without
    saying so.

    Stages without a diagnosis are never selected over the last. A last stage that fell
    back to its prior (``no_correspondence``, ``diverged``) gives way to the last stage
    whose status is not failed.
    """
    last = len(stages) - 1
    if stages[last].status in FELL_BACK_STATUSES:
        # The estimator kept its prior: the "fused" model is vision alone, whatever its
        # diagnosis says, so the stage that last produced an estimate of its own stands.
        kept = [s for s in stages if not estimate_failed(s.status)]
        if kept:
            return kept[-1].stage, (
                f"Stage {last} ended {stages[last].status} and kept its prior; "
                f"Stage {kept[-1].stage} is the last stage that did not fail"
            )
    final = stages[last].consistency
    if final is None:
        return last, "not assessed: the last stage"
    if final.supported:
        initial, hypothesis = stages[0].consistency, stages[last].hypothesis
        if (
            hypothesis is not None
            and hypothesis.bounded
            and initial is not None
            and initial.consistent
        ):
            # The shortened step passes only because it was shortened until it did: the
            # evidence contradicted the hypothesis' own step, and a fraction of it is no
            # measurement, so the consistent Stage 0 is not given up for it.
            return 0, (
                f"Stage {last} keeps {hypothesis.step:.0%} of a '{hypothesis.name}' step "
                f"the evidence contradicts in full; Stage 0 is consistent with it"
            )
        if (
            stages[last].status == "max_iterations"
            and initial is not None
            and initial.consistent
            and final.nis > CAPPED_NIS_SHARE * initial.nis
        ):
            # The iterate is not a fixed point of the fusion: only a clearly better fit to
            # the touch speaks for it, and the consistent Stage 0 explains the touch nearly
            # as well.
            return 0, (
                f"Stage {last} hit the iteration cap and removes less than half of Stage 0's "
                f"taxel misfit (NIS {final.nis:.2f} vs {initial.nis:.2f}); Stage 0 is consistent "
                "with the evidence"
            )
        return last, f"Stage {last} is consistent with the evidence"
    assessed = [s for s in stages if s.consistency is not None]
    seen_right = [s for s in assessed if s.consistency.passes_free_space]
    if seen_right:
        best = min(reversed(seen_right), key=lambda s: s.consistency.excess)
    else:
        best = min(
            reversed(assessed),
            key=lambda s: (s.consistency.free_space_excess, s.consistency.excess),
        )
    if best.stage == last:
        return last, f"no stage is consistent; Stage {last} contradicts the evidence least"
    if best.consistency.supported:
        return best.stage, (
            f"Stage {last} contradicts the evidence ({final.contradictions}); Stage "
            f"{best.stage} is consistent with it"
        )
    if seen_right and not final.passes_free_space:
        return best.stage, (
            f"Stage {last} contradicts the camera ({final.contradictions}); Stage {best.stage} "
            "is the stage the camera accepts that contradicts the taxels least "
            f"({best.consistency.excess:.2f} of the bound)"
        )
    if not seen_right:
        return best.stage, (
            f"no stage passes the camera's test; Stage {best.stage} puts the fewest points "
            f"in seen free space ({best.consistency.free_space_excess:.2f} of the limit vs "
            f"{final.free_space_excess:.2f} for Stage {last})"
        )
    return best.stage, (
        f"Stage {last} contradicts the evidence ({final.contradictions}); Stage {best.stage} "
        f"contradicts it least ({best.consistency.excess:.2f} of the bound vs "
        f"{final.excess:.2f})"
    )
