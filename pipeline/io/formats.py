"""The file formats symfuse reads or writes (one module: clouds, contacts and results share
the validators and JSON helpers here).

* Point clouds: PLY and PCD (via open3d) or ``.npy`` (an ``(N, 3)`` array); frame R, in
  metres unless the reader is told ``units="mm"``.
* Contacts: JSON, ``{"frame": "robot", "units": "m", "grasps": [{"taxels": [{"position":
  [x, y, z], "normal": [nx, ny, nz], "pad": "left", "index": 17}, ...], "plan": {...}},
  ...]}``, one entry per grasp in the order the grasps happened; ``index`` (the taxel's
  row-major index within its pad) is optional. Normals point out of the pad into the object
  and are normalised on reading (unless unit already, to rounding). The optional ``plan``
  records the grasp plan (see :func:`plan_to_json`); PS initialisation uses its predicted
  contacts for the initial bias.
  ``units`` is ``"m"`` or ``"mm"`` (positions and the plan's lengths); a reader's ``units``
  argument overrides it (``--units``). A grasp may name its after-view, the depth image the
  camera took while the hand held the object (``"after_depth"``: a ``.npy`` file beside the
  contacts file, metres), with the hand's pose then (``"hand"``: ``T_robot_hand`` and
  ``joint_positions`` by joint name), which masks the hand out of it (docs/after-view.md).
* Results: ``result.json`` (see :func:`estimate_to_json`) and ``completed_stage{0,1,2}.ply``.
* Cameras: ``camera.json``, in :mod:`pipeline.io.camera_file`.

Readers validate what they read and raise :class:`~pipeline.errors.InputError` with a
one-line message naming the file and, for JSON, the key path at fault. They convert to
metres and refuse data whose scale says millimetres (:mod:`pipeline.io.units`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import InputError
from pipeline.io.cloud_headers import check_cloud_file
from pipeline.io.units import (
    MILLIMETRES_HINT,
    STATED_UNITS_HINT,
    check_distance,
    check_not_metres,
    check_stated_not_metres,
    scale_of,
)
from pipeline.types import (
    Bias,
    Consistency,
    Contacts,
    EstimateResult,
    GraspPlan,
    Hypothesis,
    PointCloud,
    StageEstimate,
    Symmetry,
    SymmetryPlane,
)

CLOUD_SUFFIXES = (".ply", ".pcd", ".npy")


def require_file(path: Path) -> Path:
    """``path`` when it is an existing file, else an :class:`InputError`."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    return path


def read_cloud(path: Path, units: str = "m") -> PointCloud:
    """Read an object cloud (frame R) from PLY, PCD or NPY, in ``units`` (``m`` or ``mm``).

    Raises:
        InputError: missing/unreadable file, unknown suffix, no points, wrong shape or type,
            non-finite coordinates, or a scale that says millimetres.
    """
    path = require_file(path)
    scale = scale_of(units, str(path))
    suffix = path.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise InputError(f"{path}: unknown cloud format '{suffix}' (use .ply, .pcd or .npy)")
    if suffix == ".npy":
        points = read_npy(path)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"{path}: expected an (N, 3) array, got shape {points.shape}")
        if points.dtype.kind not in "iuf":  # signed, unsigned, floating
            raise InputError(f"{path}: expected real numbers, got dtype {points.dtype}")
    else:
        from pipeline.io.open3d_loader import open3d

        check_cloud_file(path)  # open3d fills what a malformed file lacks with garbage
        o3d = open3d()
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            cloud = o3d.io.read_point_cloud(str(path))
        points = np.asarray(cloud.points)
    if len(points) == 0:
        raise InputError(f"{path}: the cloud has no points (empty or unreadable file)")
    if len(points) == 1:
        raise InputError(f"{path}: the cloud has a single point; a view of an object needs more")
    points = np.asarray(points, dtype=np.float64)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise InputError(
            f"{path}: {int(bad.sum())} point(s) have NaN or infinite coordinates "
            f"(first at row {int(np.flatnonzero(bad)[0])})"
        )
    points = points * scale
    check_distance(points, str(path), MILLIMETRES_HINT if units == "m" else None)
    check_not_metres(np.ptp(points, axis=0), units, str(path))
    return PointCloud(points=points, frame="robot")


