"""A shipped hand in a MuJoCo model (:mod:`pipeline.sim.mujoco.scene`): its palm moved
through its mocap target, its joints through position servos, its pads probed by rays
and its contacts read from MuJoCo's contact list.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.sim.hand_models import SimHand, TaxelFrames, hand_model
from pipeline.sim.mujoco.scene import (
    HAND_PREFIX,
    HAND_TARGET_BODY,
    OBJECT_COLLISION_GROUP,
    TABLE_GROUP,
)
from pipeline.sim.taxels import ray_segments, segments_near_box, surface_gaps

#: The geom groups a taxel probe sees: the object's collision parts and the table (which
#: hides the object behind it); never the hand.
PROBE_GROUPS = np.array(
    [group in (TABLE_GROUP, OBJECT_COLLISION_GROUP) for group in range(6)], dtype=np.uint8
)


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return np.array([w, x, y, z])


class MujocoHand(SimHand):
    """The hand ``gripper`` of a compiled scene, driven through ``data``.

    ``object_id`` arguments are MuJoCo body ids.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, gripper: str) -> None:
        self.m = model
        self.d = data
        simulated = hand_model(gripper)
        self._palm = model.body(HAND_PREFIX + "palm").id
        self._target = model.body_mocapid[model.body(HAND_TARGET_BODY).id]
        self._base_qpos = model.jnt_qposadr[model.joint(HAND_PREFIX + "base").id]
        self._base_dof = model.jnt_dofadr[model.joint(HAND_PREFIX + "base").id]
        self._actuator: dict[str, int] = {}
        self._qpos: dict[str, int] = {}
        self._dof: dict[str, int] = {}
        joint_limits: dict[str, tuple[float, float]] = {}
        joint_effort: dict[str, float] = {}
        for index in range(model.nu):
            joint = int(model.actuator_trnid[index, 0])
            name = model.joint(joint).name.removeprefix(HAND_PREFIX)
            self._actuator[name] = index
            self._qpos[name] = int(model.jnt_qposadr[joint])
            self._dof[name] = int(model.jnt_dofadr[joint])
            joint_limits[name] = (
                float(model.jnt_range[joint, 0]),
                float(model.jnt_range[joint, 1]),
            )
            joint_effort[name] = float(model.jnt_actfrcrange[joint, 1])
        self._setup(simulated, joint_limits, joint_effort)
        self._pad_bodies = [model.body(HAND_PREFIX + pad.layout.link).id for pad in simulated.pads]
        hand_bodies = [b for b in range(model.nbody) if model.body_rootid[b] == self._palm]
        self._hand_bodies = np.zeros(model.nbody, dtype=bool)
        self._hand_bodies[hand_bodies] = True
        # Each finger's bodies: those named after it (f1_knuckle, f1_proximal_pad, left_jaw...).
        self._finger_of_body = {
            body: i
            for body in hand_bodies
            for i, finger in enumerate(simulated.fingers)
            if model.body(body).name.removeprefix(HAND_PREFIX).startswith(f"{finger.name}_")
        }
        self._pad_row_of_body = {body: row for row, body in enumerate(self._pad_bodies)}

    # ------------------------------------------------------------------ base pose
    def pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.d.xmat[self._palm].reshape(3, 3)
        T[:3, 3] = self.d.xpos[self._palm]
        return T

    def reset_pose(self, T_robot_hand: np.ndarray) -> None:
        T = np.asarray(T_robot_hand, dtype=np.float64)
        self.d.qpos[self._base_qpos : self._base_qpos + 3] = T[:3, 3]
        self.d.qpos[self._base_qpos + 3 : self._base_qpos + 7] = _wxyz(T[:3, :3])
        self.d.qvel[self._base_dof : self._base_dof + 6] = 0.0
        self.move_to(T)
        mujoco.mj_forward(self.m, self.d)

    def move_to(self, T_robot_hand: np.ndarray) -> None:
        """Move the mocap target the palm is welded to."""
        T = np.asarray(T_robot_hand, dtype=np.float64)
        self.d.mocap_pos[self._target] = T[:3, 3]
        self.d.mocap_quat[self._target] = _wxyz(T[:3, :3])

    # ------------------------------------------------------------------ joints
    def joint_positions(self) -> dict[str, float]:
        return {name: float(self.d.qpos[adr]) for name, adr in self._qpos.items()}

    def _reset_joints(self, configuration: dict[str, float]) -> None:
        for name, value in configuration.items():
            self.d.qpos[self._qpos[name]] = value
            self.d.qvel[self._dof[name]] = 0.0
        mujoco.mj_forward(self.m, self.d)

    def command(self, targets: dict[str, float], force_fraction: float = 1.0) -> None:
        for name, target in targets.items():
            actuator = self._actuator[name]
            self.d.ctrl[actuator] = float(np.clip(target, *self._joint_limits[name]))
            cap = force_fraction * self._joint_effort[name]
            self.m.actuator_forcerange[actuator] = (-cap, cap)

    # ------------------------------------------------------------------ pads and contacts
    def pad_poses(self) -> tuple[np.ndarray, np.ndarray]:
        rotations = self.d.xmat[self._pad_bodies].reshape(-1, 3, 3).copy()
        return rotations, self.d.xpos[self._pad_bodies].copy()

    def taxel_gaps(
        self, object_id: int, behind_m: float, beyond_m: float
    ) -> tuple[TaxelFrames, np.ndarray]:
        """One ``mj_ray`` per taxel whose probe reaches the object's bounding box, seeing
        the table and the object's collision parts only. A probe that starts inside the
        object meets its surface where it leaves it, beyond the probed range (no hit)."""
        frames = self.taxel_frames()
        starts, ends = ray_segments(frames.positions, frames.normals, behind_m, beyond_m)
        box_min, box_max = self._body_box(object_id)
        fractions = np.ones(len(starts))
        geom = np.zeros(1, dtype=np.int32)
        for index in np.flatnonzero(segments_near_box(starts, ends, box_min, box_max)):
            along = mujoco.mj_ray(
                self.m,
                self.d,
                starts[index],
                ends[index] - starts[index],
                PROBE_GROUPS,
                1,
                -1,
                geom,
            )
            if 0.0 <= along < 1.0 and geom[0] >= 0 and self.m.geom_bodyid[geom[0]] == object_id:
                fractions[index] = along
        return frames, surface_gaps(fractions, behind_m, beyond_m)

    def _body_box(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds in frame R of the body's geoms (their bounding spheres)."""
        geoms = np.flatnonzero(self.m.geom_bodyid == body)
        centres = self.d.geom_xpos[geoms]
        radii = self.m.geom_rbound[geoms][:, None]
        return (centres - radii).min(axis=0), (centres + radii).max(axis=0)

    def _object_contacts(self, object_id: int) -> list[tuple[int, float, np.ndarray]]:
        """``(hand body, normal force N, unit normal from the object toward the hand)`` of
        every contact between the hand and the object now."""
        count = self.d.ncon
        if count == 0:
            return []
        body1 = self.m.geom_bodyid[self.d.contact.geom1[:count]]
        body2 = self.m.geom_bodyid[self.d.contact.geom2[:count]]
        # The contact frame's first row is the normal from geom1 toward geom2.
        object_first = (body1 == object_id) & self._hand_bodies[body2]
        hand_first = (body2 == object_id) & self._hand_bodies[body1]
        force = np.zeros(6)
        found = []
        for index in np.flatnonzero(object_first | hand_first):
            mujoco.mj_contactForce(self.m, self.d, int(index), force)
            normal = self.d.contact.frame[index, :3]
            if object_first[index]:
                found.append((int(body2[index]), float(force[0]), normal.copy()))
            else:
                found.append((int(body1[index]), float(force[0]), -normal))
        return found

    def pad_contact_forces(self, object_id: int) -> np.ndarray:
        forces = np.zeros(len(self._pad_bodies))
        for body, force, _ in self._object_contacts(object_id):
            row = self._pad_row_of_body.get(body)
            if row is not None:
                forces[row] += force
        return forces

    def finger_contact_forces(self, object_id: int) -> np.ndarray:
        forces = np.zeros(len(self.model.fingers))
        for body, force, _ in self._object_contacts(object_id):
            finger = self._finger_of_body.get(body)
            if finger is not None:
                forces[finger] += force
        return forces

    def bearing_down(self, object_id: int) -> tuple[int | None, float]:
        upward = [
            (force * max(normal[2], 0.0), body)
            for body, force, normal in self._object_contacts(object_id)
        ]
        if not upward:
            return None, 0.0
        body = max(upward)[1]
        return self._finger_of_body.get(body), float(sum(force for force, _ in upward))

    def touches(self, object_id: int) -> bool:
        return bool(self._object_contacts(object_id))
