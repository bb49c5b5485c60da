"""Conversions between the stage contract's types and the estimation kernels' arrays."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from pipeline.errors import StageFailure
from pipeline.estimation.covariances import NO_INFORMATION_M, normal_ellipsoids, unit_normals
from pipeline.estimation.geometry import (
    BIAS_PLANE_DIM,
    completed_model,
    normal_derivatives,
    rebase_bias_translation,
    state_normal,
)
from pipeline.types import (
    Bias,
    Consistency,
    Contacts,
    DepthObservation,
    EstimateResult,
    EstimateStatus,
    EstimationProblem,
    IterationState,
    StageEstimate,
    Symmetry,
    SymmetryPlane,
)

if TYPE_CHECKING:  # the kernels (and scipy) load when an estimate runs, not with the plugins
    from pipeline.estimation.consistency import ConsistencySettings
    from pipeline.estimation.hypotheses import Refuse
    from pipeline.estimation.iekf import FusionProblem, GraspContacts, IterationRecord, StageOutcome


def checked_points(problem: EstimationProblem, estimator: str) -> np.ndarray:
    """The cloud's points; raises :class:`StageFailure` when there are none."""
    points = problem.cloud.points
    if len(points) == 0:
        raise StageFailure(f"estimator '{estimator}': the object cloud is empty")
    return points


def initial_state(problem: EstimationProblem, pivot_m: np.ndarray) -> np.ndarray:
    """Stage-0 ``g = (b_theta, b_x, b_y, b_z, m_r, m_theta)`` with the bias re-expressed
    about ``pivot_m`` (the same rigid motion as the initialiser's bias about its own pivot);
    when the initialiser proposes a leaning plane (kind ``"plane"``) the state is that plane,
    ``(b_theta, b_x, b_y, b_z, m_r, m_theta, m_phi)`` (its offset, azimuth and elevation)."""
    init = problem.init
    bias = init.bias
    translation = rebase_bias_translation(bias.yaw_rad, bias.translation_m, bias.pivot_m, pivot_m)
    if init.kind == "plane":
        return np.array([bias.yaw_rad, *translation, *init.symmetry.values])
    return np.array([bias.yaw_rad, *translation, init.plane.offset_m, init.plane.theta_rad])


def grasp_contacts(
    contacts: Contacts,
    window_std_m: tuple[float, float],
    noise_std_m: tuple[float, float],
    facing_filter: bool = True,
) -> GraspContacts:
    """Taxels of one grasp with ``C_t`` and ``R`` built from (along, across) normal stds;
    with ``facing_filter`` their normals are kept for the surface-orientation filter. The
    reported covariance counts each taxel along its normal only (``reported_noise``: the
    same std along it, :data:`~.covariances.NO_INFORMATION_M` across), and counts that std
    once more as an error all taxels of a pad share (``pad_errors_m``: the pad's
    compliance)."""
    from pipeline.estimation.iekf import GraspContacts

    return GraspContacts(
        positions_m=contacts.positions,
        pads=contacts.pads,
        window=normal_ellipsoids(contacts.normals, *window_std_m),
        noise=normal_ellipsoids(contacts.normals, *noise_std_m),
        normals=contacts.normals if facing_filter else None,
        reported_noise=normal_ellipsoids(contacts.normals, noise_std_m[0], NO_INFORMATION_M),
        pad_errors_m=noise_std_m[0] * unit_normals(contacts.normals),
    )


