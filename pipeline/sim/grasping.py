"""Executing a planned top grasp with a simulated hand in PyBullet: the engine's side
(:class:`PybulletPhysics`) of the grasp sequence in :mod:`pipeline.sim.grasp_sequence`.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pybullet as pb

from pipeline.sim import grasp_sequence
from pipeline.sim.grasp_sequence import HAND_GRASP_SETTINGS, GraspSettings, opposed_fingers
from pipeline.sim.hands import Hand
from pipeline.types import GraspOutcome, GraspPlan, LiftOutcome, ObjectPose

__all__ = [
    "HAND_GRASP_SETTINGS",
    "GraspSettings",
    "PybulletPhysics",
    "execute_grasp",
    "lift",
    "object_pose",
    "opposed_fingers",
    "release",
]


def object_pose(client: int, object_id: int) -> ObjectPose:
    """The object's true pose: its base link frame (the mesh origin, not the centre of
    mass PyBullet reports) in frame R, quaternion (x, y, z, w)."""
    com_position, com_orientation = pb.getBasePositionAndOrientation(
        object_id, physicsClientId=client
    )
    inertial = pb.getDynamicsInfo(object_id, -1, physicsClientId=client)
    com_in_link = pb.invertTransform(inertial[3], inertial[4])
    position, orientation = pb.multiplyTransforms(com_position, com_orientation, *com_in_link)
    return ObjectPose(np.array(position), np.array(orientation))


class PybulletPhysics:
    """A PyBullet client and the body a grasp is about (:class:`grasp_sequence.Physics`)."""

    def __init__(self, client: int, object_id: int) -> None:
        self.client = client
        self.object_id = object_id

    def step(self, steps: int = 1) -> None:
        for _ in range(steps):
            pb.stepSimulation(physicsClientId=self.client)

    def detect_collisions(self) -> None:
        pb.performCollisionDetection(physicsClientId=self.client)

    def object_pose(self) -> ObjectPose:
        return object_pose(self.client, self.object_id)

    @contextmanager
    def timestep(self, timestep_s: float) -> Iterator[None]:
        parameters = pb.getPhysicsEngineParameters(physicsClientId=self.client)
        pb.setTimeStep(timestep_s, physicsClientId=self.client)
        try:
            yield
        finally:
            pb.setTimeStep(parameters["fixedTimeStep"], physicsClientId=self.client)


def release(
    client: int,
    hand: Hand,
    object_id: int,
    opening_m: float,
    settings: GraspSettings | None = None,
) -> ObjectPose:
    """:func:`pipeline.sim.grasp_sequence.release` in a PyBullet client."""
    return grasp_sequence.release(PybulletPhysics(client, object_id), hand, opening_m, settings)


def lift(
    client: int,
    hand: Hand,
    object_id: int,
    height_m: float,
    hold_s: float,
    settings: GraspSettings | None = None,
) -> LiftOutcome:
    """:func:`pipeline.sim.grasp_sequence.lift` in a PyBullet client."""
    return grasp_sequence.lift(PybulletPhysics(client, object_id), hand, height_m, hold_s, settings)


def execute_grasp(
    client: int,
    hand: Hand,
    plan: GraspPlan,
    object_id: int,
    settings: GraspSettings | None = None,
) -> GraspOutcome:
    """:func:`pipeline.sim.grasp_sequence.execute_grasp` on ``object_id`` in a PyBullet
    client (its world frame is frame R).

    Raises:
        ConfigError: the plan was made for a different hand.
    """
    return grasp_sequence.execute_grasp(PybulletPhysics(client, object_id), hand, plan, settings)
