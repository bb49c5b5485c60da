"""DBSCAN (scipy), the voxel grid and RANSAC (open3d) segment the catalogue scenes as the
textbook definitions do.

Every catalogue object stands on the table in PyBullet and the simulated Kinect (noise on)
sees it; the scene cloud is segmented with :mod:`pipeline.perception` and compared
with independent numpy/scipy references of the same definitions written here:

* DBSCAN: core points and their clusters are defined uniquely, so they must match exactly;
  a border point (non-core, within ``eps`` of a core point) joins *one* of the clusters
  whose core points reach it, and which one is the implementation's choice. The largest
  cluster may therefore differ only by border points that touch two clusters' cores.
* voxel subsampling: one point per voxel of the grid of multiples of the voxel side, the
  one nearest the voxel's mean (ties: the lower index): exactly the same indices.
* RANSAC: the table plane against the truth (the world's table height): the fitted plane
  is refitted by least squares to some 100 000 inliers of millimetre noise, so its normal is
  within 0.2 deg of vertical and its height within 1 mm.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, cKDTree

from pipeline.catalogue.objects import list_objects, load_object
from pipeline.params import build
from pipeline.perception.clustering import dbscan_labels, voxel_subsample_indices
from pipeline.perception.depth import backproject_depth
from pipeline.perception.segmentation import segment_points
from pipeline.perception.table import fit_table_ransac, table_from_height
from plugins.sensors.pybullet_kinect import PybulletKinect
from plugins.worlds.pybullet_world import Pybullet

EPS_M, MIN_POINTS = 0.01, 10  # the table-cluster segmenter's defaults
MIN_HEIGHT_M = 0.02


def reference_core_components(points: np.ndarray, eps_m: float, min_points: int):
    """Core mask, cluster of each core point (connected components of the eps-graph of core
    points), and the ``(point, cluster)`` pairs of every non-core point with each cluster
    whose core points lie within ``eps_m`` of it (unique rows)."""
    tree = cKDTree(points)
    pairs = tree.query_pairs(eps_m, output_type="ndarray")
    n = len(points)
    core = 1 + np.bincount(pairs.ravel(), minlength=n) >= min_points
    linked = pairs[core[pairs[:, 0]] & core[pairs[:, 1]]]
    graph = coo_matrix((np.ones(len(linked)), (linked[:, 0], linked[:, 1])), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    both_ways = np.vstack([pairs, pairs[:, ::-1]])
    border = both_ways[~core[both_ways[:, 0]] & core[both_ways[:, 1]]]
    reach = np.unique(np.column_stack([border[:, 0], component[border[:, 1]]]), axis=0)
    return core, component, reach


def reference_voxel_indices(points: np.ndarray, voxel_m: float) -> np.ndarray:
    keys = np.floor(points / voxel_m).astype(np.int64)
    _, voxel, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    voxel = voxel.reshape(-1)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, voxel, points)
    distance = np.linalg.norm(points - (sums / counts[:, None])[voxel], axis=1)
    order = np.lexsort((np.arange(len(points)), distance, voxel))
    first = np.ones(len(order), dtype=bool)
    first[1:] = voxel[order][1:] != voxel[order][:-1]
    return np.sort(order[first])


@pytest.fixture(scope="module", params=[info.name for info in list_objects()])
def scene(request):
    """The Kinect's scene cloud (frame R) of one catalogue object, and the table height."""
    obj = load_object(request.param)
    with Pybullet.create(obj, None, x=0.0, y=0.0, yaw=0.4, seed=1) as world:
        observation = PybulletKinect(build(PybulletKinect.Params, {}, "sensor")).observe(world)
    points, _ = backproject_depth(
        observation.depth_m, observation.intrinsics, observation.T_robot_camera
    )
    return request.param, points, observation.table_height_m