def read_npy(path: Path) -> np.ndarray:
    """The array of a ``.npy`` file (never a pickle).

    Raises:
        InputError: the file is empty, truncated, not ``.npy`` or holds Python objects.
    """
    try:
        with open(path, "rb") as stream:
            if stream.read(len(NPY_MAGIC)) != NPY_MAGIC:
                raise InputError(f"{path}: not a .npy file (it does not start as one)")
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, UnicodeError) as exc:
        raise InputError(f"{path}: cannot read as .npy: {_first_line(exc)}") from None


#: The first bytes of every ``.npy`` file (NumPy's format magic).
NPY_MAGIC = b"\x93NUMPY"


def check_keys(document: dict, known: Sequence[str], where: str, path: Path) -> None:
    """Refuse a key of a JSON object that is not ``known``: a misspelt optional key would
    be ignored without a word. ``where`` prefixes the key in the message (``intrinsics.``).
    """
    unknown = sorted(set(document) - set(known))
    if unknown:
        raise InputError(f"{path}: unknown key '{where}{unknown[0]}' (known: {', '.join(known)})")


def _first_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__


def write_cloud(path: Path, points: np.ndarray) -> Path:
    """Write ``(N, 3)`` points as binary PLY (:func:`ply_bytes`), PCD (binary, via open3d)
    or NPY, by suffix; an empty cloud is refused (open3d writes none)."""
    path = Path(path)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if path.suffix.lower() == ".npy":
        np.save(path, points)
        return path
    if len(points) == 0:
        raise InputError(f"{path}: a cloud of no points is not written")
    if path.suffix.lower() == ".ply":
        path.write_bytes(ply_bytes(points))
        return path
    from pipeline.io.open3d_loader import open3d

    o3d = open3d()
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if not o3d.io.write_point_cloud(str(path), cloud):
        raise InputError(f"{path}: open3d could not write the cloud")
    return path


#: The header of a binary PLY point cloud, laid out as open3d writes it (``{count}``: the
#: points); only the comment names the writer.
_PLY_HEADER = (
    "ply\nformat binary_little_endian 1.0\ncomment written by symfuse\nelement vertex {count}\n"
    "property double x\nproperty double y\nproperty double z\nend_header\n"
)


def ply_bytes(points: np.ndarray) -> bytes:
    """A binary PLY file of ``(N, 3)`` points: little-endian doubles, the file open3d's
    ``write_point_cloud`` writes for a cloud of points alone but for the comment naming the
    writer (written here, a run that only writes clouds does not load open3d)."""
    points = np.ascontiguousarray(points, dtype="<f8").reshape(-1, 3)
    return _PLY_HEADER.format(count=len(points)).encode("ascii") + points.tobytes()


def _vector(value: Any, where: str, path: Path) -> np.ndarray:
    if not (isinstance(value, list) and len(value) == 3):
        raise InputError(f"{path}: {where} must be a list of 3 numbers")
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        raise InputError(f"{path}: {where} must be a list of 3 numbers")
    try:
        vector = np.array(value, dtype=np.float64)
    except OverflowError:
        raise InputError(f"{path}: {where} has a number too large for a float") from None
    if not np.isfinite(vector).all():
        raise InputError(f"{path}: {where} has a NaN or infinite value")
    return vector


@dataclass(frozen=True)
class HeldHand:
    """Where the hand was while it held the object: its palm pose (frame R, the file's
    units read as metres) and its finger joints by name (rad or m)."""

    T_robot_hand: np.ndarray
    joint_positions: dict[str, float]


