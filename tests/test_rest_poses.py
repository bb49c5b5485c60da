"""Resting poses (``trial.rest``): a box rests on its faces, a pose number beyond the mesh's
count is refused, and a lying cylinder's true axis is level."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pipeline.catalogue.objects import load_object
from pipeline.catalogue.rest import at_rest, drawn_pose, parse_rest, rest_pose, stable_poses
from pipeline.config import load_config
from pipeline.errors import EXIT_BAD_INPUT, ConfigError, InputError
from pipeline.registry import load_registry
from pipeline.symmetry.scoring import true_kind
from pipeline.types import Symmetry

BOX_EXTENTS = (0.12, 0.06, 0.03)


@pytest.fixture(scope="module")
def box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=BOX_EXTENTS)


def test_a_box_rests_on_each_of_its_faces_the_largest_most_likely(box):
    transforms, probabilities = stable_poses(box)
    assert len(transforms) == 6
    assert probabilities.sum() == pytest.approx(1.0)
    # Each pose turns one face's outward normal straight down, and the box rests on it:
    # its lowest point on z = 0 and its height the extent across that face.
    down = []
    for transform in transforms:
        placed = box.copy().apply_transform(transform)
        assert placed.bounds[0][2] == pytest.approx(0.0, abs=1e-9)
        normals = placed.face_normals
        assert np.isclose(normals[:, 2], -1.0).any()
        down.append(float(placed.extents[2]))
    # Most likely first: on a big face (the thinnest extent up), last on a small one.
    assert down[0] == pytest.approx(min(BOX_EXTENTS))
    assert down[-1] == pytest.approx(max(BOX_EXTENTS))
    assert sorted(down) == pytest.approx(sorted(2 * list(BOX_EXTENTS)))
    assert np.all(np.diff(probabilities) <= 1e-12)


def test_a_pose_beyond_the_count_is_refused_naming_the_count(box):
    with pytest.raises(InputError, match="has 6 stable poses, numbered 0 to 5"):
        rest_pose(box, 6, seed=0)


def test_a_random_rest_is_repeatable_and_drawn_by_probability(box):
    _, probabilities = stable_poses(box)
    assert [rest_pose(box, "random", seed).index for seed in range(5)] == [
        drawn_pose(probabilities, seed) for seed in range(5)
    ]
    drawn = [drawn_pose(probabilities, seed) for seed in range(1000)]
    shares = np.bincount(drawn, minlength=6) / len(drawn)
    # 1000 draws: a share's standard error is at most 1.6 points.
    assert np.abs(shares - probabilities).max() < 0.05


@pytest.mark.parametrize("text", ["foo", "-1", "1.5", "", "٣"])
def test_a_rest_that_is_no_pose_is_refused(text):
    with pytest.raises(ConfigError, match=r"'trial\.rest'"):
        parse_rest(text)


def test_the_config_refuses_a_bad_rest_and_reads_a_good_one():
    registry = load_registry()
    assert load_config(registry, overrides=['trial.rest="random"']).trial.rest == "random"
    with pytest.raises(ConfigError, match=r"'trial\.rest'"):
        load_config(registry, overrides=['trial.rest="sideways"'])


def test_a_lying_cylinder_has_a_level_true_axis_and_rests_on_the_table():
    obj = load_object("salt_cylinder")
    transforms, _ = stable_poses(obj.mesh)
    lying = next(k for k, t in enumerate(transforms) if abs(t[2, 2]) < 0.5)
    rested = at_rest(obj, lying, seed=0)
    assert rested.rest is not None and not rested.rest.keeps_vertical
    assert rested.mesh.bounds[0][2] == pytest.approx(0.0, abs=1e-9)
    assert rested.mesh.bounds[:, :2].sum(axis=0) == pytest.approx([0.0, 0.0], abs=1e-9)
    # Lying, it is as long as the cylinder is tall and as high as it is wide.
    assert rested.mesh.extents[2] == pytest.approx(obj.mesh.extents[0], rel=0.02)
    axes = [s for s in rested.symmetries if s.kind == "axis"]
    assert len(axes) == 1
    assert abs(axes[0].direction[2]) < 1e-3  # the searched axis: within 0.06 deg
    # The axis runs through the middle of the lying cylinder, half its width up.
    assert axes[0].point_m[2] == pytest.approx(rested.mesh.extents[2] / 2.0, abs=1e-3)
    assert rested.symmetry == "none" and rested.symmetry_plane is None
    # A body of revolution in any pose: lying, its axis is level.
    assert true_kind(rested.symmetries) == "axis"
    assert true_kind(obj.symmetries or _searched(obj)) == "axis"


def _searched(obj) -> tuple[Symmetry, ...]:
    from pipeline.symmetry.truth_file import true_symmetries

    return true_symmetries(obj)


def test_a_box_on_its_edge_is_a_plane_kind():
    # A box turned 30 deg about x: its mirror planes with normals y and z lean.
    turn = trimesh.transformations.rotation_matrix(np.radians(30.0), [1.0, 0.0, 0.0])
    planes = [Symmetry("plane", turn[:3, :3] @ np.eye(3)[k], np.zeros(3)) for k in (1, 2)]
    assert true_kind(planes) == "plane"
    assert true_kind([*planes, Symmetry("plane", [1.0, 0.0, 0.0], np.zeros(3))]) == (
        "vertical-plane"
    )
    assert true_kind([]) == "none"


def test_upright_leaves_the_object_as_loaded():
    obj = load_object("cd_drive")
    assert at_rest(obj, parse_rest("upright"), seed=3) is obj


def test_trial_rest_beyond_the_count_is_one_line_and_leaves_nothing(run, tmp_path):
    code, _, err = run("trial", "--object", "cd_drive", "--rest", "99", "--out", tmp_path / "o")
    assert code == EXIT_BAD_INPUT
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("symfuse: error: --rest 99"), err
    assert "stable poses" in lines[0]
    assert not (tmp_path / "o").exists()
