"""Cutting objects out of a scene cloud (paper section 6.2.1).

Drop everything lower than ``min_height_m`` above the table (the table itself and what lies
on it flat; one cut for the scene, or one per point), optionally thin the rest on a voxel
grid and cluster it: every cluster is an object, the largest one is *the* object of the
paper. Clusters whose footprints on the table overlap are one object: objects standing on a
table do not overlap, but the parts of one object can be apart in space, such as a mug's
near wall and the inside of its far wall seen over the rim.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.perception.clustering import dbscan_labels, voxel_subsample_indices
from pipeline.perception.table import TablePlane
from pipeline.types import CameraIntrinsics


@dataclass(frozen=True)
class SegmentationResult:
    """Which scene points were kept, and why.

    Attributes:
        objects: indices into the input cloud of each cluster's points, the most populous
            first (ties: the cluster found first).
        above_table: how many points survived the height filter (before subsampling).
        clusters: how many clusters the clustering found.
    """

    objects: tuple[np.ndarray, ...]
    above_table: int
    clusters: int

    @property
    def indices(self) -> np.ndarray:
        """``(K,)`` indices of the largest cluster's points (empty when there is none)."""
        return self.objects[0] if self.objects else np.zeros(0, dtype=np.int64)


def segment_points(
    points_robot: np.ndarray,
    table: TablePlane,
    *,
    min_height_m: float | np.ndarray = 0.02,
    max_height_m: float = np.inf,
    eps_m: float = 0.01,
    min_points: int = 10,
    voxel_m: float = 0.0,
) -> SegmentationResult:
    """Segment the objects standing on ``table``.

    Args:
        points_robot: ``(N, 3)`` scene points in the robot frame, metres.
        table: the supporting plane.
        min_height_m: points lower than this above the table are dropped (m; one for
            every point, or ``(N,)``, each point's own).
        max_height_m: points higher than this above the table are dropped.
        eps_m: DBSCAN neighbourhood radius.
        min_points: DBSCAN core-point threshold (self included); 1 = Euclidean clustering.
        voxel_m: voxel side for subsampling before clustering (0: keep every point).

    Returns:
        Every cluster's indices, largest first, and counts for error messages.
    """
    height = table.height_m(points_robot)
    above = np.flatnonzero((height >= min_height_m) & (height <= max_height_m))
    kept = above[voxel_subsample_indices(points_robot[above], voxel_m)]
    labels = dbscan_labels(points_robot[kept], eps_m, min_points)
    labels = merge_overlapping_footprints(points_robot[kept], labels, table, gap_m=eps_m)
    clusters = int(labels.max()) + 1 if len(labels) else 0
    sizes = np.bincount(labels[labels >= 0], minlength=clusters)
    order = np.argsort(-sizes, kind="stable")
    return SegmentationResult(
        objects=tuple(kept[labels == label] for label in order),
        above_table=len(above),
        clusters=clusters,
    )


#: How far outside a footprint's hull (m) a point still counts as inside it: rounding.
HULL_TOLERANCE_M = 1e-12


