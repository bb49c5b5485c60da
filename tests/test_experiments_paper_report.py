"""The real-object experiments' rows and reports, on rows of real simulated trials.

The module fixture runs two trials through the sweep engine: the CD drive with the PG-70
(PS initialisation, the IEKF capped at 2 iterations to keep it short), and the coffee can
(99 mm) with the PG-70, whose grasp the planner must refuse (a ``failed`` row).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from pipeline.experiments import EXPERIMENTS, ExperimentOptions
from pipeline.experiments.deviation_report import report_deviation
from pipeline.experiments.measure_report import report_measure
from pipeline.experiments.paper_tasks import object_tasks
from pipeline.experiments.paper_trial import run_paper_trial
from pipeline.experiments.sweep import run_sweep

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    root = tmp_path_factory.mktemp("paper")
    options = ExperimentOptions(estimator="iekf", estimator_params={"max_iterations": 2})
    tasks = object_tasks(options, "cd_drive", inits=("ps",), view_offsets_deg=(10.0,))
    tasks += object_tasks(options, "coffee", inits=("ps",), view_offsets_deg=(0.0,))
    tasks = [
        type(task)(task.key, {**task.params, "trial_dir": str(root / "trials" / str(n))})
        for n, task in enumerate(tasks)
    ]
    rows = run_sweep(tasks, run_paper_trial, root / "results.jsonl", workers=1, progress=False)
    return root, rows


def test_a_finished_trial_row_matches_its_files(sweep):
    _, rows = sweep
    row = rows[0]
    assert "error" not in row
    assert row["failed"] is None
    trial_dir = row["params"]["trial_dir"]
    document = json.loads(Path(trial_dir, "result.json").read_text())
    assert row["status"] == document["status"]
    assert row["points"] == document["points"]
    mesh = trimesh.load(f"{trial_dir}/object_final.ply", force="mesh")
    for stage in document["stages"]:
        k = stage["stage"]
        assert row[f"stage{k}_thickness_mm"] == pytest.approx(stage["metrics"]["thickness_mm"])
        # independent oracle: trimesh's closest points on every 10th completed point
        completed = np.asarray(trimesh.load(f"{trial_dir}/completed_stage{k}.ply").vertices)
        _, distances, _ = trimesh.proximity.closest_point(mesh, completed[::10])
        assert row[f"stage{k}_deviation_median_mm"] == pytest.approx(
            1e3 * np.median(distances), abs=1.0
        )
        assert row[f"stage{k}_deviation_max_mm"] >= 1e3 * distances.max() - 1e-6
    assert row["seconds"] > 0.0


def test_shape_scores_match_independent_oracles(sweep):
    """Chamfer distance and F-score from trimesh's closest points and an independently seeded
    surface sample; IoU from an exact mesh boolean of the model's hull with the true mesh."""
    row = sweep[1][0]
    trial_dir = row["params"]["trial_dir"]
    mesh = trimesh.load(f"{trial_dir}/object_final.ply", force="mesh")
    bottom = mesh.face_normals[:, 2] < -0.95
    top = mesh.copy()
    top.update_faces(~bottom)
    truth = np.asarray(trimesh.sample.sample_surface(top, 20_000, seed=11)[0])
    for k in (0, 2):
        completed = np.asarray(trimesh.load(f"{trial_dir}/completed_stage{k}.ply").vertices)
        _, to_truth, _ = trimesh.proximity.closest_point(mesh, completed[::5])
        to_model, _ = cKDTree(completed).query(truth)
        chamfer_mm = 0.5e3 * (to_truth.mean() + to_model.mean())
        assert row[f"stage{k}_chamfer_mm"] == pytest.approx(chamfer_mm, abs=0.1)
        precision, recall = np.mean(to_truth < 0.005), np.mean(to_model < 0.005)
        fscore = 2 * precision * recall / (precision + recall)
        assert row[f"stage{k}_fscore_5mm"] == pytest.approx(fscore, abs=0.02)
        hull = trimesh.convex.convex_hull(completed)
        common = trimesh.boolean.intersection([hull, mesh], engine="manifold").volume
        iou = common / (hull.volume + mesh.volume - common)
        assert row[f"stage{k}_iou"] == pytest.approx(iou, abs=0.01)