def stage_estimate(
    stage: int,
    g: np.ndarray,
    covariance: np.ndarray,
    points: np.ndarray,
    pivot_m: np.ndarray,
    iterations: int,
    status: EstimateStatus,
    seconds: float,
    active_points: int,
    trace: Sequence[IterationRecord] = (),
    grasp_g: Sequence[np.ndarray] = (),
    filter_covariance: np.ndarray | None = None,
) -> StageEstimate:
    # Twelve parameters: every field of a stage the estimators fill, in one call.
    """A :class:`StageEstimate` with the completed model ``{f_b(p)} u {f_mb(p)}``;
    ``grasp_g`` is the state each grasp's taxels are compared under, ``covariance`` the
    reported one and ``filter_covariance`` the filter's own (None: the same)."""
    completed = completed_model(points, g, pivot_m)
    return StageEstimate(
        stage=stage,
        plane=_plane(g),
        symmetry=general_plane(g, covariance),
        bias=_bias(g, pivot_m),
        covariance=np.array(covariance, dtype=float),
        points=points,
        completed=completed,
        iterations=iterations,
        status=status,
        seconds=seconds,
        active_points=active_points,
        trace=tuple(
            IterationState(
                r.grasp, _plane(r.g), _bias(r.g, pivot_m), r.active_taxels, r.active_points
            )
            for r in trace
        ),
        grasp_g=tuple(np.array(g_k, dtype=float) for g_k in grasp_g),
        filter_covariance=None
        if filter_covariance is None
        else np.array(filter_covariance, dtype=float),
    )


def outcome_estimate(
    stage: int,
    outcome: StageOutcome,
    pivot_m: np.ndarray,
    iterations: int,
    status: EstimateStatus,
    seconds: float,
) -> StageEstimate:
    """:func:`stage_estimate` of a fused ``outcome`` standing as Stage ``stage``, with the
    iterations, status and time it reports (a re-fusion's add the fused stage's)."""
    return stage_estimate(
        stage,
        outcome.g,
        outcome.covariance,
        outcome.points,
        pivot_m,
        iterations,
        status,
        seconds,
        outcome.active_points,
        outcome.trace,
        outcome.grasp_g,
        outcome.filter_covariance,
    )


def _plane(g: np.ndarray) -> SymmetryPlane:
    """The vertical plane of ``g``; of a leaning plane, the vertical plane with its normal's
    azimuth through its point nearest the robot origin (what the paper's consumers read)."""
    if len(g) == BIAS_PLANE_DIM:
        return SymmetryPlane(theta_rad=float(g[5]), offset_m=float(g[4]))
    return SymmetryPlane(theta_rad=float(g[5]), offset_m=float(g[4] * np.cos(g[6])))


def general_plane(g: np.ndarray, covariance: np.ndarray) -> Symmetry | None:
    """A leaning plane's state (seven parameters) as a ``"plane"`` symmetry with the
    ``(m_r, m_azimuth, m_elevation)`` block of ``covariance``; None for the paper's state.

    The symmetry's parameters name the normal with a non-negative elevation; the state may
    hold its opposite, whose offset is ``-m_r``, azimuth ``m_theta + pi`` and elevation
    ``-m_phi``: the covariance's offset and elevation rows and columns then change sign."""
    if len(g) == BIAS_PLANE_DIM:
        return None
    normal = state_normal(g)
    block = np.array(covariance, dtype=float)[4:, 4:]
    x, y, z = normal
    if z < 0.0 or (z == 0.0 and (x < 0.0 or (x == 0.0 and y < 0.0))):
        # Symmetry.values names the opposite normal: m_r and the elevation change sign.
        flip = np.diag([-1.0, 1.0, -1.0])
        block = flip @ block @ flip
    return Symmetry("plane", normal, g[4] * normal, block)


def _bias(g: np.ndarray, pivot_m: np.ndarray) -> Bias:
    return Bias(yaw_rad=float(g[0]), translation_m=g[1:4].copy(), pivot_m=pivot_m.copy())