def merge_overlapping_footprints(
    points_robot: np.ndarray,
    labels: np.ndarray,
    table: TablePlane,
    gap_m: float = 0.0,
    min_height_overlap: float = 0.0,
) -> np.ndarray:
    """``labels`` (``-1``: noise) with every two clusters merged when a point of one lies
    within ``gap_m`` of the convex hull of the other's footprint (its points projected
    onto the table plane), renumbered ``0..K-1``.

    The hull is dilated by ``gap_m`` as a 16-gon about each vertex (within 2 % of a
    disc): two parts of one object whose footprints nearly touch, apart in space only
    because the surface joining them is unseen or sparse, are then one object.

    With ``min_height_overlap > 0`` two clusters are merged only when their ranges of
    height above the table overlap by at least that fraction of the shorter range: a box
    standing on another has its footprint inside the lower one's but starts where the
    lower one ends, while a container's near wall and the far wall seen over its rim
    span the same heights."""
    from scipy.spatial import ConvexHull

    normal = np.asarray(table.normal, dtype=np.float64)
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    flat = points_robot @ np.column_stack([u, np.cross(normal, u)])
    count = int(labels.max()) + 1 if len(labels) else 0
    if count == 0:
        return labels
    parent = np.arange(count)
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    disc = gap_m * np.column_stack([np.cos(angles), np.sin(angles)])

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    clustered = np.flatnonzero(labels >= 0)
    order = clustered[np.argsort(labels[clustered], kind="stable")]
    members = np.split(order, np.cumsum(np.bincount(labels[clustered], minlength=count))[:-1])
    height = table.height_m(points_robot)
    spans = np.array([[height[m].min(), height[m].max()] for m in members]).reshape(-1, 2)
    low = np.array([flat[m].min(axis=0) for m in members]).reshape(-1, 2)
    high = np.array([flat[m].max(axis=0) for m in members]).reshape(-1, 2)

    def stacked(i: int, j: int) -> bool:
        overlap = min(spans[i, 1], spans[j, 1]) - max(spans[i, 0], spans[j, 0])
        shorter = min(spans[i, 1] - spans[i, 0], spans[j, 1] - spans[j, 0])
        return overlap < min_height_overlap * shorter

    for i in range(count):
        footprint = flat[members[i]]
        # Joggled ("QJ"): a footprint on one line, or of a point or two, still has a hull.
        outline = footprint[ConvexHull(footprint, qhull_options="QJ").vertices]
        dilated = (outline[:, None, :] + disc[None, :, :]).reshape(-1, 2)
        facets = ConvexHull(dilated, qhull_options="QJ").equations
        # Only clusters whose bounding boxes meet the dilated footprint's can reach into it.
        box_low, box_high = dilated.min(axis=0), dilated.max(axis=0)
        candidates = np.flatnonzero(np.all((low <= box_high) & (high >= box_low), axis=1))
        for j in candidates:
            # Inside the hull: on the inner side of every facet (a x + b <= 0).
            outside = flat[members[j]] @ facets[:, :2].T + facets[:, 2] > HULL_TOLERANCE_M
            if j != i and outside.any(axis=1).all():
                continue
            if min_height_overlap == 0.0 or not stacked(i, int(j)):
                parent[root(int(j))] = root(i)
    roots = np.array([root(i) for i in range(count)], dtype=np.int64)
    merged = np.where(labels >= 0, roots[np.maximum(labels, 0)], -1)
    _, renumbered = np.unique(merged, return_inverse=True)
    return np.where(merged >= 0, renumbered - int(np.any(merged < 0)), -1)


#: A row or column along the image border is a dead margin when fewer than this share of
#: its pixels have depth.
MARGIN_VALID_SHARE = 0.1


def outside_view(valid: np.ndarray) -> np.ndarray:
    """``(H, W) bool``: the pixels outside the view: the image's dead margins (the rows
    and columns along each border in which fewer than :data:`MARGIN_VALID_SHARE` of the
    pixels have depth, like the band a Kinect returns nothing in along its edges) and the
    outermost row or column inside them. A no-data region inside the view (a black or
    shiny background, a cloud cropped to a box, a shadow) is not its edge: an object in
    front of it was seen whole."""
    valid = np.asarray(valid, dtype=bool)
    height, width = valid.shape

    def margin(shares: np.ndarray) -> int:
        alive = np.flatnonzero(shares >= MARGIN_VALID_SHARE)
        return int(alive[0]) if len(alive) else len(shares)

    rows, cols = valid.mean(axis=1), valid.mean(axis=0)
    top, bottom = margin(rows), margin(rows[::-1])
    left, right = margin(cols), margin(cols[::-1])
    outside = np.zeros((height, width), dtype=bool)
    outside[: top + 1] = True
    outside[height - bottom - 1 :] = True
    outside[:, : left + 1] = True
    outside[:, width - right - 1 :] = True
    return outside


def touches_view_edge(pixels: np.ndarray, outside: np.ndarray, margin_px: int) -> bool:
    """Whether an object's pixels ``(K, 2)`` (row, col) come within ``margin_px`` (the
    Chebyshev distance) of a pixel outside the view (:func:`outside_view`). Such an object
    may continue out of sight, and its mirror image would be wrong."""
    height, width = outside.shape
    rows, cols = pixels[:, 0], pixels[:, 1]
    for dr in range(-margin_px, margin_px + 1):
        for dc in range(-margin_px, margin_px + 1):
            r, c = np.clip(rows + dr, 0, height - 1), np.clip(cols + dc, 0, width - 1)
            if outside[r, c].any():
                return True
    return False