@dataclass(frozen=True)
class RecordedGrasps:
    """The grasps of a contacts file: contacts per grasp and, when recorded, its plan, its
    after-view's depth image file and the hand holding the object then (else None)."""

    contacts: tuple[Contacts, ...]
    plans: tuple[GraspPlan | None, ...]
    after_depth: tuple[Path | None, ...] = ()
    hands: tuple[HeldHand | None, ...] = ()


#: The keys of one taxel in a contacts file.
TAXEL_KEYS = ("position", "normal", "pad", "index")
#: A normal this close to unit length is unit up to rounding and is read unchanged.
_UNIT_TOLERANCE = 1e-12


def contacts_from_json(document: Any, path: Path, units: str | None = None) -> RecordedGrasps:
    """Validate a parsed contacts document (see the module docstring), in metres.

    Args:
        units: the units the user said the data are in (``--units``), or None. The
            document states its own, and one that contradicts them is refused: read in
            the other unit, the taxels would lie 1000 times too near or too far.
    """
    if not isinstance(document, dict):
        raise InputError(f"{path}: the top level must be a JSON object")
    check_keys(document, ("frame", "units", "grasps"), "", path)
    for key in ("frame", "units"):
        if key not in document:
            raise InputError(f"{path}: no '{key}' key (see the contacts format in docs/formats.md)")
    if document["frame"] != "robot":
        raise InputError(f'{path}: frame must be "robot", got {document["frame"]!r}')
    if document["units"] not in ("m", "mm"):
        raise InputError(f'{path}: units must be "m" (metres) or "mm", got {document["units"]!r}')
    if units is not None and units != document["units"]:
        raise InputError(
            f'{path}: the file says units "{document["units"]}", --units says {units}: '
            "drop --units or correct the file"
        )
    scale = scale_of(document["units"], str(path))
    grasps = document.get("grasps")
    if not isinstance(grasps, list) or not grasps:
        raise InputError(f"{path}: 'grasps' must be a non-empty list (one entry per grasp)")
    contacts, plans, after_depth, hands = [], [], [], []
    for g, grasp in enumerate(grasps):
        taxels = grasp.get("taxels") if isinstance(grasp, dict) else None
        if not isinstance(taxels, list) or not taxels:
            raise InputError(f"{path}: grasps[{g}].taxels must be a non-empty list")
        check_keys(grasp, GRASP_KEYS, f"grasps[{g}].", path)
        positions, normals, pads, indices = [], [], [], []
        for t, taxel in enumerate(taxels):
            where = f"grasps[{g}].taxels[{t}]"
            if not isinstance(taxel, dict):
                raise InputError(f"{path}: {where} must be an object")
            check_keys(taxel, TAXEL_KEYS, f"{where}.", path)
            positions.append(_vector(taxel.get("position"), f"{where}.position", path))
            normal = _vector(taxel.get("normal"), f"{where}.normal", path)
            length = float(np.linalg.norm(normal))
            if length < 1e-9:
                raise InputError(f"{path}: {where}.normal has zero length")
            # A unit normal is kept bit for bit: a replay of a recording then fuses exactly
            # as the trial that wrote it.
            normals.append(normal if abs(length - 1.0) <= _UNIT_TOLERANCE else normal / length)
            pad = taxel.get("pad")
            if not isinstance(pad, str) or not pad:
                raise InputError(f"{path}: {where}.pad must be a non-empty string")
            pads.append(pad)
            index = taxel.get("index", t)
            if not isinstance(index, int) or isinstance(index, bool) or index < 0:
                raise InputError(f"{path}: {where}.index must be a non-negative integer")
            indices.append(index)
        positions_m = scale * np.array(positions)
        check_distance(
            positions_m,
            f"{path}: grasps[{g}].taxels",
            STATED_UNITS_HINT if document["units"] == "m" else None,
        )
        check_stated_not_metres(positions_m, document["units"], f"{path}: grasps[{g}].taxels")
        contacts.append(Contacts(positions_m, np.array(normals), pads, indices))
        plan = grasp.get("plan")
        if plan is not None:
            plan = _scaled_plan(plan_from_json(plan, f"grasps[{g}].plan", path), scale)
        plans.append(plan)
        after_depth.append(_after_depth(grasp.get("after_depth"), f"grasps[{g}]", path))
        hands.append(_held_hand(grasp.get("hand"), f"grasps[{g}].hand", path, scale))
    return RecordedGrasps(tuple(contacts), tuple(plans), tuple(after_depth), tuple(hands))


