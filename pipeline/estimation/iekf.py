"""The visuo-tactile iterated EKF (docs/method.md §3, paper eqs. 5-7).

For grasp ``k`` with prior ``x-, P-`` every iteration relinearises around ``x_i``::

    H_i     = dh/dx (x_i)                  (weights recomputed at x_i, then frozen)
    K_i     = P- H_i^T (H_i P- H_i^T + R)^-1
    x_{i+1} = x- + K_i (y - h(x_i) - H_i (x- - x_i))

until the step is below the tolerance or the iteration cap is hit; then
``P+ = (I - K H) P-`` with the last gain (the covariance model decides the algebraic form:
symmetric downdate in :mod:`.structured`, textbook in :mod:`.dense`).

Choices this module makes where the paper is silent:

* **Correspondence covariance.** ``C_i = C_t + J P J^T`` is evaluated at the current state
  but with a covariance ``P`` that is fixed for the whole grasp: Stage 1 uses its prior
  ``P-``, Stage 2 the covariance Stage 1 ended with. (The paper indexes it by iteration,
  eq. 7. On the Fig. 8 study, shrinking the gates to each iterate's posterior
  makes the iteration oscillate: after a large step the narrowed gates lose the back, the
  plane falls back to its prior, the wide gates find the back again, and so on. Fixed gates
  keep one objective per grasp. Wide gates pull the weighted means toward the inside of a
  curved surface, so with ``refine_gates`` (default) Stage 1 then iterates the grasp a
  second time from its result with gates fixed at that first pass's posterior, which
  removes most of that pull (docs/results.md, "The code's own choices"); the first pass
  only has to get there, so it stops at the looser ``gate_tolerance_m``. If the second pass
  diverges or loses its correspondences the first pass's result stands. Stage 2 uses Stage 1's final
  covariance.)
* **Surface filter.** A taxel only weighs points whose surface faces like it, see
  :mod:`.surface` (``GraspContacts.normals``; None gives the paper's eq. 9). On the front
  the test includes the horizontal direction turned by the bias yaw of the state each pass
  started from, so the filter stays fixed within a pass.
* **Trust region.** A Gauss-Newton step that would move some point of the completed model
  by more than ``max_step_m`` is shortened along its direction to that length (a damped
  IEKF), so the weights are recomputed before the model travels further; from a large
  plane error an undamped first step overshoots far past the object.
* **Stages.** Stage 1 holds the points fixed (6 states). Stage 2 estimates points too; like
  the paper it *starts from the Stage-1 result*: each grasp's iterations begin at Stage 1's
  ``(b, m)`` for that grasp and its gates use Stage 1's covariance, but the prior
  ``x-, P-`` is the unfused one (the Stage-0 state, then Stage 2's own posterior), so the
  tactile data is used once per stage and never twice.
* **Several grasps.** ``P-_k = P+_{k-1} + Q`` for ``k >= 2``, ``Q`` on the bias only; the
  first grasp's own motion is already in the initial bias covariance.
* **One side per taxel** (``exclusive_sides``, default on): each taxel keeps only the side
  (front or back) with the larger weight mass, see
  :func:`~.correspondences.exclusive_sides`; off gives the paper's two residuals per taxel.
* **Schedules.** ``standard`` (eq. 9), ``alternative`` (eq. 13) or ``hybrid``: eq. 13 until
  every pad in contact has eq.-9 correspondences on more than one taxel, then eq. 9 for the
  rest of that grasp's iterations.
* **Status** of a grasp: ``converged``; ``max_iterations``; ``no_correspondence`` (at some
  iteration no taxel has any weight) and ``diverged`` (a non-finite state, some component
  of ``(b, m)`` further than ``divergence_sigmas`` prior standard deviations from the
  Stage-0 value, or some point further than ``divergence_sigmas`` of its own prior std from
  its prior position) both leave that grasp's prior state and covariance unchanged. A
  stage's status is the worst of its grasps' in the order diverged > no_correspondence >
  max_iterations > converged. A Stage 2 that ends ``diverged`` or ``no_correspondence``
  reports Stage 1's result (see :func:`fuse`).
* **Convergence** is measured where it matters, on the model: the iteration stops when no
  point of the completed model, front ``f_b(p)`` or mirrored ``f_mb(p)``, moves by more than
  ``tolerance_m`` between iterates (:func:`~.geometry.image_step_bound` plus the largest
  point step). A per-component test on ``g`` would never stop on a cylinder, whose yaw about
  a pivot off its axis trades against a translation and creeps along that weakly observable
  direction by ~1e-4 rad per iteration (a few hundredths of a millimetre on the model).

One module because it is one algorithm: the iteration of a grasp (:func:`update_grasp`),
a stage over the grasps (:func:`run_stage`) and the two stages (:func:`fuse`) carry out the
choices listed above together; the parts that stand alone (correspondences, covariance
models, the surface filter, the geometry) are modules of their own.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Literal, Protocol

import numpy as np
from scipy.spatial import cKDTree

from pipeline.errors import FELL_BACK_STATUSES
from pipeline.estimation.after_view_term import (
    AfterViewMeasurement,
    innovation,
    linearisation,
    passes_gate,
)
from pipeline.estimation.correspondences import (
    Correspondences,
    PointIndex,
    every_pad_supported,
    exclusive_sides,
    find_correspondences,
)
from pipeline.estimation.covariances import shared_pad_noise
from pipeline.estimation.geometry import image_step_bound
from pipeline.estimation.indexsets import union
from pipeline.estimation.measurement import FrozenMeasurement, Linearisation, freeze, linearise
from pipeline.estimation.structured import StructuredCovariance, block_diagonal

Schedule = Literal["standard", "alternative", "hybrid"]
GraspStatus = Literal["converged", "max_iterations", "no_correspondence", "diverged"]
_SEVERITY = ("converged", "max_iterations", "no_correspondence", "diverged")
#: Stage-2 statuses whose result is replaced by Stage 1's (status and counts kept).


class Gain(Protocol):
    def step(self, innovation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def bias_plane_posterior(self) -> np.ndarray: ...


class CovarianceModel(Protocol):
    """What the iteration loop needs from a covariance representation."""

    def bias_plane(self) -> np.ndarray: ...

    def add_bias_plane_noise(self, noise: np.ndarray) -> None: ...

    def gain(self, linearisation: Linearisation, noise: np.ndarray) -> Gain: ...

    def commit(self, gain: Gain, with_points: bool) -> None: ...


@dataclass(frozen=True)
class IekfSettings:
    """Iteration control.

    Attributes:
        schedule: correspondence weights, see the module docstring.
        max_iterations: iteration cap per grasp and stage.
        tolerance_m: convergence when no point of the completed model (front ``f_b(p)`` or
            mirrored ``f_mb(p)``) moves by more than this between iterations (m); see
            :func:`~.geometry.image_step_bound`.
        max_step_m: trust region: an iterate whose completed model would move further than
            this (m) is shortened along its Gauss-Newton direction to this length, so the
            correspondences are re-weighted before the model moves further.
        divergence_sigmas: sane region half-width, in prior standard deviations of ``g`` and
            of each point's position.
        exclusive_sides: explain each taxel by its better-supported side only.
        refine_gates: Stage 1 iterates each grasp a second time with gates narrowed to the
            first pass's posterior (see the module docstring).
        gate_tolerance_m: with ``refine_gates``, the first pass stops once the model moves
            less than this (m); the second pass converges to ``tolerance_m``.
        start_search: when the problem names no ``g_start``, Stage 1's first grasp starts
            at the best state of :func:`~.bias_search.search_start` (the prior stays
            ``g_init``).
    """

    schedule: Schedule = "hybrid"
    max_iterations: int = 30
    tolerance_m: float = 1e-4
    max_step_m: float = 0.02
    divergence_sigmas: float = 10.0
    exclusive_sides: bool = True
    refine_gates: bool = True
    gate_tolerance_m: float = 1e-3
    start_search: bool = False


@dataclass(frozen=True)
class GraspContacts:
    """The taxels of one grasp with their covariances.

    Attributes:
        positions_m: ``(M, 3)`` taxel positions, frame R.
        pads: ``(M,)`` pad id of each taxel.
        window: ``(M, 3, 3)`` correspondence window ``C_t`` (m^2).
        noise: ``(M, 3, 3)`` measurement noise ``R`` (m^2).
        normals: ``(M, 3)`` unit taxel normals for the surface-orientation filter of the
            correspondences (:mod:`.surface`), or None to weigh every point.
        reported_noise: ``(M, 3, 3)`` the noise the reported covariance counts each taxel
            with (m^2; :func:`run_stage`), None for ``noise``.
        pad_errors_m: ``(M, 3)`` the error along its normal that each taxel shares with the
            rest of its pad in the reported covariance, as its std times the normal (m);
            None for none.
        after_view: the camera's view after the grasp as a measurement of the bias
            (:mod:`.after_view_term`), fused before the taxels; None without one.
    """

    positions_m: np.ndarray
    pads: np.ndarray
    window: np.ndarray
    noise: np.ndarray
    normals: np.ndarray | None = None
    reported_noise: np.ndarray | None = None
    pad_errors_m: np.ndarray | None = None
    after_view: AfterViewMeasurement | None = None

    def reported_noise_matrix(self, measurement: FrozenMeasurement) -> np.ndarray:
        """The ``(3B, 3B)`` noise the reported covariance counts ``measurement``'s blocks
        with: each taxel's ``reported_noise`` (else ``noise``) plus the error it shares with
        its pad."""
        taxels = measurement.taxel
        own = self.noise if self.reported_noise is None else self.reported_noise
        noise = block_diagonal(own[taxels])
        if self.pad_errors_m is not None:
            noise += shared_pad_noise(self.pad_errors_m[taxels], np.asarray(self.pads)[taxels])
        return noise


@dataclass(frozen=True)
class FusionProblem:
    """Everything the filter needs, as arrays.

    Attributes:
        points_m: ``(N, 3)`` segmented object points, frame R (Stage 0 ``p_n``).
        pivot_m: ``(3,)`` fixed pivot ``c`` of the bias rotation.
        g_init: ``(6,)`` Stage 0 ``(b_theta, b_x, b_y, b_z, m_r, m_theta)``.
        covariance_init: ``(6, 6)`` prior covariance of ``g``.
        point_variance_m2: ``(N,)`` isotropic prior variance of each point.
        grasps: the grasps in the order they happened.
        regrasp_noise: ``(6, 6)`` ``Q`` added before every grasp after the first.
        g_start: ``(6,)`` where Stage 1's iterations on the first grasp begin (the prior
            stays ``g_init``); None starts at ``g_init``. See :mod:`.bias_search`.
    """

    points_m: np.ndarray
    pivot_m: np.ndarray
    g_init: np.ndarray
    covariance_init: np.ndarray
    point_variance_m2: np.ndarray
    grasps: tuple[GraspContacts, ...]
    regrasp_noise: np.ndarray
    g_start: np.ndarray | None = None
    _tree: list = field(default_factory=list, repr=False, compare=False)

    def tree(self) -> cKDTree:
        """KD-tree over ``points_m``, built on first use and shared by the filter's point
        index and the self-diagnosis (copies made with ``replace`` share it while their
        points are the same array; at a million points a tree costs half a second)."""
        if not self._tree or self._tree[0][0] is not self.points_m:
            self._tree[:] = [(self.points_m, cKDTree(self.points_m, balanced_tree=False))]
        return self._tree[0][1]


@dataclass(frozen=True)
class IterationRecord:
    """``g`` after one iteration, the taxels with support and the points inside some gate."""

    g: np.ndarray
    active_taxels: int
    active_points: int
    grasp: int = 0


@dataclass(frozen=True)
class StageOutcome:
    """Result of one stage.

    Attributes:
        g: final ``(6,)`` bias and plane.
        covariance: final ``(6, 6)`` covariance of ``g`` as the stage reports it: the
            posterior with each taxel counted by its ``reported_noise`` (see
            :func:`run_stage`).
        points: ``(N, 3)`` final points (the Stage-0 array itself in Stage 1).
        status: worst grasp status.
        iterations: iterations summed over grasps.
        active_points: points inside some gate at the last iteration of the last grasp.
        seconds: wall time of the stage.
        grasp_g, grasp_covariance: ``g`` and the filter's own covariance after each grasp
            (Stage 2's gates).
        trace: every iteration's record, over the grasps in order.
        g_start: where Stage 1's iterations on the first grasp began when not at Stage 0
            (:func:`fuse`: the start search's or the problem's ``g_start``; a Stage 2 that
            fell back carries Stage 1's); None: at Stage 0.
    """

    g: np.ndarray
    covariance: np.ndarray
    points: np.ndarray
    status: GraspStatus
    iterations: int
    active_points: int
    seconds: float
    grasp_g: tuple[np.ndarray, ...]
    grasp_covariance: tuple[np.ndarray, ...]
    trace: tuple[IterationRecord, ...] = ()
    g_start: np.ndarray | None = None

    @property
    def filter_covariance(self) -> np.ndarray:
        """The filter's own covariance of ``g`` after the last grasp (``covariance`` when
        no grasp was fused)."""
        return self.grasp_covariance[-1] if self.grasp_covariance else self.covariance


@dataclass(frozen=True)
class _GraspResult:
    g: np.ndarray
    points: np.ndarray
    status: GraspStatus
    iterations: int
    active_points: int
    #: The last iteration's gain, to commit; None when the prior is kept (see the status).
    gain: Gain | None = None
    trace: tuple[IterationRecord, ...] = ()
    #: The last iteration's measurement and linearisation (with ``gain``).
    measurement: FrozenMeasurement | None = None
    linearisation: Linearisation | None = None


def _correspondences(
    index: PointIndex,
    points: np.ndarray,
    g: np.ndarray,
    pivot_m: np.ndarray,
    contacts: GraspContacts,
    gate_covariance: np.ndarray,
    use_alternative: bool,
    exclusive: bool,
    need_pairs: bool,
    facing_g: np.ndarray,
) -> Correspondences:
    # Ten parameters: a numeric kernel given the state, the taxels and the gates as arrays.
    found = find_correspondences(
        index,
        points,
        g,
        pivot_m,
        contacts.positions_m,
        contacts.window,
        gate_covariance,
        alternative=use_alternative,
        need_pairs=need_pairs,
        taxel_normals=contacts.normals,
        facing_g=facing_g,
    )
    return exclusive_sides(found) if exclusive else found


def update_grasp(
    covariance: CovarianceModel,
    index: PointIndex,
    g_prior: np.ndarray,
    points_prior: np.ndarray,
    pivot_m: np.ndarray,
    contacts: GraspContacts,
    settings: IekfSettings,
    move_points: bool,
    g_start: np.ndarray,
    gate_covariance: np.ndarray,
    sane_centre: np.ndarray,
    sane_halfwidth: np.ndarray,
    point_variance_m2: np.ndarray,
) -> _GraspResult:
    # Thirteen parameters: the filter's state, priors and gates for one grasp, as arrays.
    # One loop of Gauss-Newton iterations whose exits (gate, divergence, convergence) all
    # read the same iterate: split, each piece would carry that state back and forth.
    """Iterate one grasp's update (see the module docstring); the caller commits the gain.

    ``points_prior`` is never modified; with ``move_points`` the result holds a new array.
    """
    if len(contacts.positions_m) == 0:
        return _GraspResult(g_prior, points_prior, "no_correspondence", 0, 0)
    g_i = np.array(g_start, dtype=float)
    points_i = points_prior.copy() if move_points else points_prior
    point_limit_m = settings.divergence_sigmas * np.sqrt(point_variance_m2)
    moved = np.empty(0, dtype=np.int64)
    use_alternative = settings.schedule != "standard"
    gain, status = None, "max_iterations"
    iterations = 0
    trace: list[IterationRecord] = []
    correspond = partial(
        _correspondences,
        index,
        pivot_m=pivot_m,
        contacts=contacts,
        gate_covariance=gate_covariance,
        exclusive=settings.exclusive_sides,
        need_pairs=move_points,
        facing_g=g_start,
    )
    for iterations in range(1, settings.max_iterations + 1):
        corr = None
        if settings.schedule == "hybrid" and use_alternative:
            standard = correspond(points_i, g_i, use_alternative=False)
            if every_pad_supported(standard, contacts.pads):
                use_alternative, corr = False, standard
        if corr is None:
            corr = correspond(points_i, g_i, use_alternative=use_alternative)
        if not corr.supported_taxels().any():
            return _GraspResult(g_prior, points_prior, "no_correspondence", iterations, 0)
        measurement = freeze(corr, contacts.positions_m, contacts.noise)
        lin = linearise(measurement, g_i, points_i, pivot_m, with_points=move_points)
        innovation = (
            measurement.observation() - lin.prediction + lin.bias_plane_jacobian @ (g_i - g_prior)
        )
        if move_points:
            innovation += lin.point_jacobian.times_displacement(points_i, points_prior)
        gain = covariance.gain(lin, measurement.noise)
        delta_g, step_points, delta_p = gain.step(innovation)
        g_next = g_prior + delta_g
        touched = union(moved, step_points) if move_points else moved
        before = points_i[touched]
        target = points_prior[touched].copy()
        if move_points:
            target[np.searchsorted(touched, step_points)] += delta_p
        point_steps_m = np.linalg.norm(target - before, axis=1)
        vertices_m, margin_m = index.hull()
        margin_m += index.displacement_bound(points_i)
        model_step_m = image_step_bound(vertices_m, g_i, g_next, pivot_m, margin_m) + float(
            np.max(point_steps_m, initial=0.0)
        )
        if model_step_m > settings.max_step_m:
            fraction = settings.max_step_m / model_step_m
            g_next = g_i + fraction * (g_next - g_i)
            target = before + fraction * (target - before)
            model_step_m = settings.max_step_m
        sane_points = True
        if move_points:
            points_i[touched] = target
            offsets_m = np.linalg.norm(target - points_prior[touched], axis=1)
            sane_points = bool(np.all(offsets_m <= point_limit_m[touched]))
            moved = touched
            index.note_moved(moved)
        sane = sane_points and np.all(np.abs(g_next - sane_centre) <= sane_halfwidth)
        active_taxels = int(np.count_nonzero(corr.supported_taxels()))
        trace.append(IterationRecord(g_next.copy(), active_taxels, corr.active_points().size))
        if not (np.all(np.isfinite(g_next)) and np.isfinite(model_step_m) and sane):
            return _GraspResult(
                g_prior, points_prior, "diverged", iterations, 0, None, tuple(trace)
            )
        g_i = g_next
        if model_step_m < settings.tolerance_m:
            status = "converged"
            break
    active = int(corr.active_points().size)
    return _GraspResult(
        g_i, points_i, status, iterations, active, gain, tuple(trace), measurement, lin
    )


def fuse_after_view(
    covariances: tuple[CovarianceModel, ...],
    index: PointIndex | None,
    g: np.ndarray,
    points: np.ndarray,
    measurement: AfterViewMeasurement,
    with_points: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Condition a grasp's prior ``g``, ``points`` and each of ``covariances`` (the
    filter's and the reported one) on its after-view; unchanged when the innovation is
    outside the gate. The measurement is linear in ``g``: one Kalman update, no iteration.
    Points move only through their covariance with ``g`` (Stage 2, a later grasp); they
    are noted in ``index``. ``with_points`` keeps the downdate's point columns."""
    if not passes_gate(measurement, g, covariances[0].bias_plane()):
        return g, points
    lin = linearisation(measurement, g)
    noise = measurement.noise[None]
    gains = [covariance.gain(lin, noise) for covariance in covariances]
    delta_g, moved, delta_p = gains[0].step(innovation(measurement, g))
    for covariance, gain in zip(covariances, gains, strict=True):
        covariance.commit(gain, with_points)
    if moved.size:
        points = points.copy()
        points[moved] += delta_p
        if index is not None:
            index.note_moved(moved)
    return g + delta_g, points


def worst_status(statuses: list[GraspStatus]) -> GraspStatus:
    """The most severe status; ``no_correspondence`` when there was no grasp at all."""
    return max(statuses, key=_SEVERITY.index) if statuses else "no_correspondence"


def run_stage(
    problem: FusionProblem,
    settings: IekfSettings,
    stage: Literal[1, 2],
    index: PointIndex,
    covariance_model: Callable[[np.ndarray, np.ndarray], CovarianceModel],
    stage_one: StageOutcome | None = None,
) -> StageOutcome:
    # One pass over the grasps in order: the covariances, the divergence bounds and the
    # record each grasp updates are the loop's own state.
    """Run Stage 1 (``stage_one`` None) or Stage 2 (started from ``stage_one``) over all
    grasps in order."""
    started = time.perf_counter()
    covariance = covariance_model(problem.covariance_init, problem.point_variance_m2)
    reported = covariance_model(problem.covariance_init, problem.point_variance_m2)
    halfwidth = settings.divergence_sigmas * np.sqrt(
        np.diag(problem.covariance_init + max(len(problem.grasps) - 1, 0) * problem.regrasp_noise)
    )
    g, points = np.array(problem.g_init, dtype=float), problem.points_m
    statuses, iterations, active = [], 0, 0
    grasp_g, grasp_covariance = [], []
    trace: list[IterationRecord] = []
    for k, contacts in enumerate(problem.grasps):
        if k > 0:
            covariance.add_bias_plane_noise(problem.regrasp_noise)
            reported.add_bias_plane_noise(problem.regrasp_noise)
        if contacts.after_view is not None:
            g, points = fuse_after_view(
                (covariance, reported), index, g, points, contacts.after_view, stage == 2
            )
        if stage == 1:
            g_start, gate = g, covariance.bias_plane()
            if k == 0 and problem.g_start is not None:
                g_start = np.asarray(problem.g_start, dtype=float)
        else:
            g_start, gate = stage_one.grasp_g[k], stage_one.grasp_covariance[k]
        update = partial(
            update_grasp,
            covariance,
            index,
            g,
            points,
            problem.pivot_m,
            contacts,
            move_points=stage == 2,
            sane_centre=problem.g_init,
            sane_halfwidth=halfwidth,
            point_variance_m2=problem.point_variance_m2,
        )
        refine = stage == 1 and settings.refine_gates
        first_pass = settings
        if refine:
            first_pass = replace(settings, tolerance_m=settings.gate_tolerance_m)
        result = update(settings=first_pass, g_start=g_start, gate_covariance=gate)
        if refine and result.gain is not None:
            posterior = result.gain.bias_plane_posterior()
            refined = update(settings=settings, g_start=result.g, gate_covariance=posterior)
            if refined.gain is not None:
                result = replace(
                    refined,
                    iterations=result.iterations + refined.iterations,
                    trace=result.trace + refined.trace,
                )
        if result.gain is not None:
            keep_points = stage == 2 and k < len(problem.grasps) - 1
            covariance.commit(result.gain, with_points=keep_points)
            noise = contacts.reported_noise_matrix(result.measurement)
            reported.commit(reported.gain(result.linearisation, noise), with_points=keep_points)
        g, points = result.g, result.points
        statuses.append(result.status)
        iterations += result.iterations
        active = result.active_points
        grasp_g.append(g.copy())
        grasp_covariance.append(covariance.bias_plane())
        trace += [replace(record, grasp=k) for record in result.trace]
    return StageOutcome(
        g=g,
        covariance=reported.bias_plane(),
        points=points,
        status=worst_status(statuses),
        iterations=iterations,
        active_points=active,
        seconds=time.perf_counter() - started,
        grasp_g=tuple(grasp_g),
        grasp_covariance=tuple(grasp_covariance),
        trace=tuple(trace),
    )


def fuse(
    problem: FusionProblem,
    settings: IekfSettings,
    last_stage: Literal[1, 2] = 2,
    covariance_model: Callable[[np.ndarray, np.ndarray], CovarianceModel] = StructuredCovariance,
) -> tuple[StageOutcome, ...]:
    """Stages 1 (and 2) of the visuo-tactile IEKF.

    Args:
        problem: the arrays to fuse.
        settings: iteration control.
        last_stage: 1 to stop after bias + plane, 2 to also estimate the points.
        covariance_model: :class:`~.structured.StructuredCovariance` (default) or
            :class:`~.dense.DenseCovariance` (the reference).

    Returns:
        The Stage 1 outcome, then the Stage 2 outcome when ``last_stage == 2``. The KD-tree
        over the points is built once and its time, and the start search's, is counted in
        Stage 1. When Stage 2
        diverges or loses every correspondence its outcome carries Stage 1's state,
        covariance and points (with Stage 2's status, iterations and time), so a failed
        point update never makes the model worse than Stage 1.
    """
    started = time.perf_counter()
    if settings.start_search and problem.g_start is None:
        from pipeline.estimation.bias_search import SearchSettings, search_start

        searched = after_first_view(problem, covariance_model)
        problem = replace(problem, g_start=search_start(searched, SearchSettings()))
    index = PointIndex(problem.points_m, problem.tree())
    build_seconds = time.perf_counter() - started
    stage_one = run_stage(problem, settings, 1, index, covariance_model)
    stage_one = replace(
        stage_one, seconds=stage_one.seconds + build_seconds, g_start=problem.g_start
    )
    if last_stage == 1:
        return (stage_one,)
    stage_two = run_stage(problem, settings, 2, index, covariance_model, stage_one)
    if stage_two.status in FELL_BACK_STATUSES:
        stage_two = replace(
            stage_one,
            status=stage_two.status,
            iterations=stage_two.iterations,
            seconds=stage_two.seconds,
            active_points=stage_two.active_points,
            trace=stage_two.trace,
        )
    return stage_one, stage_two


def after_first_view(
    problem: FusionProblem,
    covariance_model: Callable[[np.ndarray, np.ndarray], CovarianceModel] = StructuredCovariance,
) -> FusionProblem:
    """``problem`` with its prior conditioned on the first grasp's after-view, where the
    start search looks (the filter conditions its own prior in :func:`run_stage`)."""
    if not problem.grasps or problem.grasps[0].after_view is None:
        return problem
    covariance = covariance_model(problem.covariance_init, np.zeros(0))
    g, _ = fuse_after_view(
        (covariance,), None, problem.g_init, problem.points_m, problem.grasps[0].after_view, False
    )
    return replace(problem, g_init=g, covariance_init=covariance.bias_plane())