def segment_image(
    depth_m: np.ndarray,
    intrinsics: CameraIntrinsics,
    T_robot_camera: np.ndarray,
    table: TablePlane,
    *,
    backprojected: tuple[np.ndarray, np.ndarray] | None = None,
    min_height_m: float | np.ndarray = 0.02,
    max_height_m: float = np.inf,
    eps_m: float = 0.01,
    min_points: int = 10,
    window_px: int = 7,
    step_px: int = 3,
    min_turn: float = 0.3,
    min_height_overlap: float = 0.5,
) -> SegmentationResult:
    # Thirteen parameters and 85 lines: one numeric kernel with its tuning, keyword-only.
    """Segment the objects standing on ``table`` in a depth image by convex regions
    (:mod:`.surfaces`): the pixels above the table, cut at concave creases and depth steps
    into connected regions; crease pixels and regions of fewer than ``min_points`` pixels
    join the nearest region within ``eps_m``; regions whose footprints overlap are one
    object unless one stands on the other (:func:`merge_overlapping_footprints`).

    Args:
        depth_m: the view's depth image (:func:`backproject_depth`).
        intrinsics: the view's camera intrinsics.
        T_robot_camera: the view's camera pose.
        table: the supporting plane, frame R.
        backprojected: the view's points and pixels when the caller has them already.
        min_height_m: the lowest height above the table kept (m; may be ``(N,)``, one
            for each of the view's points).
        max_height_m: the highest height above the table kept (m).
        eps_m: largest gap between neighbouring pixels' points of one region at 1 m depth
            (scaled with the depth, as the pixels' spacing is).
        min_points: smallest region that stands on its own.
        window_px: side of the pixel square each normal is fitted to.
        step_px: the crease test's step (:func:`concave_creases`).
        min_turn: the crease test's least turn (:func:`concave_creases`).
        min_height_overlap: see :func:`merge_overlapping_footprints`.

    Returns:
        Every object's indices into :func:`backproject_depth`'s points, largest first.
    """
    from scipy.spatial import cKDTree

    from pipeline.perception.depth import backproject_depth
    from pipeline.perception.surfaces import concave_creases, connected_regions, image_normals

    depth = np.asarray(depth_m, dtype=np.float64)
    points_list, pixels = backprojected or backproject_depth(depth, intrinsics, T_robot_camera)
    shape = depth.shape
    points = np.full((*shape, 3), np.nan)
    points[pixels[:, 0], pixels[:, 1]] = points_list
    flat_index = np.full(shape, -1, dtype=np.int64)
    flat_index[pixels[:, 0], pixels[:, 1]] = np.arange(len(pixels))
    height = np.full(shape, np.nan)
    height[pixels[:, 0], pixels[:, 1]] = table.height_m(points_list)
    cut = np.full(shape, np.nan)
    cut[pixels[:, 0], pixels[:, 1]] = min_height_m
    with np.errstate(invalid="ignore"):
        above = (height >= cut) & (height <= max_height_m)
    normals = image_normals(points, above, window_px)
    viewpoint = np.asarray(T_robot_camera, dtype=np.float64)[:3, 3]
    crease = concave_creases(points, normals, viewpoint, step_px, min_turn) & above
    max_gap = eps_m * np.where(np.isfinite(depth), np.maximum(depth, 1.0), 0.0)
    regions = connected_regions(points, above & ~crease, max_gap)
    sizes = np.bincount(regions[regions >= 0])
    regions[(regions >= 0) & (sizes[np.maximum(regions, 0)] < min_points)] = -1
    loose = above & (regions < 0)
    anchored = regions >= 0
    if loose.any() and anchored.any():
        tree = cKDTree(points[anchored])
        distance, nearest = tree.query(points[loose], distance_upper_bound=eps_m)
        found = np.isfinite(distance)
        loose_labels = np.full(len(found), -1)
        loose_labels[found] = regions[anchored][nearest[found]]
        regions[loose] = loose_labels
    kept = flat_index[regions >= 0]
    labels = np.unique(regions[regions >= 0], return_inverse=True)[1]
    labels = merge_overlapping_footprints(
        points_list[kept], labels, table, min_height_overlap=min_height_overlap
    )
    clusters = int(labels.max()) + 1 if len(labels) else 0
    sizes = np.bincount(labels, minlength=clusters)
    order = np.argsort(-sizes, kind="stable")
    return SegmentationResult(
        objects=tuple(np.sort(kept[labels == label]) for label in order),
        above_table=int(above.sum()),
        clusters=clusters,
    )
