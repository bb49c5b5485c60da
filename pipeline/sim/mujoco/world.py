"""The MuJoCo world: one object on the table and at most one hand, as the built-in
``mujoco`` world plugin (:mod:`plugins.worlds.mujoco_world`) exposes it through the
:class:`pipeline.stages.World` contract.

The model is compiled from the scene (:func:`pipeline.sim.mujoco.scene.build_model`)
when the world is built and again when a hand comes or goes; the object's state carries
over. Grasps run the engine-neutral sequence of :mod:`pipeline.sim.grasp_sequence`, each
of its 1/240 s steps made of several MuJoCo steps (:class:`MujocoPhysics`).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError
from pipeline.sim import grasp_sequence
from pipeline.sim.bodies import MAX_SETTLE_STEPS, REST_SPEED_M_S, REST_SPIN_RAD_S, SETTLE_STEPS
from pipeline.sim.grasp_sequence import GraspSettings
from pipeline.sim.mujoco.camera import ray_cast
from pipeline.sim.mujoco.hand import MujocoHand
from pipeline.sim.mujoco.scene import OBJECT_BODY, TIMESTEP_S, ObjectBody, build_model
from pipeline.types import (
    CameraImage,
    CameraIntrinsics,
    GraspOutcome,
    GraspPlan,
    LiftOutcome,
    ObjectPose,
    SceneObject,
)

#: The time step of the settling and of the grasp sequence when it does not set one (s).
SEQUENCE_STEP_S = 1.0 / 240.0


class MujocoPhysics:
    """The world as :class:`pipeline.sim.grasp_sequence.Physics`: a step of the sequence
    is the nearest whole number of MuJoCo steps (:data:`~.scene.TIMESTEP_S`)."""

    def __init__(self, world: MujocoWorld) -> None:
        self.world = world
        self.object_id = world.object_body
        self._substeps = world.substeps(SEQUENCE_STEP_S)

    def step(self, steps: int = 1) -> None:
        mujoco.mj_step(self.world.model, self.world.data, nstep=steps * self._substeps)

    def detect_collisions(self) -> None:
        mujoco.mj_forward(self.world.model, self.world.data)

    def object_pose(self) -> ObjectPose:
        return self.world.object_pose()

    @contextmanager
    def timestep(self, timestep_s: float) -> Iterator[None]:
        previous = self._substeps
        self._substeps = self.world.substeps(timestep_s)
        try:
            yield
        finally:
            self._substeps = previous


class MujocoWorld:
    """A MuJoCo model of the table, one object and (optionally) one hand, and its state.

    Attributes:
        model, data: the compiled ``MjModel`` and its ``MjData``.
        hand: the loaded :class:`~pipeline.sim.mujoco.hand.MujocoHand`, or None.
        object_body: the object's body id.
        table_height_m: z of the table top in frame R.
    """

    def __init__(
        self,
        obj: SceneObject,
        x_m: float = 0.0,
        y_m: float = 0.0,
        yaw_rad: float = 0.0,
        table_height_m: float = 0.0,
        vhacd_resolution: int = 100_000,
    ) -> None:
        """Build the scene with ``obj`` standing at ``(x_m, y_m)`` turned by ``yaw_rad``,
        its collision parts' lowest point on the table, and let it settle."""
        self.table_height_m = float(table_height_m)
        self._body = ObjectBody.from_mesh(obj.mesh, obj.mass_kg, obj.friction, vhacd_resolution)
        position = np.array([x_m, y_m, self.table_height_m - self._body.lowest_z_m])
        quaternion = Rotation.from_euler("z", yaw_rad).as_quat()
        self.hand: MujocoHand | None = None
        self.model = build_model(self._body, position, quaternion, self.table_height_m, None)
        self.data = mujoco.MjData(self.model)
        self.object_body = self.model.body(OBJECT_BODY).id
        mujoco.mj_forward(self.model, self.data)
        self.settle()

    @staticmethod
    def substeps(timestep_s: float) -> int:
        """MuJoCo steps in a step of ``timestep_s``."""
        return max(1, round(timestep_s / TIMESTEP_S))

    # ------------------------------------------------------------------ hands
    def _rebuild(self, gripper: str | None) -> None:
        """Compile the scene with ``gripper`` (or none), the object where it is now."""
        qpos_address = self.model.jnt_qposadr[self.model.joint(OBJECT_BODY).id]
        dof_address = self.model.jnt_dofadr[self.model.joint(OBJECT_BODY).id]
        qpos = self.data.qpos[qpos_address : qpos_address + 7].copy()
        qvel = self.data.qvel[dof_address : dof_address + 6].copy()
        pose = self.object_pose()
        model = build_model(
            self._body, pose.position_m, pose.quaternion_xyzw, self.table_height_m, gripper
        )
        data = mujoco.MjData(model)
        qpos_address = model.jnt_qposadr[model.joint(OBJECT_BODY).id]
        dof_address = model.jnt_dofadr[model.joint(OBJECT_BODY).id]
        data.qpos[qpos_address : qpos_address + 7] = qpos
        data.qvel[dof_address : dof_address + 6] = qvel
        data.time = self.data.time
        self.model, self.data = model, data
        self.object_body = model.body(OBJECT_BODY).id
        mujoco.mj_forward(model, data)
        self.hand = MujocoHand(model, data, gripper) if gripper is not None else None

    def add_hand(self, gripper: str) -> None:
        """Load the hand ``gripper``, parked high above the table, fully open.

        Raises:
            ConfigError: the world has a hand already.
        """
        if self.hand is not None:
            raise ConfigError(f"this MujocoWorld already has the hand '{self.hand.spec.name}'")
        self._rebuild(gripper)
        assert self.hand is not None
        self.hand.park()

    def remove_hand(self) -> None:
        """Take the hand out (a tool change); nothing happens without a hand."""
        if self.hand is not None:
            self._rebuild(None)

    # ------------------------------------------------------------------ state
    def object_pose(self) -> ObjectPose:
        """The object's true pose now (its mesh frame in frame R)."""
        w, x, y, z = self.data.xquat[self.object_body]
        return ObjectPose(self.data.xpos[self.object_body].copy(), np.array([x, y, z, w]))

    def settle(self) -> None:
        """Let the object settle: :data:`~pipeline.sim.bodies.SETTLE_STEPS` steps of
        1/240 s, then more while it still moves, up to ``MAX_SETTLE_STEPS`` more (the
        PyBullet world's rule)."""
        physics = MujocoPhysics(self)
        dof = self.model.jnt_dofadr[self.model.joint(OBJECT_BODY).id]
        physics.step(SETTLE_STEPS)
        for _ in range(MAX_SETTLE_STEPS // SETTLE_STEPS):
            velocity = self.data.qvel[dof : dof + 6]
            if (
                np.linalg.norm(velocity[:3]) < REST_SPEED_M_S
                and np.linalg.norm(velocity[3:]) < REST_SPIN_RAD_S
            ):
                return
            physics.step(SETTLE_STEPS)

    def render(
        self,
        intrinsics: CameraIntrinsics,
        T_robot_camera: np.ndarray,
        near_m: float,
        far_m: float,
    ) -> CameraImage:
        """A noise-free ray-cast picture (:func:`pipeline.sim.mujoco.camera.ray_cast`)."""
        rgb, depth, geom = ray_cast(
            self.model, self.data, intrinsics, T_robot_camera, near_m, far_m
        )
        seen_body = np.where(geom >= 0, self.model.geom_bodyid[np.maximum(geom, 0)], -1)
        return CameraImage(rgb=rgb, depth_m=depth, object_mask=seen_body == self.object_body)

    # ------------------------------------------------------------------ grasps
    def _require_hand(self) -> MujocoHand:
        if self.hand is None:
            raise ConfigError("world 'mujoco' has no hand: call add_hand first")
        return self.hand

    def execute_grasp(self, plan: GraspPlan, settings: GraspSettings | None = None) -> GraspOutcome:
        """Run ``plan`` (:func:`pipeline.sim.grasp_sequence.execute_grasp`)."""
        hand = self._require_hand()
        return grasp_sequence.execute_grasp(MujocoPhysics(self), hand, plan, settings)

    def release(self, opening_m: float, settings: GraspSettings | None = None) -> ObjectPose:
        """Open to ``opening_m``, withdraw and park the hand
        (:func:`pipeline.sim.grasp_sequence.release`); the object's pose then."""
        hand = self._require_hand()
        return grasp_sequence.release(MujocoPhysics(self), hand, opening_m, settings)

    def lift(
        self, height_m: float, hold_s: float, settings: GraspSettings | None = None
    ) -> LiftOutcome:
        """Lift and hold what the hand grasped (:func:`pipeline.sim.grasp_sequence.lift`)."""
        hand = self._require_hand()
        return grasp_sequence.lift(MujocoPhysics(self), hand, height_m, hold_s, settings)