#: The keys of one grasp in a contacts file.
GRASP_KEYS = ("taxels", "plan", "after_depth", "hand")


def _after_depth(value: Any, where: str, path: Path) -> Path | None:
    """A grasp's after-view file, relative to the contacts file's folder."""
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        raise InputError(f"{path}: {where}.after_depth must be a file name")
    return path.parent / value


def _held_hand(value: Any, where: str, path: Path, scale: float) -> HeldHand | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise InputError(f"{path}: {where} must be an object")
    check_keys(value, ("T_robot_hand", "joint_positions"), f"{where}.", path)
    transform = rigid_transform(value.get("T_robot_hand"), f"{where}.T_robot_hand", path)
    transform[:3, 3] *= scale
    joints = value.get("joint_positions", {})
    if not isinstance(joints, dict) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in joints.values()
    ):
        raise InputError(f"{path}: {where}.joint_positions must map joint names to numbers")
    return HeldHand(transform, {str(k): float(v) for k, v in joints.items()})


def read_json(path: Path) -> Any:
    """A parsed JSON file; :class:`InputError` naming it when missing or not JSON."""
    path = require_file(path)
    try:
        return json.loads(path.read_text(), object_pairs_hook=_unique_keys)
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read: {_first_line(exc)}") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON: {exc}") from None
    except _DuplicateKey as exc:
        raise InputError(f"{path}: the key '{exc}' appears twice in one object") from None
    except RecursionError:
        raise InputError(f"{path}: not valid JSON: nested too deeply") from None


class _DuplicateKey(Exception):
    """A JSON object names a key twice (the parser would keep the last without a word)."""


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    document: dict[str, Any] = {}
    for key, value in pairs:
        if key in document:
            raise _DuplicateKey(key)
        document[key] = value
    return document


def _scaled_plan(plan: GraspPlan, scale: float) -> GraspPlan:
    """``plan`` with its lengths multiplied by ``scale`` (metres per unit)."""
    if scale == 1.0:
        return plan
    transform = np.array(plan.T_robot_hand, dtype=np.float64)
    transform[:3, 3] *= scale
    return dataclasses.replace(
        plan,
        T_robot_hand=transform,
        pregrasp_height_m=plan.pregrasp_height_m * scale,
        opening_m=plan.opening_m * scale,
        predicted_contacts=np.asarray(plan.predicted_contacts) * scale,
    )


def read_contacts(path: Path, units: str | None = None) -> RecordedGrasps:
    """Read a contacts JSON file (one entry per grasp, in order), in metres.

    Args:
        units: ``m`` or ``mm`` when the user gave ``--units``: the file's own ``units``
            must agree (None: no check).
    """
    path = require_file(path)
    return contacts_from_json(read_json(path), path, units)