def estimate_result(
    fusion: FusionProblem,
    outcomes: Sequence[StageOutcome],
    started_s: float,
    view: DepthObservation | None = None,
    consistency: ConsistencySettings | None = None,
    refuse: Refuse | None = None,
) -> EstimateResult:
    # The self-diagnosis's steps (diagnose, condition, replace, select) run in this order on
    # the same stages; each step is its own function, this one keeps their order visible.
    """Stage 0 (the initial state) followed by the fused stages ``outcomes`` (1, then 2).

    Stage 0's time is the setup: the time since ``started_s`` (a ``time.perf_counter()``
    reading taken when the estimator started) less the fused stages' own times, so the
    stages' times add up to the estimator's.

    With ``consistency`` every stage is diagnosed against the taxels (and ``view``, when
    given), a fused stage whose model contradicts the evidence gets the status
    ``inconsistent`` (unless it already failed), and the best-supported stage is selected.
    With ``refuse`` (the estimator's fusion, run on another problem; the paper's
    six-parameter state only) and ``view``, a fused stage that only the free-space test
    flags is first conditioned on free space (:mod:`.free_space_conditioning`); an
    inconsistent fused stage may then be replaced by
    an alternative that passes every test: the fusion again from Stage 0 when the searched
    start's failed (:mod:`.paper_start`), with several grasps the earlier grasps' shape
    located by the last (:mod:`.later_grasps`), then a hypothesis with part of the plane
    held (:func:`.hypotheses.revise`).
    """
    setup_seconds = time.perf_counter() - started_s - sum(o.seconds for o in outcomes)
    initial = stage_estimate(
        0,
        fusion.g_init,
        fusion.covariance_init,
        fusion.points_m,
        fusion.pivot_m,
        0,
        "initial",
        max(setup_seconds, 0.0),
        0,
        grasp_g=[fusion.g_init] * len(fusion.grasps),
    )
    fused = [
        outcome_estimate(stage, o, fusion.pivot_m, o.iterations, o.status, o.seconds)
        for stage, o in enumerate(outcomes, start=1)
    ]
    if consistency is None:
        return EstimateResult(stages=(initial, *fused))
    if len(fusion.g_init) != BIAS_PLANE_DIM:
        # The conditioning and the alternatives hold or search the paper's two plane
        # parameters; a leaning plane's stages are diagnosed and selected, not replaced.
        refuse = None
    # One tree over the unfused points serves every stage: Stage 1 holds them fixed and
    # Stage 2 moves them by millimetres, so their nearest neighbours by index barely change
    # (the patches take the stage's own coordinates). It is the filter's own tree.
    from pipeline.estimation.consistency import assess, select_stage, with_after_view_test
    from pipeline.estimation.free_space_conditioning import condition
    from pipeline.estimation.hypotheses import holdable

    tree = fusion.tree()
    diagnosed = []
    states = [fusion.g_init, *(o.g for o in outcomes)]
    for stage, g in zip((initial, *fused), states, strict=True):
        started = time.perf_counter()
        verdict = assess(
            stage.points, g, stage.grasp_g, fusion.pivot_m, fusion.grasps, view, consistency, tree
        )
        if stage.stage > 0 and len(g) != BIAS_PLANE_DIM:
            verdict = with_plane_turn_test(verdict, g, fusion, consistency.alpha)
        status = stage.status
        if not verdict.consistent and status in ("converged", "max_iterations"):
            status = "inconsistent"
            # Conditioning serves when vision alone is no option: a Stage 0 the taxels
            # accept is held by the hypotheses of §9, which stay near it.
            if (
                refuse is not None
                and view is not None
                and stage.stage > 0
                and not holdable(diagnosed[0], replace(stage, consistency=verdict))
            ):
                stage = condition(fusion, stage, g, verdict, view, consistency, tree) or stage
                if stage.hypothesis is not None:
                    verdict, status = stage.consistency, stage.status
        seconds = stage.seconds + time.perf_counter() - started
        diagnosed.append(replace(stage, consistency=verdict, status=status, seconds=seconds))
    if refuse is not None:
        from pipeline.estimation.hypotheses import revise
        from pipeline.estimation.later_grasps import earlier_shape_stages
        from pipeline.estimation.outlier_pads import outlier_pad_stages
        from pipeline.estimation.paper_start import paper_start_stages

        diagnosed = paper_start_stages(fusion, diagnosed, outcomes, refuse, view, consistency, tree)
        diagnosed = earlier_shape_stages(fusion, diagnosed, refuse, view, consistency, tree)
        diagnosed = revise(fusion, diagnosed, refuse, view, consistency, tree)
        diagnosed = outlier_pad_stages(fusion, diagnosed, refuse, view, consistency, tree)
    diagnosed = [with_after_view_test(s, fusion.grasps, consistency.alpha) for s in diagnosed]
    selected, reason = select_stage(diagnosed)
    return EstimateResult(stages=tuple(diagnosed), selected_stage=selected, selection_reason=reason)


