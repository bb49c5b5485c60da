"""Built-in world ``pybullet``: the object on a table and a Schunk hand, simulated in PyBullet.

The simulation itself lives in :mod:`pipeline.sim` (scene, hands, guarded grasp, camera
rendering); this plugin exposes it through the :class:`pipeline.stages.World` contract. The
simulator is imported when a scene is loaded, not when the plugin is, so listing plugins
stays quick.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline import hookimpl
from pipeline.errors import ConfigError
from pipeline.params import param
from pipeline.stages import World
from pipeline.types import (
    CameraImage,
    CameraIntrinsics,
    GraspOutcome,
    GraspPlan,
    GripperSpec,
    LiftOutcome,
    ObjectPose,
    SceneObject,
    SceneSetup,
    TaxelState,
)

if TYPE_CHECKING:
    from pipeline.sim.world import PybulletWorld


class Pybullet(World):
    """PyBullet physics: table, free object, PG-70 or SDH-2 with taxel pads, TinyRenderer.

    The object is a dynamic body (its catalogue mesh, mass and friction, or its URDF) left
    to settle on the table; the hand's base is held by a constraint and its fingers close
    under position control with force caps, stopping on contact (a guarded close), so the
    object slides or turns as a real one would. Cameras render with TinyRenderer (no GPU),
    taxels are probed with one batched ray test along their normals, pad forces come from
    the contact solver.
    """

    name = "pybullet"
    #: The hands in ``robots/`` (:data:`pipeline.sim.hand_models.HAND_MODELS`; importing
    #: :mod:`pipeline.sim` loads PyBullet, so they are named here; a test keeps the two equal).
    hands = ("pg70", "sdh")
    changes_hands = True

    @dataclass(frozen=True)
    class Params:
        table_height_m: float = param(0.0, "z of the table top in frame R (m)")

    def __init__(self, params: Params | None = None) -> None:
        super().__init__(params)
        self._sim: PybulletWorld | None = None
        self._opening_m = 0.0

    @classmethod
    def create(
        cls,
        obj: SceneObject,
        gripper: str | None = None,
        x: float = 0.0,
        y: float = 0.0,
        yaw: float = 0.0,
        seed: int = 0,
    ) -> Pybullet:
        """A loaded world with ``obj`` at ``(x, y)`` m turned by ``yaw`` rad and, unless
        ``gripper`` is None, that hand added (a shortcut for scripts and tests)."""
        world = cls()
        world.load_scene(SceneSetup(obj, x, y, yaw, seed))
        try:
            if gripper is not None:
                world.add_hand(gripper)
        except BaseException:
            world.close()
            raise
        return world

    @property
    def sim(self) -> PybulletWorld:
        """The underlying :class:`pipeline.sim.world.PybulletWorld` (PyBullet-only code)."""
        if self._sim is None:
            raise ConfigError("world 'pybullet' has no scene yet: call load_scene first")
        return self._sim

    def load_scene(self, setup: SceneSetup) -> None:
        from pipeline.sim.world import PybulletWorld

        self.close()
        urdf_path = getattr(setup.obj, "urdf_path", None)
        self._sim = PybulletWorld.create(
            setup.obj,
            None,
            x=setup.x_m,
            y=setup.y_m,
            yaw=setup.yaw_rad,
            seed=setup.seed,
            table_height_m=self.params.table_height_m,
            urdf_path=Path(urdf_path) if urdf_path is not None else None,
        )
        self.table_height_m = self._sim.table_height_m
        self.rng = self._sim.rng
        self.gripper = None

    def close(self) -> None:
        if self._sim is not None:
            self._sim.close()
            self._sim = None

    def gripper_spec(self, name: str) -> GripperSpec:
        from pipeline.sim.hands import GRIPPERS

        if name not in GRIPPERS:
            hands = ", ".join(self.hands)
            raise ConfigError(f"world 'pybullet' has no hand '{name}' (hands: {hands})")
        return GRIPPERS[name]

    def add_hand(self, name: str) -> None:
        self.sim.add_hand(name)
        self.gripper = self.sim.gripper
        self._opening_m = self.gripper.max_aperture_m

    def remove_hand(self) -> None:
        self.sim.remove_hand()
        self.gripper = None

    def object_pose(self) -> ObjectPose:
        return self.sim.object_pose()

    def render(
        self,
        intrinsics: CameraIntrinsics,
        T_robot_camera: np.ndarray,
        near_m: float,
        far_m: float,
    ) -> CameraImage:
        from pipeline.sim.camera import render

        rendering = render(self.sim.client, intrinsics, T_robot_camera, near_m, far_m)
        return CameraImage(
            rgb=rendering.rgb,
            depth_m=rendering.depth_m,
            object_mask=rendering.segmentation == self.sim.object_id,
        )

    def taxels(self, behind_m: float, beyond_m: float) -> TaxelState:
        return self._hand().taxel_state(self.sim.object_id, behind_m, beyond_m)

    def execute_grasp(self, plan: GraspPlan) -> GraspOutcome:
        self._hand()
        outcome = self.sim.execute_grasp(plan)
        if outcome.executed:
            self._opening_m = plan.opening_m
        return outcome

    def lift(self, height_m: float, hold_s: float) -> LiftOutcome:
        from pipeline.sim.grasping import lift

        return lift(self.sim.client, self._hand(), self.sim.object_id, height_m, hold_s)

    def release(self) -> ObjectPose:
        from pipeline.sim.grasping import release

        hand = self._hand()
        return release(self.sim.client, hand, self.sim.object_id, self._opening_m)

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

    def _hand(self):
        if self.sim.hand is None:
            raise ConfigError("world 'pybullet' has no hand: call add_hand first")
        return self.sim.hand


@hookimpl
def symfuse_register_stages(registry):
    registry.add(Pybullet)
