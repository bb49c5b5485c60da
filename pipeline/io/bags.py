"""Depth views from ROS 1 and ROS 2 bags (the ``rosbags`` library, pure Python).

The first message on the chosen topic is read: an organised ``sensor_msgs/PointCloud2``
(fields ``x y z`` as float32/float64, optionally ``rgb``/``rgba`` packed in 32 bits; points
in the camera's optical frame, NaN = no return), or a ``sensor_msgs/Image`` (``16UC1`` /
``mono16`` in millimetres, ``32FC1`` in metres) with the ``CameraInfo`` of its camera
(``<namespace>/camera_info``, else the bag's first one); a colour Image (``rgb8``, ``bgr8``,
``rgba8``, ``bgra8``) of the same size in the same ``frame_id`` (a colour image registered to
the depth, as ``depth_registered`` drivers publish) gives the view's colours. When
``/tf_static`` or ``/tf`` link the message's ``frame_id`` to a robot frame (by default the
root of its tree), the first transform recorded on each link gives ``T_robot_camera``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import InputError
from pipeline.io.captures import (
    Capture,
    check_not_empty,
    checked_depth,
    depth_from_organised,
    depth_from_points,
)
from pipeline.io.units import UNITS_IN_METRES, check_distance
from pipeline.types import CameraIntrinsics

CLOUD = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_TOPICS = ("/tf_static", "/tf")
#: PointField datatypes symfuse reads, as numpy types.
POINT_FIELD_TYPES = {7: "f4", 8: "f8", 6: "u4"}
#: Image encodings of depth, and the factor to metres.
DEPTH_ENCODINGS = {"16UC1": ("u2", 1e-3), "mono16": ("u2", 1e-3), "32FC1": ("f4", 1.0)}
#: Image encodings of colour, and the order of their channels' R, G, B.
COLOUR_ENCODINGS = {"rgb8": (0, 1, 2), "rgba8": (0, 1, 2), "bgr8": (2, 1, 0), "bgra8": (2, 1, 0)}


def _frame(name: str) -> str:
    return name.lstrip("/")


def _transform(message: Any) -> np.ndarray:
    """4x4 matrix of a ``geometry_msgs/Transform``."""
    t, q = message.translation, message.rotation
    transform = np.eye(4)
    transform[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    transform[:3, 3] = [t.x, t.y, t.z]
    return transform


def cloud_points(message: Any, where: str) -> tuple[np.ndarray, np.ndarray | None]:
    """``(H, W, 3)`` points and ``(H, W, 3) uint8`` colours (or None) of a PointCloud2."""
    fields = {f.name: f for f in message.fields}
    if not {"x", "y", "z"} <= set(fields):
        raise InputError(f"{where}: the PointCloud2 has no x y z fields")
    order = ">" if message.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for name in ("x", "y", "z", "rgb", "rgba"):
        field = fields.get(name)
        if field is None:
            continue
        kind = POINT_FIELD_TYPES.get(field.datatype)
        if kind is None:
            raise InputError(f"{where}: field {name} has unsupported datatype {field.datatype}")
        names.append(name)
        formats.append(order + ("u4" if name in ("rgb", "rgba") else kind))
        offsets.append(field.offset)
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": message.point_step}
    )
    height, width = int(message.height), int(message.width)
    check_not_empty(width, height, where)
    data = _rows(message.data, height, message.row_step, width * message.point_step, where)
    rows = data[:, : width * message.point_step].copy().view(dtype).reshape(height, width)
    points = np.stack([rows[name].astype(np.float64) for name in "xyz"], axis=-1)
    colour = next((name for name in ("rgb", "rgba") if name in names), None)
    if colour is None:
        return points, None
    packed = rows[colour]
    rgb = np.stack([(packed >> shift) & 0xFF for shift in (16, 8, 0)], axis=-1)
    return points, rgb.astype(np.uint8)


def _rows(data: Any, height: int, step: int, row_bytes: int, where: str) -> np.ndarray:
    """A message's data as ``(height, step)`` bytes, refused unless each row of ``step``
    bytes holds the ``row_bytes`` its pixels need."""
    buffer = np.frombuffer(bytes(data), dtype=np.uint8)
    if step < row_bytes or len(buffer) != height * step:
        raise InputError(
            f"{where}: the message holds {len(buffer)} bytes; its header says {height} rows "
            f"of {step} bytes, each needing {row_bytes}"
        )
    return buffer.reshape(height, step)


def image_depth(message: Any, where: str) -> np.ndarray:
    """``(H, W)`` depth in metres of a depth Image."""
    encoding = DEPTH_ENCODINGS.get(message.encoding)
    if encoding is None:
        raise InputError(
            f"{where}: image encoding '{message.encoding}' is not depth "
            f"(use {', '.join(DEPTH_ENCODINGS)})"
        )
    kind, scale = encoding
    dtype = np.dtype((">" if message.is_bigendian else "<") + kind)
    height, width = int(message.height), int(message.width)
    if height * width == 0:
        raise InputError(f"{where}: the capture is empty (Image of {width}x{height})")
    rows = _rows(message.data, height, message.step, width * dtype.itemsize, where)
    depth = rows[:, : width * dtype.itemsize].copy().view(dtype).astype(np.float64) * scale
    return depth


def image_colour(message: Any, where: str) -> np.ndarray:
    """``(H, W, 3) uint8`` RGB of a colour Image."""
    order = COLOUR_ENCODINGS[message.encoding]
    height, width = int(message.height), int(message.width)
    channels = 4 if message.encoding.endswith("a8") else 3
    rows = _rows(message.data, height, message.step, width * channels, where)
    pixels = rows[:, : width * channels].reshape(height, width, channels)
    return np.ascontiguousarray(pixels[..., list(order)])


def registered_colour(
    bag: Any, path: Path, depth: np.ndarray, frame: str
) -> tuple[np.ndarray, str] | None:
    """RGB of the first colour Image with ``depth``'s size and ``frame``, and its topic."""
    for connection in bag.connections:
        if connection.msgtype != IMAGE:
            continue
        message = _first(bag, connection)
        if (
            message is not None
            and message.encoding in COLOUR_ENCODINGS
            and (int(message.height), int(message.width)) == depth.shape
            and _frame(message.header.frame_id) == frame
        ):
            return image_colour(message, f"{path} [{connection.topic}]"), connection.topic
    return None


