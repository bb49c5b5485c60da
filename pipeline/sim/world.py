"""The PyBullet world: one object on the table and one hand, as the built-in ``pybullet``
world plugin (:mod:`plugins.worlds.pybullet_world`) exposes it through the
:class:`pipeline.stages.World` contract.

The robot frame ``R`` is PyBullet's world frame.

A process keeps the PyBullet client of a closed world and builds the next world in it after
``pybullet.resetSimulation`` (which empties it; the scene then sets gravity, time step and
engine parameters again), so a sweep worker connects once for all its trials. The results
are the same as with a new client (``tests/test_sim_client_reuse.py``); ``SYMFUSE_PYBULLET_REUSE=0``
connects a new client for every world.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

import numpy as np
import pybullet
import trimesh

from pipeline.errors import ConfigError
from pipeline.sim.scene import Scene
from pipeline.types import GraspOutcome, GraspPlan, GripperSpec, ObjectPose, SceneObject

if TYPE_CHECKING:
    from pipeline.sim.hands import Hand

#: Environment variable: ``0`` gives every world a new PyBullet client (see the module doc).
REUSE_VARIABLE = "SYMFUSE_PYBULLET_REUSE"
#: Connected, empty clients of closed worlds, waiting for the next world of this process.
_idle_clients: list[int] = []


def _reuse_clients() -> bool:
    """Whether closed worlds' clients are kept (:data:`REUSE_VARIABLE` unset, empty or
    ``1``) or disconnected (``0``).

    Raises:
        ConfigError: any other value (``false``, ``no``), which would otherwise mean reuse.
    """
    value = os.environ.get(REUSE_VARIABLE) or "1"
    if value not in ("0", "1"):
        raise ConfigError(
            f"{REUSE_VARIABLE}={value}: expected 0 (a new PyBullet client for every world) "
            "or 1 (keep one for the next world, the default)"
        )
    return value == "1"


def _empty_client() -> int | None:
    """A kept client, emptied; None when there is none (the scene then connects one)."""
    while _idle_clients:
        client = _idle_clients.pop()
        if pybullet.isConnected(client):
            pybullet.resetSimulation(physicsClientId=client)
            return client
    return None


def _release_client(client: int) -> None:
    """Keep ``client`` for the next world (at most one is kept), or disconnect it."""
    if not pybullet.isConnected(client):
        return
    if _reuse_clients() and not _idle_clients:
        pybullet.resetSimulation(physicsClientId=client)  # frees the bodies now
        _idle_clients.append(client)
    else:
        pybullet.disconnect(client)


class PybulletWorld:
    """A PyBullet scene with one object on the table and (optionally) one hand.

    Attributes:
        client: PyBullet client id.
        scene: the :class:`~pipeline.sim.scene.Scene` owning the client.
        hand: the loaded hand, or None for a sensing-only world.
        object_id: PyBullet body id of the object.
        object_mesh: the object's mesh in its own frame (m); ``object_pose().transform``
            maps it into frame ``R``.
        object_name: the object's name.
        gripper: the hand's :class:`GripperSpec` (None without a hand).
        table_height_m: z of the table top in frame ``R``.
        rng: the trial's random generator (sensor and tactile noise draw from it).
    """

    def __init__(
        self,
        scene: Scene,
        hand: Hand | None,
        object_id: int,
        object_mesh: trimesh.Trimesh,
        object_name: str,
        seed: int,
    ) -> None:
        self.scene = scene
        self.client = scene.client
        self.hand = hand
        self.object_id = object_id
        self.object_mesh = object_mesh
        self.object_name = object_name
        self.gripper: GripperSpec | None = hand.spec if hand is not None else None
        self.table_height_m = scene.table_height_m
        self.rng = np.random.default_rng(seed)

    @classmethod
    def create(
        cls,
        obj: SceneObject,
        gripper: str | None,
        x: float = 0.0,
        y: float = 0.0,
        yaw: float = 0.0,
        seed: int = 0,
        table_height_m: float = 0.0,
        urdf_path: str | Path | None = None,
    ) -> PybulletWorld:
        """Build a world: table, ``obj`` standing at ``(x, y)`` m with ``yaw`` rad, and the
        hand named ``gripper`` (``"pg70"``, ``"sdh"``; None for no hand, or one added later
        with :meth:`add_hand`).

        With ``urdf_path`` the object's body comes from that URDF (its base frame must be
        the frame ``obj.mesh`` is expressed in); otherwise it is built from ``obj.mesh``,
        ``obj.mass_kg`` and ``obj.friction``. The object is left to settle
        (:meth:`~pipeline.sim.scene.Scene.settle`).
        """
        client = _empty_client() if _reuse_clients() else None
        if client is None:
            client = pybullet.connect(pybullet.DIRECT)
        try:
            scene = Scene(table_height_m=table_height_m, client=client)
        except BaseException:
            _release_client(client)
            raise
        try:
            if urdf_path is None:
                object_id = scene.add_object(obj.mesh, obj.mass_kg, obj.friction, x, y, yaw)
            else:
                object_id = scene.add_urdf(urdf_path, x, y, yaw)
            scene.settle(object_id)
            world = cls(scene, None, object_id, obj.mesh, obj.name, seed)
            if gripper is not None:
                world.add_hand(gripper)
        except BaseException:
            scene.close()
            _release_client(client)
            raise
        return world

    def add_hand(self, gripper: str) -> None:
        """Load the hand named ``gripper`` (parked high above the table, out of the camera's
        view, so a world sensed before its hand is chosen sees exactly the same scene).

        Raises:
            ConfigError: the world has a hand already, or the name is unknown.
        """
        if self.hand is not None:
            raise ConfigError(f"this PybulletWorld already has the hand '{self.hand.spec.name}'")
        from pipeline.sim.hands import Hand

        self.hand = Hand.load(self.client, gripper)
        self.gripper = self.hand.spec

    def remove_hand(self) -> None:
        """Take the hand out of the simulation (a tool change); :meth:`add_hand` may then
        bring in another. Nothing happens without a hand."""
        if self.hand is not None:
            self.hand.remove()
            self.hand = None
            self.gripper = None

    def __enter__(self) -> PybulletWorld:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Release the PyBullet client: kept (emptied) for the next world, see the module
        doc. Idempotent."""
        client = self.scene.client
        self.scene.close()
        if client >= 0:
            _release_client(client)

    def object_pose(self) -> ObjectPose:
        """The object's true pose now (its mesh frame in frame ``R``)."""
        return self.scene.object_pose(self.object_id)

    def execute_grasp(self, plan: GraspPlan) -> GraspOutcome:
        """Run ``plan`` with the hand (see :func:`pipeline.sim.grasping.execute_grasp`)."""
        if self.hand is None:
            raise ConfigError("this PybulletWorld was created without a gripper; cannot grasp")
        from pipeline.sim.grasping import execute_grasp

        return execute_grasp(self.client, self.hand, plan, self.object_id)
