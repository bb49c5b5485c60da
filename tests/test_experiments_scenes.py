"""``symfuse sweep scenes``: the outcome of each labelled object, categories, bad input,
and (with ``SYMFUSE_CAPTURES`` naming a folder of labelled captures) a real scene."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from pipeline.experiments.scenes import category, object_outcomes, run_one


def test_each_outcome_by_hand():
    objects = np.zeros((4, 10), dtype=int)
    found = np.full((4, 10), -1)
    # Object 1 (10 px) is symfuse object 0 alone: isolated.
    objects[0] = 1
    found[0] = 0
    # Object 2 (10 px) lies in symfuse object 1 with 5 table pixels: 10 / 15 < 80 %, merged.
    objects[1] = 2
    found[1] = 1
    found[2, :5] = 1
    # Object 3 (5 px) is split 2 + 2 (+1 unfound): 80 % covered, none holds half.
    objects[2, 5:] = 3
    found[2, 5:7], found[2, 7:9] = 2, 3
    # Object 4 (10 px) has 4 px in symfuse object 4: missed.
    objects[3] = 4
    found[3, :4] = 4
    outcomes = object_outcomes(objects, found)
    assert [o["outcome"] for o in outcomes] == ["isolated", "merged", "split", "missed"]
    assert outcomes[1]["purity"] == pytest.approx(10 / 15)
    assert outcomes[2]["share"] == pytest.approx(0.4)
    assert [o["points"] for o in outcomes] == [10, 10, 5, 10]


def test_categories_from_subfolders_and_osd_names():
    root = Path("/data")
    assert category(root / "stacked" / "a.pcd", root) == "stacked"
    assert category(root / "learn16.pcd", root) == "boxes"
    assert category(root / "learn17.pcd", root) == "stacked"
    assert category(root / "learn44.pcd", root) == "cylinders"
    assert category(root / "kitchen.pcd", root) == "all"


def test_captures_are_checked_before_the_sweep(tmp_path, run):
    code, _, err = run("sweep", "scenes", "--out", tmp_path / "a")
    assert code == 2 and "--captures" in err
    code, _, err = run("sweep", "scenes", "--captures", tmp_path / "none", "--out", tmp_path / "b")
    assert code == 2 and "no such folder" in err
    code, _, err = run("sweep", "fig10", "--captures", tmp_path, "--out", tmp_path / "c")
    assert code == 2 and "reads no captures" in err
    (tmp_path / "plain.pcd").write_text(
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n0 0 1\n"
    )
    code, _, err = run("sweep", "scenes", "--captures", tmp_path, "--out", tmp_path / "d")
    assert code == 2 and "no 'label' field" in err


CAPTURES = os.environ.get("SYMFUSE_CAPTURES", "").strip()


@pytest.mark.slow
@pytest.mark.skipif(
    not (CAPTURES and (Path(CAPTURES) / "learn17.pcd").is_file()),
    reason="SYMFUSE_CAPTURES names no folder with the OSD learn split",
)
def test_two_stacked_boxes_are_two_objects():
    row = run_one({"path": str(Path(CAPTURES) / "learn17.pcd"), "category": "stacked"})
    assert row["plane_ok"]
    assert [o["outcome"] for o in row["objects"]] == ["isolated", "isolated"]
