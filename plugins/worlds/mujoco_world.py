"""Built-in world ``mujoco``: the object on a table and a Schunk hand, simulated in MuJoCo.

The simulation lives in :mod:`pipeline.sim.mujoco`; this plugin exposes it through the
:class:`pipeline.stages.World` contract (what it shares with the ``pybullet`` world in
:class:`pipeline.shipped_hands.ShippedHandsWorld`). It needs the optional ``mujoco`` package
(``pip install 'symfuse[mujoco]'``), imported when a scene is loaded, so that listing
plugins works without it and a trial without it says what to install.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.api import (
    CameraImage,
    CameraIntrinsics,
    ConfigError,
    LiftOutcome,
    ObjectPose,
    SceneSetup,
    TaxelState,
    hookimpl,
)
from pipeline.api.sim import ShippedHandsWorld

if TYPE_CHECKING:
    from pipeline.sim.mujoco.world import MujocoWorld


class Mujoco(ShippedHandsWorld):
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

    @property
    def sim(self) -> MujocoWorld:
        """The underlying :class:`pipeline.sim.mujoco.world.MujocoWorld`."""
        return super().sim

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

    def lift(self, height_m: float, hold_s: float) -> LiftOutcome:
        self._hand()
        return self.sim.lift(height_m, hold_s)

    def release(self) -> ObjectPose:
        self._hand()
        return self.sim.release(self._opening_m)


@hookimpl
def symfuse_register_stages(registry):
    registry.add(Mujoco)