def test_a_refused_grasp_becomes_a_failed_row(sweep):
    _, rows = sweep
    row = rows[1]
    assert "error" not in row
    assert "refused" in row["failed"]
    assert row["status"] == "failed"
    assert not row["diverged"]


def test_measure_report_lists_each_trial_and_the_papers_numbers(sweep, tmp_path):
    _, rows = sweep
    paths = report_measure(rows, tmp_path, EXPERIMENTS["table1"])
    assert [p.name for p in paths] == [
        "results.csv",
        "table1_error.png",
        "table1_deviation.png",
        "report.md",
    ]
    for path in paths[1:3]:
        assert path.read_bytes()[:8] == PNG_SIGNATURE
    text = (tmp_path / "report.md").read_text()
    row = rows[0]
    for k in (0, 1, 2):
        assert f"{row[f'stage{k}_thickness_mm']:.2f}" in text
    error_pct = abs(row["stage2_thickness_mm"] - 42.0) / 42.0 * 100.0
    assert f"| {error_pct:.1f} (1.9) |" in text
    chamfers = " / ".join(f"{row[f'stage{k}_chamfer_mm']:.1f}" for k in (0, 1, 2))
    ious = " / ".join(f"{row[f'stage{k}_iou']:.2f}" for k in (0, 1, 2))
    assert "## Shape scores" in text
    assert f"| PS | 1/2 finished, 1 failed, 0 diverged, 0 raised | {chamfers} |" in text
    assert f"| {ious} | converged" in text or f"| {ious} | max_iterations" in text
    assert "1/2 finished, 1 failed, 0 diverged, 0 raised" in text
    assert "coffee/ps/view+0/rep0: failed:" in text
    with open(tmp_path / "results.csv", newline="") as handle:
        table = list(csv.DictReader(handle))
    assert [line["key"] for line in table] == [r["key"] for r in rows]
    assert float(table[0]["stage2_thickness_mm"]) == pytest.approx(row["stage2_thickness_mm"])
    assert table[1]["stage2_thickness_mm"] == ""


def test_deviation_report_averages_the_finished_trials(sweep, tmp_path):
    _, rows = sweep
    paths = report_deviation(
        rows,
        tmp_path,
        name="demo",
        title="demo",
        groups={"all": rows},
        figures=[("demo_boxes", [(1.0, rows)], "group")],
        paper=("a claim",),
    )
    assert [p.name for p in paths] == ["results.csv", "demo_boxes.png", "report.md"]
    assert paths[1].read_bytes()[:8] == PNG_SIGNATURE
    text = paths[2].read_text()
    row = rows[0]
    medians = " / ".join(f"{row[f'stage{k}_deviation_median_mm']:.1f}" for k in (0, 1, 2))
    assert f"| all | 1/2 finished, 1 failed, 0 diverged, 0 raised | {medians} |" in text
    improves = row["stage2_deviation_median_mm"] < row["stage0_deviation_median_mm"]
    assert ("| yes |" if improves else "| NO |") in text
    fscores = " / ".join(f"{row[f'stage{k}_fscore_2mm']:.2f}" for k in (0, 1, 2))
    assert "## Shape scores" in text
    assert f" | {fscores} | " in text.split("## Per trial")[1]


def test_the_deviation_report_sets_the_bias_error_beside_the_claimed_std(sweep, tmp_path):
    _, rows = sweep
    row = rows[0]
    document = json.loads(Path(row["params"]["trial_dir"], "result.json").read_text())
    metrics = document["stages"][2]["metrics"]
    assert row["stage2_bias_along_error_mm"] == pytest.approx(metrics["bias_along_error_mm"])
    assert row["stage2_bias_nees"] == pytest.approx(metrics["bias_nees"])
    report_deviation(
        rows, tmp_path, name="demo", title="demo", groups={"all": rows}, figures=[], paper=()
    )
    text = (tmp_path / "report.md").read_text()
    cells = " | ".join(
        f"{abs(row[f'stage2_bias_{name}_error_{unit}']):.1f} / "
        f"{row[f'stage2_bias_{name}_std_{unit}']:.1f}"
        for name, unit in (("across", "mm"), ("along", "mm"), ("yaw", "deg"))
    )
    outside = " / ".join(f"{100 * (row[f'stage{k}_bias_nees'] > 13.2767):.0f} %" for k in (1, 2))
    assert f"| all | 1 | {cells} | {outside} |" in text.split("## Bias against the truth")[1]
