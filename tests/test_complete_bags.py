"""`symfuse complete` on ROS 1 and ROS 2 bags written here from the Kinect capture: a bag
completes exactly as the files it was made from."""

from __future__ import annotations

import dataclasses
import json
import types
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

from pipeline.cli import main
from pipeline.errors import InputError
from pipeline.io.bags import camera_intrinsics, read_bag
from pipeline.io.captures import read_pcd
from pipeline.io.open3d_loader import open3d

KINECT = Path(__file__).parent / "data" / "kinect_laptop_box_floor.pcd"
FRAME = "kinect_rgb_optical_frame"


@pytest.fixture(scope="module")
def source():
    """The capture, its points as the PCD stores them (float32) and the PCD's own run."""
    capture = read_pcd(KINECT)
    points = np.asarray(open3d().io.read_point_cloud(str(KINECT)).points).reshape(480, 640, 3)
    return capture, points.astype(np.float32)


def complete(folder: Path, scan: Path, *extra: str) -> dict:
    assert main(["complete", str(scan), *extra, "--out", str(folder)]) == 0
    document = json.loads((folder / "objects.json").read_text())
    document.pop("inputs"), document.pop("seconds")
    return document


class Messages:
    """Messages of one ROS distribution's typestore."""

    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.store.types:  # not in the ROS 1 store
            definition = "geometry_msgs/TransformStamped[] transforms"
            self.store.register(get_types_from_msg(definition, "tf2_msgs/msg/TFMessage"))
        self.types = self.store.types

    def serialize(self, message, msgtype: str) -> bytes:
        if self.ros1:
            return self.store.serialize_ros1(message, msgtype)
        return self.store.serialize_cdr(message, msgtype)

    def header(self, frame: str):
        stamp = self.types["builtin_interfaces/msg/Time"](sec=1, nanosec=0)
        if self.ros1:
            return self.types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return self.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def cloud(self, points: np.ndarray, rgb: np.ndarray):
        height, width = points.shape[:2]
        field = self.types["sensor_msgs/msg/PointField"]
        fields = [field(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
        fields.append(field(name="rgb", offset=12, datatype=7, count=1))
        records = np.zeros((height, width), dtype=[("xyz", "<f4", 3), ("rgb", "<u4")])
        records["xyz"] = points
        records["rgb"] = (rgb[..., 0].astype(np.uint32) << 16) | (
            rgb[..., 1].astype(np.uint32) << 8
        )
        records["rgb"] |= rgb[..., 2]
        return self.types["sensor_msgs/msg/PointCloud2"](
            header=self.header(FRAME),
            height=height,
            width=width,
            fields=fields,
            is_bigendian=False,
            point_step=16,
            row_step=16 * width,
            data=np.frombuffer(records.tobytes(), dtype=np.uint8),
            is_dense=False,
        )

    def image(self, depth_m: np.ndarray):
        height, width = depth_m.shape
        return self.types["sensor_msgs/msg/Image"](
            header=self.header(FRAME),
            height=height,
            width=width,
            encoding="32FC1",
            is_bigendian=0,
            step=4 * width,
            data=np.frombuffer(depth_m.astype("<f4").tobytes(), dtype=np.uint8),
        )

    def colour(self, rgb: np.ndarray, encoding: str, frame: str = FRAME):
        height, width = rgb.shape[:2]
        order = {"rgb8": [0, 1, 2], "bgr8": [2, 1, 0], "bgra8": [2, 1, 0, 0]}[encoding]
        pixels = np.ascontiguousarray(rgb[..., order])
        return self.types["sensor_msgs/msg/Image"](
            header=self.header(frame),
            height=height,
            width=width,
            encoding=encoding,
            is_bigendian=0,
            step=len(order) * width,
            data=np.frombuffer(pixels.tobytes(), dtype=np.uint8),
        )

    def camera_info(self, k):
        matrix = np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1], dtype=np.float64)
        projection = np.array([k.fx, 0, k.cx, 0, 0, k.fy, k.cy, 0, 0, 0, 1, 0], dtype=float)
        roi = self.types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        values = {"d": np.zeros(5), "k": matrix, "r": np.eye(3).ravel(), "p": projection}
        if self.ros1:
            values = {name.upper(): value for name, value in values.items()}
        return self.types["sensor_msgs/msg/CameraInfo"](
            header=self.header(FRAME),
            height=k.height,
            width=k.width,
            distortion_model="plumb_bob",
            binning_x=0,
            binning_y=0,
            roi=roi,
            **values,
        )

    def tf(self, T_parent_child: np.ndarray, parent: str, child: str):
        q = Rotation.from_matrix(T_parent_child[:3, :3]).as_quat()
        t = T_parent_child[:3, 3]
        transform = self.types["geometry_msgs/msg/Transform"](
            translation=self.types["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
            rotation=self.types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )
        stamped = self.types["geometry_msgs/msg/TransformStamped"](
            header=self.header(parent), child_frame_id=child, transform=transform
        )
        return self.types["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def write_bag(path: Path, ros1: bool, messages: list[tuple[str, str, object]]) -> Path:
    """``messages``: (topic, msgtype, message), written in order at t = 1 s."""
    factory = Messages(ros1)
    writer = Writer1(path) if ros1 else Writer2(path, version=9)
    with writer:
        for topic, msgtype, message in messages:
            connection = writer.add_connection(topic, msgtype, typestore=factory.store)
            writer.write(connection, 1_000_000_000, factory.serialize(message, msgtype))
    return path


@pytest.fixture(scope="module")
def references(source, tmp_path_factory):
    """What the files give: the PCD (no robot frame) and depth.npy + a camera.json holding
    the PCD run's support frame (a recorded robot frame, as /tf gives it)."""
    capture, _ = source
    folder = tmp_path_factory.mktemp("files")
    plain = complete(folder / "pcd", KINECT)
    T = np.array(plain["T_robot_camera"])
    np.save(folder / "depth.npy", capture.depth_m)
    camera = {"intrinsics": vars(capture.intrinsics), "T_robot_camera": T.tolist()}
    (folder / "camera.json").write_text(json.dumps(camera))
    framed = complete(folder / "npy", folder / "depth.npy")
    return {"plain": plain, "framed": framed, "T": T}


@pytest.mark.parametrize(
    ("ros1", "kind", "with_tf"),
    [
        (True, "cloud", False),
        (False, "image", False),
        (True, "image", True),
        (False, "cloud", True),
    ],
)
@pytest.mark.slow
def test_a_bag_completes_as_the_files_it_was_made_from(
    source, references, tmp_path, ros1, kind, with_tf
):
    capture, points = source
    factory = Messages(ros1)
    if kind == "cloud":
        messages = [
            (
                "/camera/depth/points",
                "sensor_msgs/msg/PointCloud2",
                factory.cloud(points, capture.rgb),
            )
        ]
    else:
        messages = [
            ("/camera/depth/image", "sensor_msgs/msg/Image", factory.image(capture.depth_m)),
            (
                "/camera/depth/camera_info",
                "sensor_msgs/msg/CameraInfo",
                factory.camera_info(capture.intrinsics),
            ),
        ]
    if with_tf:
        messages.append(
            (
                "/tf_static",
                "tf2_msgs/msg/TFMessage",
                factory.tf(references["T"], "base_link", FRAME),
            )
        )
    bag = write_bag(tmp_path / ("scene.bag" if ros1 else "scene"), ros1, messages)
    got = complete(tmp_path / "out", bag)
    expected = references["framed" if with_tf else "plain"]
    assert got["frame"] == expected["frame"]
    np.testing.assert_allclose(got["T_robot_camera"], expected["T_robot_camera"], atol=1e-12)
    assert len(got["objects"]) == len(expected["objects"]) >= 2  # laptop, box, a chair foot
    for ours, theirs in zip(got["objects"], expected["objects"], strict=True):
        assert ours["points"] == theirs["points"]
        np.testing.assert_allclose(ours["centroid"], theirs["centroid"], atol=1e-9)
        assert ours["plane"]["theta_deg"] == pytest.approx(theirs["plane"]["theta_deg"], abs=1e-6)
        assert ours["plane"]["offset"] == pytest.approx(theirs["plane"]["offset"], abs=1e-9)


@pytest.mark.parametrize("encoding", ["rgb8", "bgr8", "bgra8"])
def test_a_colour_image_registered_to_the_depth_gives_the_colours(source, tmp_path, encoding):
    capture, _ = source
    factory = Messages(False)
    other_frame = factory.colour(capture.rgb[:, ::-1], "rgb8", frame="kinect_rgb_frame")
    bag = write_bag(
        tmp_path / "scene",
        False,
        [
            ("/camera/rgb/unregistered", "sensor_msgs/msg/Image", other_frame),
            ("/camera/depth/image", "sensor_msgs/msg/Image", factory.image(capture.depth_m)),
            ("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo",
             factory.camera_info(capture.intrinsics)),
            ("/camera/rgb/image", "sensor_msgs/msg/Image", factory.colour(capture.rgb, encoding)),
        ],
    )  # fmt: skip
    got = read_bag(bag, topic="/camera/depth/image")
    np.testing.assert_array_equal(got.rgb, capture.rgb)
    assert got.source.endswith("colour from /camera/rgb/image")


def test_a_bag_without_a_depth_topic_is_one_line_exit_2(tmp_path, capsys):
    factory = Messages(False)
    bag = write_bag(
        tmp_path / "tf_only",
        False,
        [("/tf_static", "tf2_msgs/msg/TFMessage", factory.tf(np.eye(4), "base_link", FRAME))],
    )
    code = main(["complete", str(bag), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("symfuse: error: ") and "no PointCloud2 or Image" in err
    code = main(["complete", str(bag), "--topic", "/nope", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "no topic '/nope'" in err


def image_bag(path: Path, source, image=None, T_robot_camera=None) -> Path:
    """A ROS 1 bag of the capture's depth Image (or ``image``), its CameraInfo and, given
    ``T_robot_camera``, a /tf_static to base_link."""
    capture, _ = source
    factory = Messages(True)
    messages = [
        ("/camera/depth/image", "sensor_msgs/msg/Image", image or factory.image(capture.depth_m)),
        ("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo",
         factory.camera_info(capture.intrinsics)),
    ]  # fmt: skip
    if T_robot_camera is not None:
        tf = factory.tf(T_robot_camera, "base_link", FRAME)
        messages.append(("/tf_static", "tf2_msgs/msg/TFMessage", tf))
    return write_bag(path, True, messages)


def one_error(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("symfuse: error: "), lines
    return lines[0]


def test_a_bag_image_shorter_than_its_header_says_is_named(source, tmp_path, capsys):
    capture, _ = source
    image = dataclasses.replace(
        Messages(True).image(capture.depth_m), data=np.zeros(100, dtype=np.uint8)
    )
    bag = image_bag(tmp_path / "short.bag", source, image=image)
    assert main(["complete", str(bag), "--out", str(tmp_path / "out")]) == 2
    assert "the message holds 100 bytes; its header says 480 rows of 2560" in one_error(capsys)


def test_a_camera_in_millimetres_in_tf_is_refused(source, tmp_path, capsys):
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 1500.0]
    bag = image_bag(tmp_path / "tf_mm.bag", source, T_robot_camera=T)
    assert main(["complete", str(bag), "--out", str(tmp_path / "out")]) == 2
    assert "the camera in /tf: a point lies 1.5e+03 m" in one_error(capsys)


def test_a_broken_ros2_metadata_file_is_one_line(tmp_path, capsys):
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n")
    assert main(["complete", str(tmp_path / "bag"), "--out", str(tmp_path / "out")]) == 2
    assert "cannot read as a ROS bag: Could not load YAML" in one_error(capsys)


@pytest.mark.parametrize("focal", [0.0, float("inf"), float("nan")])
def test_a_camera_info_without_a_finite_focal_length_is_refused(focal):
    k = [focal, 0.0, 320.0, 0.0, 525.0, 240.0, 0.0, 0.0, 1.0]
    info = types.SimpleNamespace(k=np.array(k), width=640, height=480)
    with pytest.raises(InputError, match="no valid K matrix"):
        camera_intrinsics(info, "scene.bag [/camera_info]")
