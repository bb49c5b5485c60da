"""Running the stages in order: fusion on recorded data (:func:`fuse`), and the Stage 0
model of an object without contacts (:func:`initial_estimate`).

The runner talks to stages only through their contracts (``pipeline.stages``) and the
registry; which implementation runs is the config's business.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Iterator, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from pipeline.config import Config
from pipeline.errors import ConfigError, StageFailure
from pipeline.estimation.problem import initial_state, stage_estimate
from pipeline.registry import StageRegistry
from pipeline.stages import Estimator
from pipeline.types import (
    AfterView,
    Bias,
    Contacts,
    DepthObservation,
    EstimateResult,
    EstimationProblem,
    GraspPlan,
    PointCloud,
    SymmetryInit,
    SymmetryPlane,
)


@dataclasses.dataclass(frozen=True)
class FusionRun:
    """The initial state handed to the estimator and what it returned."""

    init: SymmetryInit
    result: EstimateResult


def initialise_from_recording(
    config: Config,
    registry: StageRegistry,
    cloud: PointCloud,
    grasps: Sequence[Contacts],
    plans: Sequence[GraspPlan | None],
    view: DepthObservation | None = None,
) -> SymmetryInit:
    """Run the configured initialiser on a recorded cloud (and ``view``, the depth image it
    came from, when there is one) plus the first grasp's contacts.

    Raises:
        ConfigError: the initialiser needs a depth image, and there is none.
    """
    name = config.choices["initialiser"]
    initialiser = config.create(registry, "initialiser")
    if initialiser.needs_observation and view is None:
        usable = [
            n
            for n in registry.names("initialiser")
            if not registry.get("initialiser", n).cls.needs_observation
        ]
        raise ConfigError(
            f"initialiser '{name}' needs the depth image the cloud came from; give --depth "
            f"FILE, --plane NX,NY,D or --init one of: {', '.join(usable)}"
        )
    proposal = initialiser.propose(cloud, view)
    return initialiser.refine(proposal, cloud, plans[0] if plans else None, grasps[0])


def estimate(
    config: Config,
    registry: StageRegistry,
    cloud: PointCloud,
    init: SymmetryInit,
    grasps: Sequence[Contacts],
    view: DepthObservation | None = None,
    after_views: Sequence[AfterView | None] = (),
) -> EstimateResult:
    """Run the configured estimator from ``init`` over ``grasps`` (in order); ``view``, the
    depth image the cloud came from, lets the estimator check its model against the space
    the camera saw empty; ``after_views``, the camera's view after each grasp (None where
    a grasp has none), measure how the grasps moved the object.

    Raises:
        StageFailure: the initialiser rejected every hypothesis.
    """
    estimator = config.create(registry, "estimator")
    return estimate_with(estimator, cloud, init, grasps, view, after_views)


def estimate_with(
    estimator: Estimator,
    cloud: PointCloud,
    init: SymmetryInit,
    grasps: Sequence[Contacts],
    view: DepthObservation | None = None,
    after_views: Sequence[AfterView | None] = (),
) -> EstimateResult:
    """:func:`estimate` with an estimator already built (a trial builds its stages once).

    Raises:
        StageFailure: the initialiser rejected every hypothesis.
    """
    if init.status != "ok":
        raise StageFailure(f"initialiser gave no usable symmetry plane: {init.reason}")
    problem = EstimationProblem(
        cloud=cloud, init=init, grasps=tuple(grasps), view=view, after_views=tuple(after_views)
    )
    return run_estimator(estimator, problem)


def initial_estimate(cloud: PointCloud, init: SymmetryInit) -> EstimateResult:
    """Stage 0 alone, when there are no contacts to fuse: the cloud and its mirror image
    under ``init`` (the model an estimator starts from; the bias is re-expressed about the
    cloud's centroid as the estimators do). No estimator ran, so the covariance is NaN.

    Raises:
        StageFailure: the initialiser rejected every hypothesis.
    """
    if init.status != "ok":
        raise StageFailure(f"initialiser gave no usable symmetry plane: {init.reason}")
    started = time.perf_counter()
    pivot = np.mean(cloud.points, axis=0)
    g = initial_state(EstimationProblem(cloud=cloud, init=init, grasps=()), pivot)
    covariance = np.full((len(g), len(g)), np.nan)
    seconds = time.perf_counter() - started
    stage = stage_estimate(0, g, covariance, cloud.points, pivot, 0, "initial", seconds, 0)
    return EstimateResult(stages=(stage,))


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block on a single-threaded BLAS.

    A trial's matrices are small (hundreds to thousands of rows): a multi-threaded BLAS
    only contends with itself and with sweep workers. On a loaded 2-core machine a 336-row
    Cholesky is 3.5x slower with two threads than with one, and a ``(2000, 2) @ (2, 200)``
    product (a robust line fit's start) costs 25x the processor time.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        yield


def run_estimator(estimator: Estimator, problem: EstimationProblem) -> EstimateResult:
    """``estimator.estimate(problem)`` on a single-threaded BLAS (:func:`one_blas_thread`)."""
    with one_blas_thread():
        return estimator.estimate(problem)


def fuse(
    config: Config,
    registry: StageRegistry,
    cloud: PointCloud,
    grasps: Sequence[Contacts],
    plans: Sequence[GraspPlan | None] = (),
    plane: SymmetryPlane | None = None,
    view: DepthObservation | None = None,
    after_views: Sequence[AfterView | None] = (),
) -> FusionRun:
    """Fuse a recorded cloud (frame R) with recorded contacts.

    Args:
        plane: the initial symmetry plane; when None the configured initialiser guesses it.
        plans: the recorded grasp plan of each grasp, where known (PS uses it for the bias).
        view: the depth image the cloud came from, its camera pose in frame R, when
            recorded: initialisers that need it can run, and the estimator checks its model
            against the space the camera saw empty, as in a trial.
        after_views: each grasp's after-view, where recorded (docs/after-view.md).
    """
    if plane is not None:
        init = SymmetryInit(plane=plane, bias=Bias(pivot_m=np.mean(cloud.points, axis=0)))
    else:
        init = initialise_from_recording(config, registry, cloud, grasps, plans, view)
    result = estimate(config, registry, cloud, init, grasps, view, after_views)
    return FusionRun(init=init, result=result)
