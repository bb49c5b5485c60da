"""Saving camera images: PNG contents, the NaN colour, and the raw depth array."""

from __future__ import annotations

import matplotlib.colors
import matplotlib.image
import numpy as np
import pytest

from pipeline.io.images import (
    MISSING_COLOUR,
    save_depth,
    save_depth_npy,
    save_observation,
    save_rgb,
)
from pipeline.types import CameraIntrinsics, DepthObservation


def gradient_depth(missing: bool) -> np.ndarray:
    depth = np.tile(np.linspace(0.6, 2.0, 160, dtype=np.float32), (120, 1))
    if missing:
        depth[40:80, 60:100] = np.nan
    return depth


def count_colour(png: np.ndarray, colour: str) -> int:
    rgb = np.asarray(matplotlib.colors.to_rgb(colour))
    return int(np.sum(np.all(np.abs(png[..., :3] - rgb) < 0.02, axis=-1)))


def test_rgb_png_round_trips(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    path = save_rgb(tmp_path / "rgb.png", rgb)
    read = matplotlib.image.imread(path)
    np.testing.assert_array_equal(np.rint(read[..., :3] * 255).astype(np.uint8), rgb)


def test_rgb_rejects_non_images(tmp_path):
    with pytest.raises(ValueError, match="uint8"):
        save_rgb(tmp_path / "bad.png", np.zeros((4, 4)))


def test_depth_png_shows_missing_pixels_in_their_own_colour(tmp_path):
    with_gaps = matplotlib.image.imread(save_depth(tmp_path / "a.png", gradient_depth(True)))
    without = matplotlib.image.imread(save_depth(tmp_path / "b.png", gradient_depth(False)))
    # The NaN block (40 x 40 image pixels) appears in the missing colour; the legend swatch
    # is there in both.
    assert count_colour(with_gaps, MISSING_COLOUR) > count_colour(without, MISSING_COLOUR) + 800
    assert with_gaps.shape[1] > 160  # room for the colourbar


def test_depth_png_of_an_all_missing_image(tmp_path):
    depth = np.full((30, 40), np.nan, dtype=np.float32)
    assert save_depth(tmp_path / "empty.png", depth).is_file()


def test_depth_npy_keeps_values_and_nans(tmp_path):
    depth = gradient_depth(True)
    read = np.load(save_depth_npy(tmp_path / "depth.npy", depth))
    assert read.dtype == np.float32
    np.testing.assert_array_equal(read, depth)


def test_save_observation_writes_the_three_files(tmp_path):
    depth = gradient_depth(True)
    observation = DepthObservation(
        depth_m=depth,
        rgb=np.zeros((120, 160, 3), dtype=np.uint8),
        intrinsics=CameraIntrinsics(160, 120, 150.0, 150.0, 79.5, 59.5),
        T_robot_camera=np.eye(4),
    )
    paths = save_observation(tmp_path / "view", observation)
    assert [p.name for p in paths] == ["rgb.png", "depth.png", "depth.npy"]
    assert all(p.is_file() for p in paths)
    np.testing.assert_array_equal(np.load(paths[2]), depth)