def camera_intrinsics(info: Any, where: str) -> CameraIntrinsics:
    """Pinhole intrinsics from a CameraInfo's ``K`` (ROS 1) or ``k`` (ROS 2)."""
    k = np.asarray(getattr(info, "k", None) if hasattr(info, "k") else info.K, dtype=np.float64)
    if k.shape != (9,) or not (np.isfinite(k).all() and k[0] > 0 and k[4] > 0):
        raise InputError(f"{where}: the CameraInfo has no valid K matrix")
    return CameraIntrinsics(int(info.width), int(info.height), k[0], k[4], k[2], k[5])


def chain(links: dict[str, tuple[str, np.ndarray]], frame: str, root: str) -> np.ndarray | None:
    """``T_root_frame`` from ``links`` (child -> (parent, T_parent_child)); ``root`` ''
    means the top of ``frame``'s tree. None when ``frame`` is not in the tree or ``root``
    is not above it."""
    if frame not in links:
        return None
    transform, current, seen = np.eye(4), frame, set()
    while current in links and current != root and current not in seen:
        seen.add(current)
        parent, T_parent_child = links[current]
        transform = T_parent_child @ transform
        current = parent
    return transform if (not root or current == root) else None


def read_bag(path: Path, *, topic: str = "", robot_frame: str = "") -> Capture:
    """The first depth view on ``topic`` (default: the first PointCloud2 or Image topic)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    try:
        with AnyReader([Path(path)], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as bag:
            return _read(bag, Path(path), topic, robot_frame)
    except InputError:
        raise
    except Exception as exc:  # rosbags raises many kinds on a corrupt or foreign file
        detail = " ".join(str(exc).split()) or type(exc).__name__  # YAML errors span lines
        raise InputError(f"{path}: cannot read as a ROS bag: {detail}") from None


def _first(bag: Any, connection: Any) -> Any:
    for conn, _, raw in bag.messages(connections=[connection]):
        return bag.deserialize(raw, conn.msgtype)
    return None


def _read(bag: Any, path: Path, topic: str, robot_frame: str) -> Capture:
    views = [c for c in bag.connections if c.msgtype in (CLOUD, IMAGE)]
    if topic:
        views = [c for c in bag.connections if c.topic == topic]
        if not views:
            topics = ", ".join(sorted({c.topic for c in bag.connections})) or "none"
            raise InputError(f"{path}: no topic '{topic}' in the bag (topics: {topics})")
        if views[0].msgtype not in (CLOUD, IMAGE):
            raise InputError(
                f"{path}: topic '{topic}' carries {views[0].msgtype}, not a PointCloud2 or Image"
            )
    if not views:
        raise InputError(f"{path}: the bag has no PointCloud2 or Image topic")
    connection = views[0]
    where = f"{path} [{connection.topic}]"
    message = _first(bag, connection)
    if message is None:
        raise InputError(f"{where}: the capture is empty (no message on the topic)")
    frame = _frame(message.header.frame_id)
    if connection.msgtype == CLOUD:
        points, rgb = cloud_points(message, where)
        if points.shape[0] == 1:
            depth, rgb, intrinsics = depth_from_points(points, rgb, where)
            size = f"{intrinsics.width}x{intrinsics.height}"
            kind = f"unorganised PointCloud2, re-projected into a virtual {size} camera"
        else:
            depth, intrinsics = depth_from_organised(points, where)
            kind = f"PointCloud2 {intrinsics.width}x{intrinsics.height}"
    else:
        infos = [c for c in bag.connections if c.msgtype == CAMERA_INFO]
        namespace = connection.topic.rsplit("/", 1)[0]
        infos.sort(key=lambda c: c.topic != f"{namespace}/camera_info")
        info = _first(bag, infos[0]) if infos else None
        if info is None:
            raise InputError(f"{where}: a depth Image needs a CameraInfo, and the bag has none")
        intrinsics = camera_intrinsics(info, where)
        depth = image_depth(message, where)
        if depth.shape != (intrinsics.height, intrinsics.width):
            raise InputError(f"{where}: image {depth.shape} != CameraInfo size")
        depth, rgb = checked_depth(depth, where), None
        kind = f"Image {message.encoding} {intrinsics.width}x{intrinsics.height}"
        colour = registered_colour(bag, path, depth, frame)
        if colour is not None:
            rgb, colour_topic = colour
            kind += f", colour from {colour_topic}"
    links: dict[str, tuple[str, np.ndarray]] = {}
    for tf in [c for c in bag.connections if c.topic in TF_TOPICS]:
        for conn, _, raw in bag.messages(connections=[tf]):
            for stamped in bag.deserialize(raw, conn.msgtype).transforms:
                child = _frame(stamped.child_frame_id)
                links.setdefault(
                    child, (_frame(stamped.header.frame_id), _transform(stamped.transform))
                )
    T_robot_camera = chain(links, frame, robot_frame) if frame else None
    if robot_frame and T_robot_camera is None:
        raise InputError(f"{where}: /tf does not link frame '{frame}' to '{robot_frame}'")
    if T_robot_camera is not None:
        check_distance(T_robot_camera[:3, 3], f"{where}: the camera in /tf", UNITS_IN_METRES)
    return Capture(depth, rgb, intrinsics, T_robot_camera, None, f"{where}: {kind}")
