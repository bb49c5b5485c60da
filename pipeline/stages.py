"""The seven stage contracts: the world a trial runs in, and the six stages that see it,
grasp it and estimate the object.

A stage implementation is a class derived from one of the contracts below. It sets
``name`` (the string users put in config), declares its parameters as a nested frozen
dataclass ``Params`` (see :mod:`pipeline.params`), takes an instance of it in ``__init__``,
and implements the contract's method(s). The first paragraph of its docstring is the
one-line description ``symfuse plugins`` prints: keep it short.

Order in a trial (``pipeline.run.trial``)::

    world.load_scene -> sensor.observe -> segmenter.segment -> initialiser.propose -> planner.plan
      -> world.execute_grasp -> tactile.read -> initialiser.refine -> estimator.estimate

Every initialiser has both a ``propose`` (before the grasp: enough of a plane to plan with)
and a ``refine`` (after it, with the contacts). PS initialisation does its real work in
``refine`` (docs/method.md §5), VC in ``propose``; the runner never asks which one it has.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from types import TracebackType
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from pipeline.errors import ConfigError
from pipeline.params import NoParams, build, check_bounds
from pipeline.types import (
    CameraImage,
    CameraIntrinsics,
    Contacts,
    DepthObservation,
    EstimateResult,
    EstimationProblem,
    GraspOutcome,
    GraspPlan,
    GripperSpec,
    LiftOutcome,
    ObjectPose,
    PointCloud,
    SceneSetup,
    SymmetryInit,
    TaxelState,
)

if TYPE_CHECKING:
    from pipeline.planning.next_grasp import MeasurementModel

STAGES = ("world", "sensor", "segmenter", "initialiser", "planner", "tactile", "estimator")
"""The stage kinds, in pipeline order; these are also the config section names."""


class StageImplementation(ABC):
    """Common base of every stage implementation."""

    stage: ClassVar[str]
    name: ClassVar[str]
    Params: ClassVar[type] = NoParams

    def __init__(self, params: object | None = None) -> None:
        """``params``: a ``Params`` instance, a mapping of (some of) its values as a config
        file gives them (validated like one), or None for the defaults."""
        section = f"{self.stage}.{self.name}"
        if params is None or isinstance(params, Mapping):
            params = build(self.Params, params or {}, section)
        self.params = params
        self.check_params(self.params)

    @classmethod
    def check_params(cls, params: object) -> None:
        """Refuse parameters that do not go together: each within its declared bounds,
        and (an implementation overrides this, calling it first) any pair that makes no
        sense, named by its dotted key. Runs as the implementation is built, and when a
        config is checked without building it (:meth:`pipeline.config.Config.check_stages`).

        Raises:
            ConfigError: naming the key at fault.
        """
        check_bounds(params, f"{cls.stage}.{cls.name}")

    @classmethod
    def description(cls) -> str:
        """The first paragraph of the class docstring, on one line."""
        paragraph = (cls.__doc__ or "").strip().split("\n\n")[0]
        return " ".join(line.strip() for line in paragraph.splitlines())


class World(StageImplementation):
    """One object on a table and one hand: what sensors see, tactile models feel and
    grasps move.

    The built-in ``pybullet`` world simulates it; an analytic scene
    (:mod:`pipeline.testing`), another simulator or a robot driver can implement it too.
    Sensors and tactile models reach the world only through this contract, so they run in
    any world. A world is used as::

        world.load_scene(SceneSetup(obj, x_m, y_m, yaw_rad, seed))
        try:
            ...sense, world.add_hand(name), world.execute_grasp(plan), world.taxels(...)
            ...world.release(), world.execute_grasp(another_plan), world.lift(0.1, 2.0), ...
            ...world.release(), world.remove_hand(), world.add_hand(other), ...
        finally:
            world.close()

    Attributes (valid after :meth:`load_scene`):
        table_height_m: z of the table top in frame R (m).
        rng: the trial's random generator, seeded from ``SceneSetup.seed``; sensor and
            tactile noise draw from it, so a trial is repeatable from its seed.
        gripper: the hand's :class:`GripperSpec` once :meth:`add_hand` ran, else None.
    """

    stage = "world"
    #: Names of the hands :meth:`add_hand` accepts (``trial.gripper`` is checked against
    #: them, and hand choice asks every planner naming one of them).
    hands: ClassVar[tuple[str, ...]] = ()
    #: Whether :meth:`remove_hand` can take the hand out between grasps, so that a later
    #: grasp of a trial with ``trial.gripper = "auto"`` may be made by another hand (a
    #: tool change). A world that cannot keeps the first grasp's hand throughout.
    changes_hands: ClassVar[bool] = False

    table_height_m: float
    rng: np.random.Generator
    gripper: GripperSpec | None = None

    @abstractmethod
    def load_scene(self, setup: SceneSetup) -> None:
        """Build the scene: the table, and ``setup.obj`` standing at rest on it; no hand."""

    def close(self) -> None:
        """Release what the world holds (simulator connection, robot); idempotent."""

    def __enter__(self) -> World:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    @abstractmethod
    def gripper_spec(self, name: str) -> GripperSpec:
        """What planners need to know about the hand ``name`` (one of :attr:`hands`).

        Raises:
            ConfigError: the world has no such hand.
        """

    @abstractmethod
    def add_hand(self, name: str) -> None:
        """Bring the hand ``name`` into the scene, parked where the camera cannot see it.

        Raises:
            ConfigError: unknown hand, or the world has a hand already.
        """

    def remove_hand(self) -> None:
        """Take the hand out of the scene, after :meth:`release`, so that :meth:`add_hand`
        can bring in another (a tool change). Worlds that set :attr:`changes_hands`
        implement it.

        Raises:
            ConfigError: the world cannot change its hand.
        """
        raise ConfigError(f"world '{self.name}' cannot change its hand")

    @abstractmethod
    def object_pose(self) -> ObjectPose:
        """The object's true pose now (its mesh frame in frame R)."""

    @abstractmethod
    def render(
        self,
        intrinsics: CameraIntrinsics,
        T_robot_camera: np.ndarray,
        near_m: float,
        far_m: float,
    ) -> CameraImage:
        """A noise-free picture from a pinhole camera at ``T_robot_camera`` (OpenCV optical
        frame in R): colour, depth along the optical axis, and the object's mask; nothing
        nearer than ``near_m`` or farther than ``far_m`` (m) is seen."""

    @abstractmethod
    def taxels(self, behind_m: float, beyond_m: float) -> TaxelState:
        """Every taxel of the hand now, with the object's distance along each taxel normal
        probed from ``behind_m`` inside the pad to ``beyond_m`` past its surface (m).

        Raises:
            ConfigError: the world has no hand.
        """

    @abstractmethod
    def execute_grasp(self, plan: GraspPlan) -> GraspOutcome:
        """Pre-grasp, descend, close each finger until it touches (a guarded close),
        settle; report what happened. A hand still holding the object releases it first.

        Raises:
            ConfigError: no hand, or the plan is for another hand.
        """

    def lift(self, height_m: float, hold_s: float) -> LiftOutcome:
        """Grip, raise the hand with what it grasped ``height_m`` straight up (+z of frame R),
        hold it still for ``hold_s`` (s) and report whether the object is still held
        (:class:`LiftOutcome`). Optional: ``symfuse sweep graspability`` needs it; the
        simulated worlds implement it with the grasp sequence's
        :func:`pipeline.sim.grasp_sequence.lift`.

        Raises:
            ConfigError: the world cannot lift (the default), or it has no hand.
        """
        raise ConfigError(f"world '{self.name}' cannot lift")

    @classmethod
    def hand_meshes(
        cls,
        gripper: str,
        joint_positions: dict[str, float] | None,
        T_robot_hand: np.ndarray,
        plan: GraspPlan,
    ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``link -> (vertices (V, 3), faces (F, 3), vertex normals (V, 3))`` of the hand
        ``gripper`` in frame R, with its palm at ``T_robot_hand`` and its joints at
        ``joint_positions`` (or, when a run did not record them, opened as ``plan``
        says), to draw a recorded grasp. Empty (the default) when the world cannot draw
        its hands; nothing else depends on it."""
        return {}

    @abstractmethod
    def release(self) -> ObjectPose:
        """Open the hand and withdraw it from the object (the object stays where it is let
        go, free to settle); return the object's pose once it has. A hand that holds
        nothing is withdrawn all the same. After it, :meth:`execute_grasp` may run again.

        Raises:
            ConfigError: the world has no hand.
        """


class SensorSource(StageImplementation):
    """Produces a depth observation of the world."""

    stage = "sensor"

    @abstractmethod
    def observe(self, world: World) -> DepthObservation:
        """Render or capture one depth + colour image; noise uses ``world.rng``."""

    def observe_again(self, world: World, first: DepthObservation) -> DepthObservation | None:
        """The camera that took ``first`` looking at the world again now, through the same
        sensor model (noise, calibration): the after-view while the hand holds the object
        (docs/after-view.md). None, the default, when the sensor cannot look again (a
        recorded capture)."""
        return None


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
    #: best-scored feasible plan decides the hand (:mod:`pipeline.planning.hand_choice`).
    grippers: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def plan(self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec) -> GraspPlan:
        """Return a plan; an infeasible one has ``status="refused"`` and a reason."""

    def alternatives(
        self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec
    ) -> tuple[GraspPlan, ...]:
        """Every feasible grasp the planner considers, best first, each as a plan: the
        next grasp of a multi-grasp trial is chosen among them
        (:mod:`pipeline.planning.next_grasp`).
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

    def measurement_model(self) -> MeasurementModel | None:
        """How this estimator weighs taxels, for the next-grasp information score to predict
        its fusion with (:class:`pipeline.planning.next_grasp.MeasurementModel`); None when it has
        no taxel model of its own (the score then takes an installed estimator's that
        has, :func:`pipeline.run.trial.measurement_model`)."""
        return None


CONTRACTS: dict[str, type[StageImplementation]] = {
    "world": World,
    "sensor": SensorSource,
    "segmenter": Segmenter,
    "initialiser": SymmetryInitialiser,
    "planner": GraspPlanner,
    "tactile": TactileModel,
    "estimator": Estimator,
}
