"""The six stage contracts, and the world a trial runs in.

A stage implementation is a class derived from one of the contracts below. It sets
``name`` (the string users put in config), declares its parameters as a nested frozen
dataclass ``Params`` (see :mod:`pipeline.params`), takes an instance of it in ``__init__``,
and implements the contract's method(s). The first paragraph of its docstring is the
one-line description ``symfuse plugins`` prints: keep it short.

Order in a trial (``pipeline.runner``)::

    sensor.observe -> segmenter.segment -> initialiser.propose -> planner.plan
      -> world.execute_grasp -> tactile.read -> initialiser.refine -> estimator.estimate

Every initialiser has both a ``propose`` (before the grasp: enough of a plane to plan with)
and a ``refine`` (after it, with the contacts). PS initialisation does its real work in
``refine`` (docs/method.md §5), VC in ``propose``; the runner never asks which one it has.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar, Protocol

import numpy as np

from .params import NoParams, check_bounds
from .types import (
    Contacts,
    DepthObservation,
    EstimateResult,
    EstimationProblem,
    GraspOutcome,
    GraspPlan,
    GripperSpec,
    ObjectPose,
    PointCloud,
    SymmetryInit,
)

#: The stage kinds, in pipeline order; these are also the config section names.
STAGES = ("sensor", "segmenter", "initialiser", "planner", "tactile", "estimator")


class World(Protocol):
    """A scene with one object on a table and one hand, that can be seen and grasped.

    The PyBullet backend implements it; a robot driver could too. Sensor sources and
    tactile models may require a particular implementation and must say so in a clear
    error when given another.
    """

    gripper: GripperSpec
    table_height_m: float
    rng: np.random.Generator

    def object_pose(self) -> ObjectPose:
        """The object's true pose now."""
        ...

    def execute_grasp(self, plan: GraspPlan) -> GraspOutcome:
        """Pre-grasp, descend, close until contact, settle; report what happened."""
        ...


class StageImplementation(ABC):
    """Common base of every stage implementation."""

    stage: ClassVar[str]
    name: ClassVar[str]
    Params: ClassVar[type] = NoParams

    def __init__(self, params: object | None = None) -> None:
        self.params = self.Params() if params is None else params
        check_bounds(self.params, f"{self.stage}.{self.name}")

    @classmethod
    def description(cls) -> str:
        """The first paragraph of the class docstring, on one line."""
        paragraph = (cls.__doc__ or "").strip().split("\n\n")[0]
        return " ".join(line.strip() for line in paragraph.splitlines())


class SensorSource(StageImplementation):
    """Produces a depth observation of the world."""

    stage = "sensor"

    @abstractmethod
    def observe(self, world: World) -> DepthObservation:
        """Render or capture one depth + colour image; noise uses ``world.rng``."""


class Segmenter(StageImplementation):
    """Cuts the object out of a depth observation."""

    stage = "segmenter"

    @abstractmethod
    def segment(self, observation: DepthObservation) -> PointCloud:
        """Return the object's points in frame R, with their source pixels.

        Raises:
            StageFailure: nothing is left after segmentation.
        """

    def segment_objects(self, observation: DepthObservation) -> tuple[PointCloud, ...]:
        """Every object on the table, the one :meth:`segment` returns first (``symfuse
        complete`` uses this); by default just that one.

        Raises:
            StageFailure: no object is left after segmentation.
        """
        return (self.segment(observation),)


class SymmetryInitialiser(StageImplementation):
    """Guesses the symmetry plane (and, with contacts, the bias): the Stage 0 state."""

    stage = "initialiser"
    #: True when ``propose`` needs the depth image (it cannot run on a bare cloud).
    needs_observation: ClassVar[bool] = False

    @abstractmethod
    def propose(self, cloud: PointCloud, observation: DepthObservation | None) -> SymmetryInit:
        """The plane to plan the grasp with, before any contact."""

    def refine(
        self,
        proposal: SymmetryInit,
        cloud: PointCloud,
        plan: GraspPlan | None,
        contacts: Contacts,
    ) -> SymmetryInit:
        """The Stage 0 state after the first grasp; by default the proposal unchanged.

        ``plan`` is None when the contacts come from a recording without a plan.
        """
        return proposal


class GraspPlanner(StageImplementation):
    """Plans a grasp from the cloud and the proposed plane."""

    stage = "planner"
    #: Names of the hands this planner plans for. With ``trial.gripper = "auto"`` every
    #: installed planner naming an available hand is asked for its best grasp, and the
    #: best-scored feasible plan decides the hand (:mod:`pipeline.hand_choice`).
    grippers: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def plan(self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec) -> GraspPlan:
        """Return a plan; an infeasible one has ``status="refused"`` and a reason."""

    def alternatives(
        self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec
    ) -> tuple[GraspPlan, ...]:
        """Every feasible grasp the planner considers, best first, each as a plan: the
        next grasp of a multi-grasp trial is chosen among them (:mod:`pipeline.next_grasp`).
        By default the one plan of :meth:`plan`, when it is feasible."""
        plan = self.plan(cloud, proposal, gripper)
        return (plan,) if plan.status == "ok" else ()


class TactileModel(StageImplementation):
    """Turns the hand's state after a grasp into taxel contacts."""

    stage = "tactile"

    @abstractmethod
    def read(self, world: World, outcome: GraspOutcome) -> Contacts:
        """Taxels in contact, in frame R, from the hand's final configuration."""


class Estimator(StageImplementation):
    """Fuses the cloud, the initial symmetry and the contacts into Stages 0, 1 and 2."""

    stage = "estimator"

    @abstractmethod
    def estimate(self, problem: EstimationProblem) -> EstimateResult:
        """Return the three stage estimates (0: initial, 1: bias + plane, 2: + points)."""


CONTRACTS: dict[str, type[StageImplementation]] = {
    "sensor": SensorSource,
    "segmenter": Segmenter,
    "initialiser": SymmetryInitialiser,
    "planner": GraspPlanner,
    "tactile": TactileModel,
    "estimator": Estimator,
}