def with_plane_turn_test(
    verdict: Consistency, g: np.ndarray, fusion: FusionProblem, alpha: float
) -> Consistency:
    """``verdict`` with a fused leaning plane's turn from Stage 0's
    (:func:`.consistency.plane_turn_test`); failed when it turned further than its prior
    allows."""
    from pipeline.estimation.consistency import plane_turn_test

    turn, bound = plane_turn_test(g, fusion.g_init, fusion.covariance_init, alpha)
    checked = replace(
        verdict,
        checks=(*verdict.checks, "plane_turn"),
        plane_turn_deg=float(np.degrees(turn)),
        plane_turn_bound_deg=float(np.degrees(bound)),
    )
    if turn <= bound:
        return checked
    failure = (
        f"plane turned {np.degrees(turn):.1f} deg from the camera's (bound {np.degrees(bound):.1f})"
    )
    reason = "; ".join(r for r in (verdict.reason, failure) if r)
    return replace(checked, consistent=False, reason=reason)


def diagonal_covariance(stds: tuple[float, ...]) -> np.ndarray:
    """``diag(stds^2)``."""
    return np.diag(np.square(np.asarray(stds, dtype=float)))


def plane_angle_stds(
    azimuth_std_rad: float, normal_std_rad: float, g: np.ndarray
) -> tuple[float, ...]:
    """Prior stds of the plane's angles in ``g`` (rad): ``(azimuth_std_rad,)`` for the
    paper's vertical plane; for a leaning plane ``(azimuth, elevation)`` stds that let its
    normal turn by ``normal_std_rad`` in any direction on the sphere.

    A step ``da`` of the azimuth turns the normal by ``cos(elevation) da`` and a step of
    the elevation by itself, so the chart's stds are ``normal_std / cos(elevation)`` and
    ``normal_std``. Near the chart's pole (a level plane) the azimuth hardly moves the
    normal: its std is capped where ``cos(elevation)`` falls below ``sin(normal_std)``,
    inside one std of the pole, where every azimuth is as good as another.
    """
    if len(g) == BIAS_PLANE_DIM:
        return (azimuth_std_rad,)
    lever = max(float(np.cos(g[6])), float(np.sin(normal_std_rad)))
    return (normal_std_rad / lever, normal_std_rad)


def bias_plane_covariance(
    stds: tuple[float, ...], g: np.ndarray, pivot_m: np.ndarray
) -> np.ndarray:
    """Prior covariance of ``g`` with the plane's offset uncertainty stated at the object.

    ``stds`` are ``(b_theta, b_x, b_y, b_z, offset, m_theta[, m_phi])`` with ``offset`` the
    std of the plane's distance from ``pivot_m``, independent of the normal's angles.
    ``m_r`` is measured from the robot origin, so ``m_r = offset + n . pivot`` and turning
    the normal moves ``m_r`` by ``n' . pivot`` per radian: with the object half a metre away
    a diagonal prior on ``(m_r, m_theta)`` would put the plane hundreds of millimetres off
    the object for a few tens of degrees of ``m_theta``. The result is
    ``J diag(stds^2) J^T`` with ``J = d(m_r, angles) / d(offset, angles)`` at ``g``.
    """
    jacobian = np.eye(len(g))
    pivot = np.asarray(pivot_m, dtype=float)
    for column, n_prime in enumerate(normal_derivatives(g), start=5):
        jacobian[4, column] = float(n_prime @ pivot)
    return jacobian @ diagonal_covariance(stds) @ jacobian.T
