"""Test helpers for plugin authors: an analytic world, a registry with your plugin, a tiny
scene and a ready estimation problem.

:class:`AnalyticWorld` implements the whole :class:`pipeline.stages.World` contract without
a physics engine: a mesh standing on an infinite table, seen by ray casting (open3d's
``RaycastingScene``), and a parallel-jaw hand whose two flat pads close, each on its own,
until they touch the object (a guarded close), then press in by ``press_m``. The object
never moves. A sensor or tactile model that works in it uses nothing but the contract::

    from pipeline.testing import AnalyticWorld, tiny_scene

    with AnalyticWorld() as world:
        world.load_scene(tiny_scene())
        observation = MySensor().observe(world)

:func:`registry_with` gives the installed plugins plus yours (to run a whole trial, a
config, or ``registry.create``), :func:`estimation_problem` an
:class:`~pipeline.types.EstimationProblem` with a known answer for estimators;
:func:`load_config` and :func:`run_trial` build and run a trial as ``symfuse trial`` does.

One module because it is the one import path plugin authors are given for their tests
(docs/plugins.md section 6), and :class:`AnalyticWorld`, one class implementing the whole
world contract, is most of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from pipeline.config import load_config
from pipeline.errors import ConfigError
from pipeline.geometry.pad_layout import pad_grid
from pipeline.params import param
from pipeline.registry import Origin, StageRegistry, load_registry
from pipeline.run.trial import run_trial
from pipeline.stages import StageImplementation, World
from pipeline.types import (
    Bias,
    CameraImage,
    CameraIntrinsics,
    Contacts,
    EstimationProblem,
    GraspOutcome,
    GraspPlan,
    GripperSpec,
    ObjectPose,
    PadLayout,
    PointCloud,
    SceneSetup,
    SymmetryInit,
    SymmetryPlane,
    TaxelState,
)

__all__ = [
    "PARALLEL_HAND",
    "AnalyticWorld",
    "estimation_problem",
    "load_config",
    "registry_with",
    "run_trial",
    "tiny_scene",
]

#: The name of the analytic world's one hand (``trial.gripper``).
PARALLEL_HAND = "parallel"
#: Where the hand waits when it holds nothing, frame R (m): far above any scene.
PARKED_AT_M = np.array([0.0, 0.0, 2.0])
#: Colours (RGB) of the table and the object in rendered images.
TABLE_RGB = np.array([150.0, 150.0, 150.0])
OBJECT_RGB = np.array([200.0, 120.0, 60.0])
#: Half the side of the square table (m); the table is a plane for every practical view.
TABLE_HALF_SIDE_M = 50.0


def _yaw_quaternion(yaw_rad: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0)])


class AnalyticWorld(World):
    """No physics: the object on an infinite table, ray-cast images, pads that close until
    they touch (a test world; the object never moves).

    The hand (``"parallel"``) is the parallel gripper of ``hand_urdf`` (the PG-70 unless
    set; any two-jaw URDF of the convention of docs/hands.md): its
    :class:`~pipeline.types.GripperSpec`, aperture and pad placement are read from it
    (:func:`pipeline.io.hand_urdf.gripper_spec_from_urdf`). Its two flat pads of ``rows x cols``
    taxels (by default as many as fit the pad at ``pitch_m``) face each other across the
    hand's x axis, their centres as far down the hand's z axis as the URDF puts them. A
    grasp puts the open hand at ``plan.T_robot_hand`` (no collision check on the way down)
    and moves each pad along its normal until the first point of the object within the
    pad's area touches it, or until the pads meet; a pad that touched then presses
    ``press_m`` further in and feels ``pad_stiffness_N_per_m * press_m``. Cameras do not
    see the hand. :attr:`~pipeline.types.GraspOutcome.joint_positions` names each jaw's
    travel ``<pad>_jaw``.
    """

    name = "analytic"
    hands = (PARALLEL_HAND,)

    @dataclass(frozen=True)
    class Params:
        table_height_m: float = param(0.0, "z of the table top in frame R (m)")
        hand_urdf: str = param(
            "pg70.urdf", "the parallel gripper's URDF: a path, or a file of robots/"
        )
        rows: int = param(
            0, "taxel rows per pad, along the finger (0: as many as fit the pad)", at_least=0
        )
        cols: int = param(
            0, "taxel columns per pad, across the finger (0: as many as fit the pad)", at_least=0
        )
        pitch_m: float = param(0.0034, "taxel centre-to-centre distance (m)", above=0.0)
        press_m: float = param(0.0005, "how far a touching pad presses in (m)", at_least=0.0)
        pad_stiffness_N_per_m: float = param(
            20_000.0, "pad force per metre pressed in (N/m)", at_least=0.0
        )

    def __init__(self, params: Params | None = None) -> None:
        super().__init__(params)
        self.hand = self._read_hand()
        self._scene: Any = None
        self._object_mesh: Any = None
        self._pose: ObjectPose | None = None
        self._T_robot_hand: np.ndarray | None = None
        self._pad_offsets_m = np.zeros(2)  # each pad surface's distance from the centre plane
        self._pressed = np.zeros(2, dtype=bool)

    # ------------------------------------------------------------------ scene
    def load_scene(self, setup: SceneSetup) -> None:
        import trimesh

        from pipeline.io.open3d_loader import open3d

        p = self.params
        mesh = setup.obj.mesh.copy()
        c, s = math.cos(setup.yaw_rad), math.sin(setup.yaw_rad)
        transform = np.eye(4)
        transform[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        transform[:3, 3] = [setup.x_m, setup.y_m, p.table_height_m]
        mesh.apply_transform(transform)
        side = TABLE_HALF_SIDE_M
        table = trimesh.Trimesh(
            vertices=[
                [setup.x_m - side, setup.y_m - side, p.table_height_m],
                [setup.x_m + side, setup.y_m - side, p.table_height_m],
                [setup.x_m + side, setup.y_m + side, p.table_height_m],
                [setup.x_m - side, setup.y_m + side, p.table_height_m],
            ],
            faces=[[0, 1, 2], [0, 2, 3]],
        )
        self._scene = open3d().t.geometry.RaycastingScene()
        self._object_id = self._scene.add_triangles(
            np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.uint32)
        )
        self._scene.add_triangles(
            np.asarray(table.vertices, dtype=np.float32), np.asarray(table.faces, dtype=np.uint32)
        )
        self._object_mesh = mesh
        self._pose = ObjectPose(
            np.array([setup.x_m, setup.y_m, p.table_height_m]), _yaw_quaternion(setup.yaw_rad)
        )
        self.table_height_m = p.table_height_m
        self.rng = np.random.default_rng(setup.seed)
        self.gripper = None
        self._T_robot_hand = None

    def close(self) -> None:
        self._scene = None

    def _cast(
        self, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(t, is_object, normals)`` of the first hit along each ray
        ``origin + t direction`` (``t = inf`` where nothing is hit)."""
        if self._scene is None:
            raise ConfigError("world 'analytic' has no scene: call load_scene first")
        hits = self._scene.cast_rays(np.hstack([origins, directions]).astype(np.float32))
        t = hits["t_hit"].numpy().astype(np.float64)
        is_object = np.isfinite(t) & (hits["geometry_ids"].numpy() == self._object_id)
        return t, is_object, hits["primitive_normals"].numpy().astype(np.float64)

    def object_pose(self) -> ObjectPose:
        if self._pose is None:
            raise ConfigError("world 'analytic' has no scene: call load_scene first")
        return self._pose

    def render(
        self,
        intrinsics: CameraIntrinsics,
        T_robot_camera: np.ndarray,
        near_m: float,
        far_m: float,
    ) -> CameraImage:
        rows, cols = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width]
        # Rays through the pixel centres with unit depth in the camera frame (OpenCV).
        rays_camera = np.stack(
            [
                (cols.ravel() - intrinsics.cx) / intrinsics.fx,
                (rows.ravel() - intrinsics.cy) / intrinsics.fy,
                np.ones(rows.size),
            ],
            axis=1,
        )
        T = np.asarray(T_robot_camera, dtype=np.float64)
        directions = rays_camera @ T[:3, :3].T
        origins = np.broadcast_to(T[:3, 3], directions.shape)
        depth, is_object, normals = self._cast(origins, directions)  # ray z = 1: t is depth
        seen = (depth >= near_m) & (depth <= far_m)
        shape = (intrinsics.height, intrinsics.width)
        # Lambertian shading lit from the camera, so every visible face has a shade.
        unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        shade = 0.35 + 0.65 * np.abs(np.sum(normals * unit, axis=1))
        colour = np.where(is_object[:, None], OBJECT_RGB, TABLE_RGB) * shade[:, None]
        colour[~seen] = 0.0
        return CameraImage(
            rgb=np.clip(colour, 0, 255).astype(np.uint8).reshape(*shape, 3),
            depth_m=np.where(seen, depth, np.nan).astype(np.float32).reshape(shape),
            object_mask=(seen & is_object).reshape(shape),
        )

    # ------------------------------------------------------------------ hand
    def _read_hand(self) -> GripperSpec:
        """The hand of ``hand_urdf`` with this world's taxel grids.

        Raises:
            ConfigError: naming ``world.analytic.hand_urdf``: the file is not a URDF of
                the convention, or not a two-jaw gripper.
        """
        from pipeline.io.hand_urdf import PadGeometry, gripper_spec_from_urdf, hand_geometry

        p = self.params
        key = f"config key 'world.{self.name}.hand_urdf'"
        try:
            geometry = hand_geometry(p.hand_urdf)
        except ConfigError as error:
            raise ConfigError(f"{key}: {error}") from None
        if len(geometry.closing) != 2 or geometry.jaw_travel_m <= 0.0:
            raise ConfigError(
                f"{key}: {geometry.urdf} is not a parallel gripper: world 'analytic' needs "
                f"two jaws on prismatic joints, each with a pad (docs/hands.md)"
            )
        pads = []
        for closing in geometry.closing:
            mount = geometry.pad(closing.pad)
            rows = p.rows or int(mount.length_m / p.pitch_m + 1e-9)
            cols = p.cols or int(mount.width_m / p.pitch_m + 1e-9)
            if rows < 1 or cols < 1:
                raise ConfigError(
                    f"config key 'world.{self.name}.pitch_m': {p.pitch_m} m fits no taxel on "
                    f"the {mount.length_m * 1e3:.1f} x {mount.width_m * 1e3:.1f} mm pad "
                    f"'{mount.pad}' of {geometry.urdf}"
                )
            pads.append(PadGeometry(PadLayout(mount.pad, mount.link, rows, cols, p.pitch_m)))
        return gripper_spec_from_urdf(PARALLEL_HAND, p.hand_urdf, pads)

    def gripper_spec(self, name: str) -> GripperSpec:
        if name != PARALLEL_HAND:
            raise ConfigError(f"world 'analytic' has no hand '{name}' (hands: {PARALLEL_HAND})")
        return self.hand

    def add_hand(self, name: str) -> None:
        if self.gripper is not None:
            raise ConfigError(f"world 'analytic' already has the hand '{self.gripper.name}'")
        self.gripper = self.gripper_spec(name)
        self._park()

    def _park(self) -> None:
        self._T_robot_hand = np.eye(4)
        self._T_robot_hand[:3, :3] = np.diag([1.0, -1.0, -1.0])
        self._T_robot_hand[:3, 3] = PARKED_AT_M
        self._pad_offsets_m = np.full(2, self.hand.max_aperture_m / 2.0)
        self._pressed = np.zeros(2, dtype=bool)

    def _require_hand(self) -> np.ndarray:
        if self.gripper is None or self._T_robot_hand is None:
            raise ConfigError("world 'analytic' has no hand: call add_hand first")
        return self._T_robot_hand

    def _pad_frame(self, pad: int, T_robot_hand: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotation and origin in frame R of pad 0 or 1 (in the hand's closing order; the
        PG-70's ``left`` is at -x): x along the finger (hand +z), z its outward normal,
        origin its surface centre."""
        closing = self.hand.closing[pad]
        side = -math.copysign(1.0, closing.facing[0])
        x_axis, z_axis = np.array([0.0, 0.0, 1.0]), np.array([-side, 0.0, 0.0])
        rotation_hand = np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis])
        depth = self.hand.geometry.pad(closing.pad).centre_m[2]
        centre_hand = np.array([side * self._pad_offsets_m[pad], 0.0, depth])
        R, t = T_robot_hand[:3, :3], T_robot_hand[:3, 3]
        return R @ rotation_hand, R @ centre_hand + t

    def _pad_points(
        self, pad: int, T_robot_hand: np.ndarray, subdivide: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """Taxel centres (``subdivide`` x finer for probing) and the pad normal in frame R."""
        layout = self.hand.pads[pad]
        grid, _ = pad_grid(
            subdivide * layout.rows, subdivide * layout.cols, layout.pitch_m / subdivide
        )
        rotation, origin = self._pad_frame(pad, T_robot_hand)
        return grid @ rotation.T + origin, rotation[:, 2]

    def taxels(self, behind_m: float, beyond_m: float) -> TaxelState:
        T_robot_hand = self._require_hand()
        positions, normals, pads, indices, forces = [], [], [], [], []
        for pad, layout in enumerate(self.gripper.pads):
            pad_positions, normal = self._pad_points(pad, T_robot_hand)
            pad_normals = np.broadcast_to(normal, pad_positions.shape)
            positions.append(pad_positions)
            normals.append(pad_normals)
            pads.append(np.full(len(pad_positions), layout.name))
            indices.append(np.arange(len(pad_positions)))
            force = self.params.pad_stiffness_N_per_m * self.params.press_m
            forces.append(np.full(len(pad_positions), force if self._pressed[pad] else 0.0))
        positions, normals = np.concatenate(positions), np.concatenate(normals)
        t, is_object, _ = self._cast(positions - behind_m * normals, normals)
        gaps = np.where(is_object & (t <= behind_m + beyond_m), t - behind_m, np.inf)
        return TaxelState(
            positions,
            normals,
            np.concatenate(pads),
            np.concatenate(indices),
            gaps,
            np.concatenate(forces),
        )

    def _inside(self, points: np.ndarray) -> np.ndarray:
        """Which points lie inside the object: an odd number of surface crossings on the
        way up (the table is below every point, so only the object counts)."""
        up = np.broadcast_to([0.0, 0.0, 1.0], points.shape)
        rays = np.hstack([points, up]).astype(np.float32)
        return self._scene.count_intersections(rays).numpy() % 2 == 1

    def _touch_distance(self, pad: int, T_robot_hand: np.ndarray, stroke_m: float) -> float:
        """How far the open pad moves along its normal before the object touches it,
        sampled four times finer than the taxel pitch over the pad's area; inf for none."""
        origins, normal = self._pad_points(pad, T_robot_hand, subdivide=4)
        distances, is_object, _ = self._cast(origins, np.broadcast_to(normal, origins.shape))
        hit = is_object & (distances <= stroke_m)
        return float(distances[hit].min()) if hit.any() else math.inf

    def execute_grasp(self, plan: GraspPlan) -> GraspOutcome:
        self._require_hand()
        if plan.gripper != PARALLEL_HAND:
            raise ConfigError(
                f"grasp plan is for gripper '{plan.gripper}' but the world's hand is "
                f"'{PARALLEL_HAND}'"
            )
        before = self.object_pose()
        if plan.status != "ok" or not 0.0 <= plan.opening_m <= self.hand.max_aperture_m:
            reason = plan.reason or f"opening {plan.opening_m * 1e3:.1f} mm is out of range"
            return self._outcome(before, False, reason)
        self._park()
        T_robot_hand = np.asarray(plan.T_robot_hand, dtype=np.float64)
        self._pad_offsets_m = np.full(2, plan.opening_m / 2.0)
        if any(self._inside(self._pad_points(pad, T_robot_hand, 4)[0]).any() for pad in (0, 1)):
            return self._outcome(before, False, "a pad overlaps the object at the grasp pose")
        self._T_robot_hand = T_robot_hand
        stroke = plan.opening_m / 2.0
        for pad in (0, 1):
            touch = self._touch_distance(pad, T_robot_hand, stroke)
            self._pressed[pad] = math.isfinite(touch)
            travel = min(touch + self.params.press_m, stroke) if self._pressed[pad] else stroke
            self._pad_offsets_m[pad] = plan.opening_m / 2.0 - travel
        return self._outcome(before, True)

    def _outcome(self, before: ObjectPose, executed: bool, reason: str = "") -> GraspOutcome:
        return GraspOutcome(
            executed=executed,
            aperture_m=float(self._pad_offsets_m.sum()) if executed else math.nan,
            joint_positions={
                f"{pad.name}_jaw": float(offset)
                for pad, offset in zip(self.hand.pads, self._pad_offsets_m, strict=True)
            },
            T_robot_hand=np.array(self._require_hand()),
            object_before=before,
            object_after=self.object_pose(),
            reason=reason,
        )

    def release(self) -> ObjectPose:
        self._require_hand()
        self._park()
        return self.object_pose()


def registry_with(*classes: type[StageImplementation]) -> StageRegistry:
    """The installed plugins' registry with ``classes`` added, as a plugin named
    ``"test"`` would add them (to use with :func:`pipeline.config.load_config`,
    :func:`pipeline.run.trial.run_trial` or ``registry.create``). A class that is installed
    already (your plugin, ``pip install``-ed) is kept as installed.

    Raises:
        PluginError: a class is not a stage implementation, or another class has its name.
    """
    registry = load_registry()
    with registry.adding_from(Origin("test", "<test>", "")):
        for cls in classes:
            if (
                cls.name not in registry.names(cls.stage)
                or registry.get(cls.stage, cls.name).cls is not cls
            ):
                registry.add(cls)
    return registry


def tiny_scene(
    thickness_m: float = 0.04,
    width_m: float = 0.1,
    height_m: float = 0.12,
    x_m: float = 0.0,
    yaw_rad: float = 0.0,
    seed: int = 0,
) -> SceneSetup:
    """A box standing on the table, mirror-symmetric about its x = 0 plane (before
    ``yaw_rad``): ``thickness_m`` along x, ``width_m`` along y, ``height_m`` tall, 0.2 kg."""
    import trimesh

    mesh = trimesh.creation.box((thickness_m, width_m, height_m))
    mesh.apply_translation((0.0, 0.0, height_m / 2.0))
    box = SimpleNamespace(name="tiny-box", mesh=mesh, mass_kg=0.2, friction=0.8, urdf_path=None)
    return SceneSetup(box, x_m=x_m, yaw_rad=yaw_rad, seed=seed)


def estimation_problem(
    thickness_m: float = 0.04,
    plane_error_rad: float = math.radians(3.0),
    offset_error_m: float = 0.004,
    spacing_m: float = 0.004,
) -> tuple[EstimationProblem, SymmetryPlane]:
    """A box seen from its -x side, grasped across x, and an initial plane that is wrong.

    The box is ``thickness_m`` along x, 0.1 m along y and 0.12 m tall, standing on z = 0
    centred on the origin; its true symmetry plane is ``x = 0``. The cloud is its -x face
    and its top, sampled every ``spacing_m``; one grasp touches both x faces with a pad of
    6 x 14 taxels (3.4 mm pitch) each, centred 70 mm up. The initial plane is the truth
    turned by ``plane_error_rad`` and moved by ``offset_error_m``; the bias starts at zero
    about the cloud's centroid.

    Returns:
        The problem and the true plane (what a good estimator should come close to).
    """
    half, width, height = thickness_m / 2.0, 0.1, 0.12
    ys = np.arange(-width / 2 + spacing_m / 2, width / 2, spacing_m)
    zs = np.arange(spacing_m / 2, height, spacing_m)
    xs = np.arange(-half + spacing_m / 2, half, spacing_m)
    front = np.array([(-half, y, z) for y in ys for z in zs])
    top = np.array([(x, y, height) for x in xs for y in ys])
    cloud = PointCloud(np.vstack([front, top]))

    positions, normals = [], []
    grid, _ = pad_grid(14, 6, 0.0034)  # rows along the finger (z), columns along y
    for side in (-1.0, 1.0):
        positions.append(
            np.column_stack([np.full(len(grid), side * half), grid[:, 1], 0.07 + grid[:, 0]])
        )
        normals.append(np.tile([-side, 0.0, 0.0], (len(grid), 1)))
    contacts = Contacts(
        positions=np.vstack(positions),
        normals=np.vstack(normals),
        pads=np.repeat(["left", "right"], len(grid)),
        taxel_indices=np.tile(np.arange(len(grid)), 2),
    )
    truth = SymmetryPlane(0.0, 0.0)
    init = SymmetryInit(
        plane=SymmetryPlane(plane_error_rad, offset_error_m),
        bias=Bias(pivot_m=cloud.points.mean(axis=0)),
    )
    return EstimationProblem(cloud=cloud, init=init, grasps=(contacts,)), truth
