"""Pure taxel geometry (pipeline.geometry.pad_layout, pipeline.sim.taxels) against analytic
values."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.geometry.pad_layout import pad_grid
from pipeline.sim.taxels import (
    ray_segments,
    rotations_from_quaternions,
    segments_near_box,
    surface_gaps,
    taxels_to_robot,
)

PITCH = 0.0034


def test_flat_grid_is_centred_row_major_with_the_pitch():
    positions, normals = pad_grid(14, 6, PITCH)
    assert positions.shape == normals.shape == (84, 3)
    np.testing.assert_allclose(positions.mean(axis=0), 0.0, atol=1e-15)
    # Active area 47.6 x 20.4 mm: centre span 13 x 5 pitches.
    np.testing.assert_allclose(np.ptp(positions, axis=0), [13 * PITCH, 5 * PITCH, 0.0])
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, 1.0], (84, 1)))
    # Row-major: index = row * cols + col, row along x, col along y.
    row, col = 9, 4
    np.testing.assert_allclose(
        positions[row * 6 + col], [(row - 6.5) * PITCH, (col - 2.5) * PITCH, 0.0]
    )
    assert np.all(np.diff(positions[:6, 1]) > 0) and np.all(np.diff(positions[::6, 0]) > 0)


def test_curved_rows_lie_on_the_arc_with_the_pitch_along_the_surface():
    radius = 0.059
    positions, normals = pad_grid(13, 6, PITCH, curved_rows=9, radius_m=radius)
    flat, _ = pad_grid(13, 6, PITCH)
    # The four flat rows are untouched.
    np.testing.assert_allclose(positions[: 4 * 6], flat[: 4 * 6])
    # The curve starts half a pitch past the last flat row, tangent to the flat part: its
    # centre is radius below that point.
    x_start = flat[3 * 6, 0] + PITCH / 2
    centre = np.array([x_start, -radius])
    curved = positions[4 * 6 :: 6][:, [0, 2]]
    np.testing.assert_allclose(np.linalg.norm(curved - centre, axis=1), radius, rtol=1e-12)
    # Consecutive row centres one pitch apart along the arc: chord = 2 R sin(p / 2R).
    chords = np.linalg.norm(np.diff(positions[3 * 6 :: 6], axis=0), axis=1)
    np.testing.assert_allclose(chords[1:], 2 * radius * np.sin(PITCH / (2 * radius)))
    # Across the flat-to-curve join: half a pitch flat, then half a pitch of arc.
    phi = PITCH / (2 * radius)
    join = np.hypot(PITCH / 2 + radius * np.sin(phi), radius * (1 - np.cos(phi)))
    assert chords[0] == pytest.approx(join)
    # Normals are unit, radial, and turn away from +z toward the tip (+x).
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    radial = (curved - centre) / radius
    np.testing.assert_allclose(normals[4 * 6 :: 6][:, [0, 2]], radial, atol=1e-12)
    assert np.all(np.diff(normals[::6, 0]) >= 0) and normals[-1, 0] > 0.4


@pytest.mark.parametrize(
    ("args", "message"),
    [((0, 6, PITCH), "rows"), ((14, 6, -1.0), "pitch"), ((14, 6, PITCH, 15), "curved_rows")],
)
def test_bad_grids_are_rejected(args, message):
    with pytest.raises(ValueError, match=message):
        pad_grid(*args)
    with pytest.raises(ValueError, match="radius"):
        pad_grid(13, 6, PITCH, curved_rows=2, radius_m=np.inf)


def _hamilton(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion product a * b, both (x, y, z, w)."""
    av, aw, bv, bw = a[:3], a[3], b[:3], b[3]
    return np.concatenate([aw * bv + bw * av + np.cross(av, bv), [aw * bw - av @ bv]])


def test_quaternions_to_matrices_rotate_like_the_quaternion_product():
    rng = np.random.default_rng(1)
    quaternions = rng.normal(size=(20, 4))
    quaternions *= rng.uniform(0.5, 2.0, (20, 1)) / np.linalg.norm(quaternions, axis=1)[:, None]
    rotations = rotations_from_quaternions(quaternions)
    for q, rotation in zip(quaternions, rotations, strict=True):
        unit = q / np.linalg.norm(q)
        conjugate = unit * np.array([-1.0, -1.0, -1.0, 1.0])
        for v in np.eye(3):
            rotated = _hamilton(_hamilton(unit, np.append(v, 0.0)), conjugate)[:3]
            np.testing.assert_allclose(rotation @ v, rotated, atol=1e-12)


def test_taxels_to_robot_matches_a_per_taxel_loop():
    rng = np.random.default_rng(0)
    positions, normals = pad_grid(14, 6, PITCH)
    pad_of_taxel = rng.integers(0, 3, len(positions))
    rotations = Rotation.random(3, random_state=2).as_matrix()
    origins = rng.normal(size=(3, 3))
    out_p, out_n = taxels_to_robot(positions, normals, pad_of_taxel, rotations, origins)
    for i, pad in enumerate(pad_of_taxel):
        np.testing.assert_allclose(out_p[i], rotations[pad] @ positions[i] + origins[pad])
        np.testing.assert_allclose(out_n[i], rotations[pad] @ normals[i])


def test_ray_segments_and_surface_gaps_invert_each_other():
    positions = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    starts, ends = ray_segments(positions, normals, 0.002, 0.005)
    np.testing.assert_allclose(starts, [[0, 0, -0.002], [0.998, 2, 3]])
    np.testing.assert_allclose(ends, [[0, 0, 0.005], [1.005, 2, 3]])
    # A hit 1 mm past the surface, one 0.5 mm pressed in, and no hit.
    fractions = np.array([0.003 / 0.007, 0.0015 / 0.007, 1.0])
    np.testing.assert_allclose(surface_gaps(fractions, 0.002, 0.005), [0.001, -0.0005, np.inf])


def test_segments_near_box_never_drops_a_segment_that_enters_the_box():
    rng = np.random.default_rng(5)
    starts = rng.uniform(-0.05, 0.05, (2000, 3))
    ends = starts + rng.normal(0.0, 0.01, (2000, 3))
    box_min, box_max = np.array([-0.01, -0.02, -0.005]), np.array([0.015, 0.01, 0.02])
    near = segments_near_box(starts, ends, box_min, box_max)
    samples = starts[:, None, :] + np.linspace(0, 1, 201)[None, :, None] * (ends - starts)[:, None]
    enters = np.any(np.all((samples >= box_min) & (samples <= box_max), axis=2), axis=1)
    assert enters.any() and (~near).any()
    assert np.all(near[enters])
    # A segment whose bounding box misses the box is dropped.
    assert not segments_near_box(
        np.array([[0.1, 0, 0]]), np.array([[0.2, 0, 0]]), box_min, box_max
    )[0]
