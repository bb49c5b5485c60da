"""Recorded depth data: organised PCD clouds, depth images with ``camera.json``, ROS bags.

Every reader returns a :class:`Capture`: a metric depth image in the camera's OpenCV
optical frame (x right, y down, z forward; metres, NaN = no return), its pinhole
intrinsics, a colour image when the recording has one, and the camera pose in a robot
frame when the recording knows it.

* **PCD** (``x y z`` and optionally ``rgb``/``rgba``; ASCII, binary or binary_compressed;
  NaN = no return), points in the camera frame. For an organised cloud the depth image is
  the points' z and the intrinsics are fitted to the points (``u = fx x / z + cx``, ``v =
  fy y / z + cy`` over every valid pixel); the fit must be sub-pixel, else the points are
  not a pinhole image in their frame. An unorganised cloud (one row) is re-projected into
  a virtual pinhole camera at the frame's origin looking along +z
  (:func:`depth_from_points`).
* **Depth image**: a 16-bit PNG in millimetres (0 = no return) or a ``.npy`` float array in
  metres (NaN = no return), with a ``camera.json`` (:func:`pipeline.io.camera_file.read_camera`)
  and optionally a colour PNG of the same size (by default ``rgb.png`` beside it).
* **ROS bags**: see :mod:`pipeline.io.bags`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.io.camera_file import read_camera
from pipeline.io.formats import read_npy, require_file
from pipeline.types import CameraIntrinsics, DepthObservation

#: A median depth above this many metres means the values are millimetres (a depth
#: camera's range ends well before 20 m; 20 mm is closer than any of them sees).
MILLIMETRE_MEDIAN_M = 20.0
#: Largest RMS error (px) of the pinhole fit to an organised cloud.
MAX_PINHOLE_RMS_PX = 0.5
#: Largest side (px) of the virtual camera an unorganised cloud is re-projected into.
MAX_VIRTUAL_SIDE_PX = 1280
PCD_SUFFIXES = (".pcd",)
DEPTH_IMAGE_SUFFIXES = (".png", ".npy")


@dataclass(frozen=True)
class Capture:
    """One recorded depth view.

    Attributes:
        depth_m: ``(H, W) float32`` depth along the optical axis (m), NaN = no return.
        rgb: ``(H, W, 3) uint8`` registered colour image, or None.
        intrinsics: pinhole intrinsics of the depth image.
        T_robot_camera: ``(4, 4)`` camera pose in the recording's robot frame, or None.
        table_height_m: z of the support plane in that frame when recorded, else None.
        source: one line saying what was read (file, format, topic).
    """

    depth_m: np.ndarray
    rgb: np.ndarray | None
    intrinsics: CameraIntrinsics
    T_robot_camera: np.ndarray | None
    table_height_m: float | None
    source: str

    def view(
        self,
        T_robot_camera: np.ndarray,
        table_height_m: float | None,
        frame_from_support: bool = False,
    ) -> DepthObservation:
        """The capture as the pipeline's observation, its camera at ``T_robot_camera``; a
        capture without colour gets its depth as a grey image (near bright, far dark, no
        return black)."""
        rgb = self.rgb if self.rgb is not None else depth_as_grey(self.depth_m)
        return DepthObservation(
            depth_m=self.depth_m,
            rgb=rgb,
            intrinsics=self.intrinsics,
            T_robot_camera=T_robot_camera,
            table_height_m=table_height_m,
            frame_from_support=frame_from_support,
        )


def depth_as_grey(depth_m: np.ndarray) -> np.ndarray:
    """``(H, W, 3) uint8`` stand-in colour image of a depth image: near bright, far dark,
    no return black."""
    depth = np.asarray(depth_m, dtype=np.float64)
    valid = np.isfinite(depth)
    near, far = np.percentile(depth[valid], [1.0, 99.0]) if valid.any() else (0.0, 1.0)
    level = np.clip((far - depth) / max(far - near, 1e-6), 0.0, 1.0) * 205.0 + 50.0
    grey = np.where(valid, level, 0.0).astype(np.uint8)
    return np.repeat(grey[..., None], 3, axis=2)


def checked_depth(depth_m: np.ndarray, where: str) -> np.ndarray:
    """``depth_m`` as float32 with non-positive values turned into NaN; rejects an image
    without a single valid pixel and one whose values look like millimetres."""
    depth = np.array(depth_m, dtype=np.float32)
    depth[~(depth > 0.0)] = np.nan  # also NaN where depth is NaN
    valid = np.isfinite(depth)
    if not valid.any():
        raise InputError(f"{where}: the capture is empty (no pixel has a depth)")
    median = float(np.median(depth[valid]))
    if median > MILLIMETRE_MEDIAN_M:
        raise InputError(
            f"{where}: the depth looks like millimetres (median {median:.0f}); "
            "symfuse reads metres (a 16-bit PNG is read as millimetres)"
        )
    return depth


def depth_from_organised(points: np.ndarray, where: str) -> tuple[np.ndarray, CameraIntrinsics]:
    """Depth image and fitted pinhole intrinsics of an organised ``(H, W, 3)`` cloud in the
    camera's optical frame (NaN = no return).

    Raises:
        InputError: no valid point, millimetres, points behind the camera, or the points
            are not a pinhole image (fit worse than :data:`MAX_PINHOLE_RMS_PX`).
    """
    points = np.asarray(points, dtype=np.float64)
    height, width = points.shape[:2]
    depth = checked_depth(np.where(np.isfinite(points).all(axis=2), points[..., 2], np.nan), where)
    rows, cols = np.nonzero(np.isfinite(depth))
    if len(rows) < 3:
        raise InputError(f"{where}: fewer than 3 valid points; cannot fit the camera")
    behind = np.isfinite(points[..., 2]) & (points[..., 2] <= 0.0)
    if behind.any():
        raise InputError(
            f"{where}: {int(behind.sum())} points have z <= 0; the cloud must be in the "
            "camera's optical frame (x right, y down, z forward)"
        )
    z = depth[rows, cols].astype(np.float64)
    fitted, squared = [], 0.0
    for pixel, coordinate in ((cols, points[rows, cols, 0]), (rows, points[rows, cols, 1])):
        design = np.column_stack([coordinate / z, np.ones_like(z)])
        (focal, centre), *_ = np.linalg.lstsq(design, pixel.astype(np.float64), rcond=None)
        fitted.append((float(focal), float(centre)))
        squared += float(np.mean((design @ np.array([focal, centre]) - pixel) ** 2))
    rms = float(np.sqrt(squared))
    (fx, cx), (fy, cy) = fitted
    if rms <= MAX_PINHOLE_RMS_PX and (fx <= 0.0 or fy <= 0.0):
        flipped = " and ".join(axis for axis, f in (("x", fx), ("y", fy)) if f <= 0.0)
        raise InputError(
            f"{where}: the organised points are a mirror image: their {flipped} axis runs "
            "against the pixel grid; give the cloud in the camera's optical frame (x right, "
            "y down, z forward)"
        )
    if not rms <= MAX_PINHOLE_RMS_PX:
        raise InputError(
            f"{where}: the organised points are not a pinhole image in their frame "
            f"(fit RMS {rms:.2f} px); give the cloud in the camera's optical frame"
        )
    return depth, CameraIntrinsics(width, height, fx, fy, cx, cy)


def check_not_empty(width: int, height: int, where: str) -> None:
    """Reject a cloud of ``width x height`` points that has none."""
    if width * height == 0:
        raise InputError(f"{where}: the capture is empty ({width}x{height} points)")


def depth_from_points(
    points: np.ndarray, colours: np.ndarray | None, where: str
) -> tuple[np.ndarray, np.ndarray | None, CameraIntrinsics]:
    """Depth image, colour image and intrinsics of a virtual pinhole camera at the origin of
    the points' frame (the camera's optical frame), looking along +z, that sees them all.

    The focal length puts neighbouring points about one pixel apart (the median distance
    from a point to its nearest neighbour in ``x / z, y / z``), capped so that the image
    is at most :data:`MAX_VIRTUAL_SIDE_PX` on a side; each pixel keeps its nearest point.
    A point moves by at most half a pixel across its ray, so the re-projection blurs the
    cloud by half its own spacing; pixels no point falls in have no return (NaN).

    Args:
        points: ``(N, 3)`` camera frame, metres (non-finite rows are no return).
        colours: ``(N, 3) uint8`` per point, or None.

    Raises:
        InputError: fewer than 3 valid points, millimetres, or points behind the camera.
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    valid = np.isfinite(points).all(axis=1)
    if valid.sum() < 3:
        raise InputError(f"{where}: fewer than 3 valid points")
    if (points[valid, 2] <= 0.0).any():
        raise InputError(
            f"{where}: {int((points[valid, 2] <= 0.0).sum())} points have z <= 0; the cloud "
            "must be in the camera's optical frame (x right, y down, z forward)"
        )
    checked_depth(points[valid, 2], where)
    kept = points[valid]
    tangents = kept[:, :2] / kept[:, 2:3]
    spacing, _ = cKDTree(tangents).query(tangents, k=2)
    low, high = tangents.min(axis=0), tangents.max(axis=0)
    focal = 1.0 / max(float(np.median(spacing[:, 1])), 1e-9)
    focal = min(focal, (MAX_VIRTUAL_SIDE_PX - 1) / max(float((high - low).max()), 1e-9))
    width, height = (np.floor(focal * (high - low)).astype(int) + 1).tolist()
    cx, cy = -focal * low
    u = np.rint(focal * tangents[:, 0] + cx).astype(np.int64)
    v = np.rint(focal * tangents[:, 1] + cy).astype(np.int64)
    # Nearest point per pixel: write far to near, so the nearest write lands last.
    order = np.argsort(-kept[:, 2], kind="stable")
    depth = np.full((height, width), np.nan, dtype=np.float32)
    depth[v[order], u[order]] = kept[order, 2]
    rgb = None
    if colours is not None:
        rgb = np.zeros((height, width, 3), dtype=np.uint8)
        rgb[v[order], u[order]] = np.asarray(colours).reshape(-1, 3)[valid][order]
    intrinsics = CameraIntrinsics(width, height, float(focal), float(focal), float(cx), float(cy))
    return depth, rgb, intrinsics