def test_dbscan_matches_the_definition(scene):
    name, points, table_height_m = scene
    above = points[table_from_height(table_height_m).height_m(points) >= MIN_HEIGHT_M]
    labels = dbscan_labels(above, EPS_M, MIN_POINTS)
    core, component, reach = reference_core_components(above, EPS_M, MIN_POINTS)
    # Core points: the same partition (one open3d label per reference component and back).
    pairs = np.unique(np.column_stack([labels[core], component[core]]), axis=0)
    assert len(pairs) == len(np.unique(labels[core])) == len(np.unique(component[core])), name
    assert (labels[core] >= 0).all(), name
    # A border point joins a cluster whose core reaches it; a point no core reaches is noise.
    to_reference = np.full(labels.max() + 1, -1)
    to_reference[pairs[:, 0]] = pairs[:, 1]
    reached = np.isin(np.arange(len(above)), reach[:, 0])
    border = np.flatnonzero(~core & reached)
    joined = np.column_stack([border, to_reference[labels[border]]])
    key = reach[:, 0] * (component.max() + 1) + reach[:, 1]
    assert np.isin(joined[:, 0] * (component.max() + 1) + joined[:, 1], key).all(), name
    assert (labels[~core & ~reached] == -1).all(), name


def footprint_gap_m(hull_of: np.ndarray, points: np.ndarray) -> float:
    """Least distance (m) in the table's xy plane from ``points`` to the convex hull of
    ``hull_of``'s footprint, 0 when one lies inside: every point against every edge."""
    outline = hull_of[ConvexHull(hull_of[:, :2]).vertices, :2]  # counter-clockwise
    start, edge = outline, np.roll(outline, -1, axis=0) - outline
    xy = points[:, None, :2]
    along = np.clip(
        np.einsum("pek,ek->pe", xy - start, edge) / np.einsum("ek,ek->e", edge, edge), 0.0, 1.0
    )
    nearest = start + along[..., None] * edge
    distance = np.linalg.norm(xy - nearest, axis=2).min(axis=1)
    cross = edge[:, 0] * (xy[..., 1] - start[:, 1]) - edge[:, 1] * (xy[..., 0] - start[:, 0])
    distance[np.all(cross >= 0.0, axis=1)] = 0.0
    return float(distance.min())


def test_segmentation_keeps_the_same_object(scene):
    # The object is the largest DBSCAN cluster of the definition, joined by every other
    # cluster whose footprint on the table comes within eps of it (an open object's near
    # wall and its inside are apart in space); a point that two clusters' cores reach may
    # go either way.
    name, points, table_height_m = scene
    table = table_from_height(table_height_m)
    result = segment_points(points, table, min_height_m=MIN_HEIGHT_M, eps_m=EPS_M)
    above = np.flatnonzero(table.height_m(points) >= MIN_HEIGHT_M)
    core, component, reach = reference_core_components(points[above], EPS_M, MIN_POINTS)
    clusters_reaching = np.bincount(reach[:, 0], minlength=len(above))
    ambiguous = set(above[clusters_reaching > 1].tolist())
    members = {
        c: set(above[core & (component == c)].tolist())
        | set(above[reach[(reach[:, 1] == c) & (clusters_reaching[reach[:, 0]] == 1), 0]])
        for c in np.unique(component[core])
    }
    kept = set(result.indices.tolist())
    joined = {c for c, m in members.items() if m <= kept}
    assert np.argmax(np.bincount(component[core])) in joined, name
    assert kept - set().union(*(members[c] for c in joined)) <= ambiguous, name
    assert len(kept) > 500, name

    def apart_m(a: set[int], b: set[int]) -> float:
        first, second = points[sorted(a)], points[sorted(b)]
        return min(footprint_gap_m(first, second), footprint_gap_m(second, first))

    for c, m in members.items():
        if c in joined and len(joined) > 1:
            rest = set().union(*(members[j] for j in joined if j != c))
            assert apart_m(rest, m) <= EPS_M + 1e-6, name
        elif c not in joined:
            assert all(apart_m(members[j], m) > EPS_M - 1e-6 for j in joined), name


def test_voxel_subsampling_matches_the_definition(scene):
    _, points, table_height_m = scene
    above = points[table_from_height(table_height_m).height_m(points) >= MIN_HEIGHT_M]
    for voxel_m in (0.002, 0.005):
        np.testing.assert_array_equal(
            voxel_subsample_indices(above, voxel_m), reference_voxel_indices(above, voxel_m)
        )


def test_ransac_finds_the_table(scene):
    name, points, table_height_m = scene
    plane, inliers = fit_table_ransac(points, np.random.default_rng(0))
    assert np.degrees(np.arccos(plane.normal[2])) < 0.2, name
    assert abs(plane.offset_m - table_height_m) < 1e-3, name
    on_table = np.abs(points[:, 2] - table_height_m) < 0.002
    assert inliers[on_table].mean() > 0.99, name
