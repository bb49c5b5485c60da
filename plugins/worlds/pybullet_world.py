"""Built-in world ``pybullet``: the object on a table and a Schunk hand, simulated in PyBullet.

The simulation itself lives in :mod:`pipeline.sim` (scene, hands, guarded grasp, camera
rendering); this plugin exposes it through the :class:`pipeline.stages.World` contract, with
what it shares with the ``mujoco`` world in :class:`pipeline.shipped_hands.ShippedHandsWorld`.
The simulator is imported when a scene is loaded, not when the plugin is, so listing plugins
stays quick.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.api import (
    CameraImage,
    CameraIntrinsics,
    LiftOutcome,
    ObjectPose,
    SceneObject,
    SceneSetup,
    TaxelState,
    hookimpl,
)
from pipeline.api.sim import ShippedHandsWorld

if TYPE_CHECKING:
    from pipeline.sim.world import PybulletWorld


class Pybullet(ShippedHandsWorld):
    """PyBullet physics: table, free object, PG-70 or SDH-2 with taxel pads, TinyRenderer.

    The object is a dynamic body (its catalogue mesh, mass and friction, or its URDF) left
    to settle on the table; the hand's base is held by a constraint and its fingers close
    under position control with force caps, stopping on contact (a guarded close), so the
    object slides or turns as a real one would. Cameras render with TinyRenderer (no GPU),
    taxels are probed with one batched ray test along their normals, pad forces come from
    the contact solver.
    """

    name = "pybullet"

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
        return super().sim

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

    def lift(self, height_m: float, hold_s: float) -> LiftOutcome:
        from pipeline.sim.grasping import lift

        return lift(self.sim.client, self._hand(), self.sim.object_id, height_m, hold_s)

    def release(self) -> ObjectPose:
        from pipeline.sim.grasping import release

        hand = self._hand()
        return release(self.sim.client, hand, self.sim.object_id, self._opening_m)


@hookimpl
def symfuse_register_stages(registry):
    registry.add(Pybullet)
