"""Resting poses: an object placed on the table in one of its stable poses.

``trial.rest`` (``symfuse trial --rest``) says how the object lies on the table:

* ``"upright"`` (the default): in the mesh's own frame, as every trial before it;
* ``"K"`` (``"0"``, ``"1"``, ...): in the K-th most likely of the mesh's stable poses;
* ``"random"``: one stable pose drawn by the poses' probabilities with the trial's seed.

A mesh's stable poses are those of its convex hull on a plane under gravity
(:func:`trimesh.poses.compute_stable_poses` with the centre of mass fixed: no sampling, so
deterministic): each hull face the centre of mass projects into is a pose, its probability
the share of random drops that topple onto it. A cylinder's curved side is many hull faces,
so lying is many poses of small probability each (one per facet of the side).

The rested object is the same solid turned into that pose and placed as every object is (its
base on ``z = 0``, centred in x, y): the scene, the camera, the planners and the evaluation
see it as any other object, and its true symmetries (:mod:`pipeline.symmetry.truth_file`)
are turned with it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pipeline.errors import ConfigError, InputError

if TYPE_CHECKING:
    import trimesh

    from pipeline.catalogue.objects import CatalogueObject
    from pipeline.config import TrialSettings

#: ``trial.rest``'s words besides a pose number.
UPRIGHT, RANDOM = "upright", "random"

#: A rest pose keeps the object's z axis vertical when it tilts it less than this (deg): the
#: object stands on its base or its top, and the measures that assume an upright object (a
#: box's thickness, a cylinder's diameter) apply.
VERTICAL_DEG = 1.0

#: The random stream of the ``random`` rest pose, apart from the trial's other draws from
#: the same seed (the world's noise).
REST_STREAM = 0x7E57


@dataclass(frozen=True)
class RestPose:
    """The stable pose an object was placed in.

    Attributes:
        index: its rank among the mesh's stable poses, most likely first (0).
        probability: the share of random drops that come to rest in it (-).
        count: how many stable poses the mesh has.
        transform: ``(4, 4)`` from the object frame the mesh was loaded in to the rested
            object's frame (base on ``z = 0``, centred in x, y), m.
        drawn: whether it was drawn at random (``trial.rest = "random"``).
    """

    index: int
    probability: float
    count: int
    transform: np.ndarray
    drawn: bool = False

    @property
    def keeps_vertical(self) -> bool:
        """Whether the pose keeps the object's z axis vertical (within
        :data:`VERTICAL_DEG`): it stands on its base or on its top."""
        return bool(abs(self.transform[2, 2]) >= math.cos(math.radians(VERTICAL_DEG)))

    def to_json(self) -> dict:
        """The pose as ``result.json`` records it."""
        return {
            "index": self.index,
            "probability": self.probability,
            "count": self.count,
            "drawn": self.drawn,
            "keeps_vertical": self.keeps_vertical,
            "transform": [[float(v) for v in row] for row in self.transform],
        }


def parse_rest(text: str) -> int | str:
    """``trial.rest`` as :data:`UPRIGHT`, :data:`RANDOM` or a pose number.

    Raises:
        ConfigError: anything else (naming the key).
    """
    if text in (UPRIGHT, RANDOM):
        return text
    if text.isdigit() and text.isascii():
        return int(text)
    raise ConfigError(
        f"config key 'trial.rest' (--rest): expected upright, random or a stable pose's "
        f"number 0, 1, ... (0: the most likely), got {text!r}"
    )


def stable_poses(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """The stable poses of ``mesh``, most likely first: ``(n, 4, 4)`` transforms that put
    it on the plane ``z = 0`` and their probabilities ``(n,)``. Computed once per mesh in
    a process (by the digest of its vertices and faces)."""
    from pipeline.sim.collision import mesh_hash

    transforms, probabilities = _stable_poses(mesh_hash(mesh), mesh)
    return transforms.copy(), probabilities.copy()


@functools.lru_cache(maxsize=16)
def _stable_poses(digest: str, mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    del digest  # the cache's key: a mesh itself is not hashable by its contents
    hull = mesh.convex_hull
    # The solid's centre of mass, as the simulator gives the body; a scan with holes
    # encloses no volume, and its hull's centroid stands in (always inside the hull, which
    # the pose search needs).
    centre = mesh.center_mass if mesh.is_volume else hull.center_mass
    transforms, probabilities = trimesh.poses.compute_stable_poses(
        hull, center_mass=centre, sigma=0.0, n_samples=1, seed=0
    )
    # Most likely first; equal probabilities (a box's opposite faces) keep the search's
    # order, which depends on the mesh alone.
    order = np.argsort(-probabilities, kind="stable")
    return np.asarray(transforms)[order], np.asarray(probabilities)[order]


def drawn_pose(probabilities: np.ndarray, seed: int) -> int:
    """A stable pose's number drawn with ``seed`` by the poses' ``probabilities``."""
    rng = np.random.default_rng((REST_STREAM, seed))
    return int(rng.choice(len(probabilities), p=probabilities / probabilities.sum()))


def rest_pose(mesh: trimesh.Trimesh, choice: int | str, seed: int) -> RestPose | None:
    """The rest pose ``choice`` (:func:`parse_rest`) of ``mesh``, with the transform that
    places it; None for :data:`UPRIGHT`.

    Raises:
        InputError: a pose number beyond the mesh's count (the message gives the count).
    """
    if choice == UPRIGHT:
        return None
    transforms, probabilities = stable_poses(mesh)
    if choice == RANDOM:
        index = drawn_pose(probabilities, seed)
    else:
        index = int(choice)
        if index >= len(probabilities):
            raise InputError(
                f"--rest {index} (trial.rest): the object has {len(probabilities)} stable "
                f"poses, numbered 0 to {len(probabilities) - 1}"
            )
    placed = mesh.copy()
    placed.apply_transform(transforms[index])
    lower, upper = placed.bounds
    centring = np.eye(4)
    centring[:3, 3] = -np.array(
        [(lower[0] + upper[0]) / 2.0, (lower[1] + upper[1]) / 2.0, lower[2]]
    )
    return RestPose(
        index=index,
        probability=float(probabilities[index]),
        count=len(probabilities),
        transform=centring @ transforms[index],
        drawn=choice == RANDOM,
    )


def at_rest(obj: CatalogueObject, choice: int | str, seed: int) -> CatalogueObject:
    """``obj`` in its rest pose ``choice`` (:func:`parse_rest`), with its true symmetries
    turned with it; ``obj`` itself for :data:`UPRIGHT`.

    The paper's plane (``symmetry_plane``) is kept when the pose leaves it vertical; an
    object's ``"rotational"`` class only when the pose keeps its axis vertical.

    Raises:
        InputError: a pose number beyond the count; a URDF object (the simulator loads its
            body as the file states it, upright).
    """
    from pipeline.catalogue.objects import vertical_plane
    from pipeline.symmetry.truth_file import true_symmetries

    if choice == UPRIGHT:
        return obj
    if obj.urdf_path is not None:
        raise InputError(
            f"{obj.urdf_path}: --rest (trial.rest) places mesh files and catalogue objects; "
            "a URDF body is loaded as its file states it"
        )
    pose = rest_pose(obj.mesh, choice, seed)
    assert pose is not None
    mesh = obj.mesh.copy()
    mesh.apply_transform(pose.transform)
    symmetries = tuple(s.transformed(pose.transform) for s in true_symmetries(obj))
    plane = None
    if obj.symmetry_plane is not None:
        from pipeline.types import Symmetry

        plane = vertical_plane(Symmetry.from_plane(obj.symmetry_plane).transformed(pose.transform))
    symmetry = "planar" if plane is not None else "none"
    if obj.symmetry == "rotational" and pose.keeps_vertical:
        symmetry = "rotational"
    return dataclasses.replace(
        obj,
        mesh=mesh,
        symmetry=symmetry,
        symmetry_plane=plane,
        description=f"{obj.description}, resting in its stable pose {pose.index}",
        symmetries=symmetries,
        rest=pose,
    )


def scene_object(settings: TrialSettings) -> CatalogueObject:
    """The object a trial's ``[trial]`` settings place on the table: loaded
    (:func:`pipeline.catalogue.objects.load_object`) and put in its rest pose."""
    from pipeline.catalogue.objects import load_object

    obj = load_object(settings.object, units=settings.units, symmetry=settings.symmetry)
    return at_rest(obj, parse_rest(settings.rest), settings.seed)