def _pcd_header(path: Path) -> dict[str, list[str]]:
    """The header lines of a PCD file, keyed by their first word (up to ``DATA``)."""
    header: dict[str, list[str]] = {}
    try:
        with path.open("rb") as stream:
            for _ in range(64):
                line = stream.readline().decode("ascii", errors="replace").strip()
                if not line or line.startswith("#"):
                    continue
                key, *values = line.split()
                header[key.upper()] = values
                if key.upper() == "DATA":
                    return header
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror}") from None
    raise InputError(f"{path}: not a PCD file (no DATA line in its header)")


def read_pcd(path: Path) -> Capture:
    """A PCD cloud (camera frame, metres) as a capture; open3d reads the data (every point
    in order, NaN kept), the header gives the organisation. An unorganised cloud is
    re-projected into a virtual camera (:func:`depth_from_points`)."""
    from pipeline.io.open3d_loader import open3d

    header = _pcd_header(path)
    fields = header.get("FIELDS", [])
    if not {"x", "y", "z"} <= set(fields):
        raise InputError(f"{path}: the PCD has no x y z fields (FIELDS {' '.join(fields)})")
    try:
        width, height = int(header["WIDTH"][0]), int(header["HEIGHT"][0])
    except (KeyError, IndexError, ValueError):
        width = height = -1
    if width < 0 or height < 0:
        raise InputError(f"{path}: the PCD header has no valid WIDTH/HEIGHT")
    check_not_empty(width, height, str(path))
    o3d = open3d()
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        cloud = o3d.io.read_point_cloud(
            str(path), format="pcd", remove_nan_points=False, remove_infinite_points=False
        )
    points = np.asarray(cloud.points)
    if len(points) != width * height:
        raise InputError(
            f"{path}: cannot read the PCD data ({len(points)} points read, the header says "
            f"{width} x {height})"
        )
    colours = None
    if cloud.has_colors():
        colours = np.clip(np.rint(np.asarray(cloud.colors) * 255.0), 0, 255).astype(np.uint8)
    encoding = header.get("DATA", ["?"])[0]
    if height == 1:
        depth, rgb, intrinsics = depth_from_points(points, colours, str(path))
        source = (
            f"{path}: unorganised PCD ({width} points, {encoding}) re-projected into a "
            f"virtual {intrinsics.width}x{intrinsics.height} camera"
        )
        return Capture(depth, rgb, intrinsics, None, None, source)
    depth, intrinsics = depth_from_organised(points.reshape(height, width, 3), str(path))
    rgb = None if colours is None else colours.reshape(height, width, 3)
    return Capture(
        depth, rgb, intrinsics, None, None, f"{path}: organised PCD {width}x{height}, {encoding}"
    )


