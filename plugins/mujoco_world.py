"""Built-in world ``mujoco``: the object on a table and a Schunk hand, simulated in MuJoCo.

The simulation lives in :mod:`pipeline.sim.mujoco`; this plugin exposes it through the
:class:`pipeline.stages.World` contract. It needs the optional ``mujoco`` package
(``pip install 'symfuse[mujoco]'``), imported when a scene is loaded, so that listing
plugins works without it and a trial without it says what to install.
"""

from __future__ import annotations

from dataclasses import dataclass
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
    SceneSetup,
    TaxelState,
)

if TYPE_CHECKING:
    from pipeline.sim.mujoco.world import MujocoWorld


class Mujoco(World):
    """MuJoCo physics: table, free object, PG-70 or SDH-2 from the same URDFs, ray-cast camera.

    The same scene as ``pybullet``: the object (its catalogue mesh, mass and friction, with
    convex collision parts) settles on the table; the hand, compiled by MuJoCo from the
    project's URDF, is welded to a moving target and its fingers close under position
    servos with force caps, stopping on contact (the same guarded grasp sequence). Cameras
    are ray cast with ``mj_multiRay`` (no GL context needed), taxels probed with ``mj_ray``
    along their normals, pad forces read from MuJoCo's contacts. An object given as a URDF
    is built from its mesh, mass and friction as the catalogue reads them.
    """

    name = "mujoco"
    #: The hands in ``robots/``, as for the ``pybullet`` world (a test keeps them equal).
    hands = ("pg70", "sdh")
    changes_hands = True

    @dataclass(frozen=True)
    class Params:
        table_height_m: float = param(0.0, "z of the table top in frame R (m)")

    def __init__(self, params: Params | None = None) -> None:
        super().__init__(params)
        self._sim: MujocoWorld | None = None
        self._opening_m = 0.0

    @property
    def sim(self) -> MujocoWorld:
        """The underlying :class:`pipeline.sim.mujoco.world.MujocoWorld`."""
        if self._sim is None:
            raise ConfigError("world 'mujoco' has no scene yet: call load_scene first")
        return self._sim

    def load_scene(self, setup: SceneSetup) -> None:
        try:
            from pipeline.sim.mujoco.world import MujocoWorld
        except ModuleNotFoundError as error:
            if error.name != "mujoco":
                raise
            raise ConfigError(
                "world 'mujoco' needs the mujoco package: pip install 'symfuse[mujoco]'"
            ) from error

        self.close()
        self._sim = MujocoWorld(
            setup.obj,
            x_m=setup.x_m,
            y_m=setup.y_m,
            yaw_rad=setup.yaw_rad,
            table_height_m=self.params.table_height_m,
        )
        self.table_height_m = self._sim.table_height_m
        self.rng = np.random.default_rng(setup.seed)
        self.gripper = None

    def close(self) -> None:
        self._sim = None

    def gripper_spec(self, name: str) -> GripperSpec:
        from pipeline.sim.hand_models import GRIPPERS

        if name not in GRIPPERS:
            hands = ", ".join(self.hands)
            raise ConfigError(f"world 'mujoco' has no hand '{name}' (hands: {hands})")
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

    def render(
        self,
        intrinsics: CameraIntrinsics,
        T_robot_camera: np.ndarray,
        near_m: float,
        far_m: float,
    ) -> CameraImage:
        return self.sim.render(intrinsics, T_robot_camera, near_m, far_m)

    def taxels(self, behind_m: float, beyond_m: float) -> TaxelState:
        return self._hand().taxel_state(self.sim.object_body, behind_m, beyond_m)

    def execute_grasp(self, plan: GraspPlan) -> GraspOutcome:
        self._hand()
        outcome = self.sim.execute_grasp(plan)
        if outcome.executed:
            self._opening_m = plan.opening_m
        return outcome

    def lift(self, height_m: float, hold_s: float) -> LiftOutcome:
        self._hand()
        return self.sim.lift(height_m, hold_s)

    def release(self) -> ObjectPose:
        self._hand()
        return self.sim.release(self._opening_m)

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
            raise ConfigError("world 'mujoco' has no hand: call add_hand first")
        return self.sim.hand


@hookimpl
def symfuse_register_stages(registry):
    registry.add(Mujoco)