def contacts_to_json(
    grasps: Sequence[Contacts],
    plans: Sequence[GraspPlan | None] | None = None,
    entries: Sequence[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """The contacts document for ``grasps`` (what :func:`read_contacts` reads back);
    ``entries`` adds keys to each grasp's entry (its after-view,
    :func:`pipeline.io.after_view_files.write_after_view`)."""
    plans = list(plans) if plans is not None else [None] * len(grasps)
    entries = list(entries) if entries is not None else [{}] * len(grasps)
    return {
        "frame": "robot",
        "units": "m",
        "grasps": [
            {
                "taxels": [
                    {
                        "position": [float(v) for v in position],
                        "normal": [float(v) for v in normal],
                        "pad": str(pad),
                        "index": int(index),
                    }
                    for position, normal, pad, index in zip(
                        contacts.positions,
                        contacts.normals,
                        contacts.pads,
                        contacts.taxel_indices,
                        strict=True,
                    )
                ],
                **({"plan": plan_to_json(plan)} if plan is not None else {}),
                **entry,
            }
            for contacts, plan, entry in zip(grasps, plans, entries, strict=True)
        ],
    }


def rigid_transform(value: Any, where: str, path: Path) -> np.ndarray:
    """A JSON 4x4 matrix as a rigid transform: a rotation (orthonormal, determinant +1,
    not a reflection), a finite translation and the bottom row 0 0 0 1."""
    try:
        transform = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        transform = np.zeros(0)
    if transform.shape != (4, 4) or not np.isfinite(transform).all():
        raise InputError(f"{path}: {where} must be a finite 4x4 matrix")
    rotation = transform[:3, :3]
    if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6):
        raise InputError(f"{path}: {where}'s rotation is not orthonormal")
    if np.linalg.det(rotation) < 0.0:
        raise InputError(f"{path}: {where}'s rotation is a reflection (determinant -1)")
    if not np.allclose(transform[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(f"{path}: {where}'s bottom row must be 0 0 0 1")
    return transform


def plan_to_json(plan: GraspPlan) -> dict[str, Any]:
    """A grasp plan as JSON (frame R, metres, radians); ``score`` is null when the planner
    gives none."""
    return {
        "gripper": plan.gripper,
        "status": plan.status,
        "T_robot_hand": np.asarray(plan.T_robot_hand).tolist(),
        "pregrasp_height_m": float(plan.pregrasp_height_m),
        "opening_m": float(plan.opening_m),
        "closing_direction": [float(v) for v in plan.closing_direction],
        "predicted_contacts": np.asarray(plan.predicted_contacts).reshape(-1, 3).tolist(),
        "spread_rad": float(plan.spread_rad),
        "score": None if math.isnan(plan.score) else float(plan.score),
        "reason": plan.reason,
    }


#: The keys of a grasp plan in JSON (:func:`plan_to_json`).
PLAN_KEYS = (
    "gripper",
    "status",
    "T_robot_hand",
    "pregrasp_height_m",
    "opening_m",
    "closing_direction",
    "predicted_contacts",
    "spread_rad",
    "score",
    "reason",
)


def plan_from_json(document: Any, where: str, path: Path) -> GraspPlan:
    """Read what :func:`plan_to_json` wrote; errors name the key (``where.KEY``) in
    ``path``. ``status``, ``predicted_contacts``, ``spread_rad``, ``score`` and ``reason``
    are optional."""
    if not isinstance(document, dict):
        raise InputError(f"{path}: {where} must be an object")
    check_keys(document, PLAN_KEYS, f"{where}.", path)
    gripper = document.get("gripper")
    if not isinstance(gripper, str) or not gripper:
        raise InputError(f"{path}: {where}.gripper must be a non-empty string (the hand)")
    status = document.get("status", "ok")
    if status not in ("ok", "refused"):
        raise InputError(f'{path}: {where}.status must be "ok" or "refused", got {status!r}')
    closing = _vector(document.get("closing_direction"), f"{where}.closing_direction", path)
    if abs(float(np.linalg.norm(closing)) - 1.0) > 1e-6:
        raise InputError(f"{path}: {where}.closing_direction must be a unit vector")
    predicted = document.get("predicted_contacts", [])
    if not isinstance(predicted, list):
        raise InputError(f"{path}: {where}.predicted_contacts must be a list of points")
    score = document.get("score")
    if score is not None and not (_number(score) and 0.0 <= score <= 1.0):
        raise InputError(f"{path}: {where}.score must be a number in [0, 1] or null")
    reason = document.get("reason", "")
    if not isinstance(reason, str):
        raise InputError(f"{path}: {where}.reason must be a string")
    return GraspPlan(
        gripper=gripper,
        status=status,
        T_robot_hand=rigid_transform(document.get("T_robot_hand"), f"{where}.T_robot_hand", path),
        pregrasp_height_m=_length(document, "pregrasp_height_m", where, path),
        opening_m=_length(document, "opening_m", where, path),
        closing_direction=closing,
        predicted_contacts=np.array(
            [
                _vector(point, f"{where}.predicted_contacts[{k}]", path)
                for k, point in enumerate(predicted)
            ]
        ).reshape(-1, 3),
        spread_rad=_finite(document.get("spread_rad", 0.0), f"{where}.spread_rad", path),
        reason=reason,
        score=math.nan if score is None else float(score),
    )


def _number(value: Any) -> bool:
    """Whether a parsed JSON value is a finite number (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _finite(value: Any, where: str, path: Path) -> float:
    if not _number(value):
        raise InputError(f"{path}: {where} must be a finite number, got {value!r}")
    return float(value)


def _length(document: dict, key: str, where: str, path: Path) -> float:
    """A plan's length ``key``: a finite number, not negative."""
    value = _finite(document.get(key), f"{where}.{key}", path)
    if value < 0.0:
        raise InputError(f"{path}: {where}.{key} must not be negative, got {value!r}")
    return value


def write_json(path: Path, document: Any) -> Path:
    """Write JSON with NaN/inf turned into null (strict JSON readers reject them)."""
    path = Path(path)
    path.write_text(json.dumps(_jsonable(document), indent=2) + "\n")
    return path


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def plane_to_json(plane: SymmetryPlane) -> dict[str, Any]:
    """``{"normal": [nx, ny], "offset": d, "theta_deg": ...}``: the plane nx x + ny y = d."""
    return {
        "normal": [float(plane.normal[0]), float(plane.normal[1])],
        "offset": float(plane.offset_m),
        "theta_deg": float(np.degrees(plane.theta_rad)),
    }


def symmetry_to_json(symmetry: Symmetry) -> dict[str, Any]:
    """A symmetry's kind, its plane normal (or axis direction) and point (m), its parameters
    by name (m, rad) and their covariance (None when unknown)."""
    vector = "normal" if symmetry.is_plane else "direction"
    return {
        "kind": symmetry.kind,
        vector: [float(v) for v in symmetry.direction],
        "point": [float(v) for v in symmetry.point_m],
        "parameters": dict(zip(symmetry.parameters, map(float, symmetry.values), strict=True)),
        "covariance": None if symmetry.covariance is None else symmetry.covariance.tolist(),
    }


def bias_to_json(bias: Bias) -> dict[str, Any]:
    """Yaw (rad and deg), translation (m) and the pivot it rotates about (m)."""
    return {
        "yaw": float(bias.yaw_rad),
        "yaw_deg": float(np.degrees(bias.yaw_rad)),
        "translation": [float(v) for v in bias.translation_m],
        "pivot": [float(v) for v in bias.pivot_m],
    }


def stage_to_json(stage: StageEstimate) -> dict[str, Any]:
    """One stage of a result as JSON (without the clouds, which go to PLY files)."""
    return {
        "stage": stage.stage,
        "plane": plane_to_json(stage.plane),
        # The estimator's plane: the paper's vertical one with the (m_r, m_theta) block of
        # the covariance, or the leaning one it fused with its three parameters' block.
        "symmetry": symmetry_to_json(stage.estimated_symmetry),
        "bias": bias_to_json(stage.bias),
        "covariance": np.asarray(stage.covariance).tolist(),
        "status": stage.status,
        "iterations": int(stage.iterations),
        "seconds": float(stage.seconds),
        "active_points": int(stage.active_points),
        "trace": [
            {
                "grasp": state.grasp,
                "plane": plane_to_json(state.plane),
                "bias": bias_to_json(state.bias),
                "active_taxels": state.active_taxels,
                "active_points": state.active_points,
            }
            for state in stage.trace
        ],
        "consistency": consistency_to_json(stage.consistency),
        "hypothesis": hypothesis_to_json(stage.hypothesis),
    }


def hypothesis_to_json(hypothesis: Hypothesis | None) -> dict[str, Any] | None:
    """The alternative hypothesis a stage's model comes from (None: the fused estimate):
    its name, the fraction of its step kept and why the fused model was set aside."""
    if hypothesis is None:
        return None
    return {
        "name": hypothesis.name,
        "step": float(hypothesis.step),
        "replaced": hypothesis.replaced,
    }


def consistency_to_json(consistency: Consistency | None) -> dict[str, Any] | None:
    """A stage's self-diagnosis (None when it was not assessed): the checks that ran, the
    taxels' RMS distance from the model (mm) and NIS with its bound, the model points in
    seen free space with their limit (None when no camera image was given), the verdict, and
    a fused stage's bias against the after-views with its bound (None without them)."""
    if consistency is None:
        return None
    return _jsonable(
        {
            "checks": list(consistency.checks),
            "taxel_rms_mm": consistency.taxel_rms_m * 1e3,
            "nis": consistency.nis,
            "nis_threshold": consistency.nis_threshold,
            "free_space_violations": consistency.free_space_violations,
            "free_space_limit": consistency.free_space_limit,
            "consistent": consistency.consistent,
            "reason": consistency.reason,
            "after_view_nis": consistency.after_view_nis,
            "after_view_threshold": consistency.after_view_threshold,
            # A leaning plane's test only: a vertical plane's document is unchanged.
            **(
                {}
                if consistency.plane_turn_deg is None
                else {
                    "plane_turn_deg": consistency.plane_turn_deg,
                    "plane_turn_bound_deg": consistency.plane_turn_bound_deg,
                }
            ),
        }
    )


def consistency_fields(prefix: str, consistency_json: dict[str, Any] | None) -> dict[str, Any]:
    """A stage's self-diagnosis as flat sweep-row fields ``{prefix}_consistent``,
    ``{prefix}_taxel_rms_mm``, ``{prefix}_nis``, ``{prefix}_free_space_violations``,
    ``{prefix}_after_view_nis`` (empty when it was not assessed; the last empty too in a
    ``result.json`` written before it was recorded)."""
    if consistency_json is None:
        return {}
    names = ("consistent", "taxel_rms_mm", "nis", "free_space_violations")
    fields = {f"{prefix}_{name}": consistency_json[name] for name in names}
    fields[f"{prefix}_after_view_nis"] = consistency_json.get("after_view_nis")
    return fields


def hypothesis_field(prefix: str, hypothesis_json: dict[str, Any] | None) -> dict[str, str]:
    """The alternative hypothesis a stage's model comes from as the sweep-row field
    ``{prefix}_hypothesis`` (empty for the fused or initial model)."""
    return {f"{prefix}_hypothesis": (hypothesis_json or {}).get("name", "")}


def estimate_to_json(result: EstimateResult) -> list[dict[str, Any]]:
    """The per-stage list that ``result.json`` holds under ``"stages"``."""
    return [stage_to_json(stage) for stage in result.stages]


def selection_to_json(result: EstimateResult) -> dict[str, Any]:
    """``{"selected_stage": k, "selection_reason": ...}``: the best-supported stage."""
    return {"selected_stage": result.selected.stage, "selection_reason": result.selection_reason}


def write_completed_clouds(out_dir: Path, result: EstimateResult) -> list[Path]:
    """Write ``completed_stage{0,1,2}.ply`` into ``out_dir``."""
    return [
        write_cloud(Path(out_dir) / f"completed_stage{stage.stage}.ply", stage.completed)
        for stage in result.stages
    ]