def read_png(path: Path) -> np.ndarray:
    """A PNG as an array (``(H, W)`` for grey, ``(H, W, 3|4)`` for colour), dtype kept."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            return np.array(image)
    except (OSError, UnidentifiedImageError) as exc:
        raise InputError(f"{path}: cannot read as an image: {exc}") from None


def depth_camera_path(path: Path, camera_path: Path | None) -> Path:
    """The ``camera.json`` of the depth image ``path``: ``camera_path`` when given, else
    the one beside the image."""
    return Path(camera_path) if camera_path else path.with_name("camera.json")


def read_depth_image(path: Path, camera_path: Path | None, colour_path: Path | None) -> Capture:
    """A depth image (16-bit PNG in mm, or ``.npy`` in m) with its ``camera.json``.

    Args:
        camera_path: the camera file; None = ``camera.json`` beside the image.
        colour_path: a colour PNG of the same size; None = ``rgb.png`` beside the image
            when there is one.
    """
    if path.suffix.lower() == ".npy":
        depth = read_npy(path)
        if depth.ndim != 2 or depth.dtype.kind != "f":
            raise InputError(
                f"{path}: expected an (H, W) float depth image in metres, got shape "
                f"{depth.shape} {depth.dtype}"
            )
    else:
        raw = read_png(path)
        if raw.ndim != 2 or raw.dtype != np.uint16:
            raise InputError(
                f"{path}: expected a 16-bit single-channel depth PNG in millimetres, got "
                f"shape {raw.shape} {raw.dtype}"
            )
        depth = raw.astype(np.float32) / 1000.0
    depth = checked_depth(depth, str(path))
    camera_path = depth_camera_path(path, camera_path)
    if not camera_path.exists():
        raise InputError(f"{path}: a depth image needs its camera: {camera_path} does not exist")
    camera = read_camera(camera_path)
    shape = (camera.intrinsics.height, camera.intrinsics.width)
    if depth.shape != shape:
        raise InputError(f"{path}: the image is {depth.shape}, {camera_path} says {shape}")
    colour = Path(colour_path) if colour_path else path.with_name("rgb.png")
    rgb = None
    if colour_path or colour.exists():
        rgb = read_png(require_file(colour))
        if rgb.ndim != 3 or rgb.shape[:2] != shape or rgb.dtype != np.uint8:
            raise InputError(f"{colour}: expected an 8-bit colour image of {shape} pixels")
        rgb = rgb[..., :3].copy()
    return Capture(
        depth,
        rgb,
        camera.intrinsics,
        camera.T_robot_camera,
        camera.table_height_m,
        f"{path}: depth image {shape[1]}x{shape[0]}, camera {camera_path}",
    )


def _refuse_unused(path: Path, applies_to: str, **options: object) -> None:
    """Refuse an option given for another kind of capture than ``path`` (it would be
    ignored): ``options`` maps ``sensor.recorded`` parameter names to their values."""
    for name, value in options.items():
        if value:
            raise InputError(
                f"{path}: sensor.recorded.{name} (--{name}) applies to {applies_to}, "
                "not to this capture"
            )


def read_capture(
    path: Path,
    *,
    camera: Path | None = None,
    colour: Path | None = None,
    topic: str = "",
    robot_frame: str = "",
) -> Capture:
    """Read any supported recording (see the module docstring), chosen by suffix; a
    folder or a ``.bag``/``.db3``/``.mcap`` file is a ROS bag.

    Raises:
        InputError: a missing, unreadable, empty or unsupported recording, one in
            millimetres, or an unorganised cloud.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if path.is_dir() or suffix in (".bag", ".db3", ".mcap"):
        from pipeline.io.bags import read_bag

        _refuse_unused(path, "a depth image", camera=camera, colour=colour)
        return read_bag(path, topic=topic, robot_frame=robot_frame)
    if suffix in PCD_SUFFIXES:
        _refuse_unused(path, "a depth image", camera=camera, colour=colour)
        _refuse_unused(path, "a ROS bag", topic=topic, robot_frame=robot_frame)
        return read_pcd(path)
    if suffix in DEPTH_IMAGE_SUFFIXES:
        _refuse_unused(path, "a ROS bag", topic=topic, robot_frame=robot_frame)
        return read_depth_image(path, camera, colour)
    raise InputError(
        f"{path}: unknown capture format '{suffix}' (use an organised .pcd, a depth .png or "
        ".npy with camera.json, or a ROS bag: .bag, or a ROS 2 bag folder)"
    )
