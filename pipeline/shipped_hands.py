"""What the built-in simulated worlds share: the hands shipped in ``robots/`` and the calls
that only pass through to the engine's scene.

:class:`ShippedHandsWorld` is the :class:`~pipeline.stages.World` part of the ``pybullet``
and ``mujoco`` worlds that does not depend on the engine: the hands it offers and their
:class:`~pipeline.types.GripperSpec`, the hand's links for drawing, and the checks that a
scene and a hand are there. A subclass holds its engine's scene in ``_sim`` and adds what
the engine does (loading a scene, rendering, reading taxels, releasing). Nothing here
imports a simulator, so listing the plugins stays quick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from pipeline.errors import ConfigError
from pipeline.params import param
from pipeline.stages import World
from pipeline.types import GraspOutcome, GraspPlan, GripperSpec, ObjectPose


class ShippedHandsWorld(World):
    """A simulated world with the hands of ``robots/`` (its subclasses name the engine).

    The engine's scene (``_sim``) offers ``add_hand(name)``, ``remove_hand()``,
    ``object_pose()``, ``execute_grasp(plan)`` and ``hand`` (None without one).
    """

    #: The hands in ``robots/`` (:data:`pipeline.sim.hand_models.HAND_MODELS`; importing
    #: :mod:`pipeline.sim` loads PyBullet, so they are named here; a test keeps the two equal),
    #: then :attr:`extra_hands`.
    hands: ClassVar[tuple[str, ...]] = ("pg70", "sdh")
    #: Parallel grippers a subclass adds, by name: their URDFs (a path, or a file of
    #: ``robots/``; docs/hands.md), loaded as the shipped ones are
    #: (:func:`pipeline.sim.hand_models.add_parallel_hand`).
    extra_hands: ClassVar[dict[str, str]] = {}
    changes_hands = True

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.hands = tuple(dict.fromkeys((*cls.hands, *cls.extra_hands)))

    @dataclass(frozen=True)
    class Params:
        table_height_m: float = param(0.0, "z of the table top in frame R (m)")

    def __init__(self, params: Params | None = None) -> None:
        super().__init__(params)
        self._sim: Any = None
        self._opening_m = 0.0

    @property
    def sim(self) -> Any:
        """The engine's scene (engine-only code).

        Raises:
            ConfigError: no scene is loaded.
        """
        if self._sim is None:
            raise ConfigError(f"world '{self.name}' has no scene yet: call load_scene first")
        return self._sim

    def gripper_spec(self, name: str) -> GripperSpec:
        from pipeline.sim.hand_models import GRIPPERS, add_parallel_hand

        if name in self.extra_hands:
            try:
                return add_parallel_hand(name, self.extra_hands[name])
            except ConfigError as error:
                raise ConfigError(f"world '{self.name}': {error}") from None
        if name not in self.hands or name not in GRIPPERS:
            hands = ", ".join(self.hands)
            raise ConfigError(f"world '{self.name}' has no hand '{name}' (hands: {hands})")
        return GRIPPERS[name]

    def add_hand(self, name: str) -> None:
        self.gripper_spec(name)
        self.sim.add_hand(name)
        self.gripper = self._hand().spec
        self._opening_m = self.gripper.max_aperture_m

    def remove_hand(self) -> None:
        self.sim.remove_hand()
        self.gripper = None

    def object_pose(self) -> ObjectPose:
        return self.sim.object_pose()

    def execute_grasp(self, plan: GraspPlan) -> GraspOutcome:
        self._hand()
        outcome = self.sim.execute_grasp(plan)
        if outcome.executed:
            self._opening_m = plan.opening_m
        return outcome

    @classmethod
    def hand_meshes(
        cls,
        gripper: str,
        joint_positions: dict[str, float] | None,
        T_robot_hand: np.ndarray,
        plan: GraspPlan,
    ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Each link of a shipped hand from its URDF
        (:func:`pipeline.sim.hand_models.hand_link_meshes`)."""
        from pipeline.sim.hand_models import hand_link_meshes

        return hand_link_meshes(gripper, joint_positions, T_robot_hand, plan)

    def _hand(self) -> Any:
        """The engine's hand in the scene.

        Raises:
            ConfigError: no hand was added.
        """
        if self.sim.hand is None:
            raise ConfigError(f"world '{self.name}' has no hand: call add_hand first")
        return self.sim.hand
