"""Segmentation of real scenes against per-object labels: ``symfuse sweep scenes --captures DIR``.

Every organised PCD under DIR with a ``label`` field (the Object Segmentation Database's
convention: 0 no return or unlabelled, 1-9 the supporting table, ``10 k .. 10 k + 9`` the
parts of object ``k``) runs through what ``symfuse complete`` does before completion: the
``recorded`` sensor (support plane and frame) and the segmenter, objects at the edge of the
view set aside. Each labelled object then ends one of four ways (:func:`object_outcomes`):

- *isolated*: one symfuse object holds at least half of its points and is made at least
  80 % of them;
- *merged*: one symfuse object holds at least half of its points but is mostly made of
  other things (neighbours, the table);
- *split*: the objects found cover at least half of it, but none holds half;
- *missed*: less than half of it is in any object (cut away with the table, set aside at
  the edge of the view, or the run found no support plane).

The *plane* of a scene is right when at least 90 % of its table pixels lie within 15 mm of
the support plane found. A scene's category is its subfolder under DIR; in a flat folder,
files named ``learnN`` follow the OSD learn split (boxes, stacked, occluded, cylinders) and
anything else is ``all``.
"""

from __future__ import annotations

import re
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ConfigError, InputError, StageFailure
from pipeline.experiments import ExperimentOptions, SweepTask
from pipeline.experiments.common import fmt, plugin_registry

DESCRIPTION = "real labelled captures (--captures DIR): objects isolated/merged/split/missed"
CONFIG_SECTIONS = ("sensor", "segmenter")
READS_CAPTURES = True
OUTCOMES = ("isolated", "merged", "split", "missed")
#: Least share of an object's points one symfuse object must hold to have found it.
MIN_SHARE = 0.5
#: Least share of a symfuse object the labelled object must make for it to be isolated.
MIN_PURITY = 0.8
#: A table pixel this close to the support plane (m) is on it; a right plane holds
#: :data:`MIN_TABLE_SHARE` of them.
TABLE_TOLERANCE_M = 0.015
MIN_TABLE_SHARE = 0.9
#: The OSD learn split: the last file number of each category.
OSD_LEARN_CATEGORIES = ((16, "boxes"), (24, "stacked"), (32, "occluded"), (44, "cylinders"))


def capture_files(folder: Path) -> list[Path]:
    """The labelled PCDs under ``folder``, in natural order (learn2 before learn10).

    Raises:
        ConfigError: no such folder, no PCD in it, or a PCD without a ``label`` field.
    """
    from pipeline.io.captures import _pcd_header

    if not Path(folder).is_dir():
        raise ConfigError(f"--captures {folder}: no such folder")
    files = sorted(Path(folder).rglob("*.pcd"), key=natural_key)
    if not files:
        raise ConfigError(f"--captures {folder}: no *.pcd in that folder")
    for path in files:
        if "label" not in _pcd_header(path).get("FIELDS", []):
            raise ConfigError(f"--captures: {path} has no 'label' field (FIELDS ...)")
    return files


def natural_key(path: Path) -> tuple:
    """Sort key that orders the numbers inside names by value."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", str(path)))


def category(path: Path, folder: Path) -> str:
    """The scene's category: its subfolder under ``folder``, else the OSD learn split's
    category of a ``learnN`` file, else ``all``."""
    relative = Path(path).relative_to(folder)
    if len(relative.parts) > 1:
        return relative.parts[0]
    match = re.fullmatch(r"learn(\d+)", relative.stem)
    if match:
        number = int(match.group(1))
        for last, name in OSD_LEARN_CATEGORIES:
            if number <= last:
                return name
    return "all"


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    if options.captures is None:
        raise ConfigError("sweep scenes: give the labelled captures with --captures DIR")
    folder = Path(options.captures)
    files = capture_files(folder)
    if options.quick:
        files = files[:: max(1, len(files) // 4)][:4]
    return [
        SweepTask(
            key=str(path.relative_to(folder).with_suffix("")),
            params={
                "path": str(path),
                "category": category(path, folder),
                "config": dict(options.config),
            },
        )
        for path in files
    ]


def read_labels(path: Path) -> np.ndarray:
    """The ``label`` field of an organised PCD as an ``(H, W)`` int array."""
    from pipeline.io.captures import _pcd_header
    from pipeline.io.open3d_loader import open3d

    header = _pcd_header(path)
    width, height = int(header["WIDTH"][0]), int(header["HEIGHT"][0])
    cloud = open3d().t.io.read_point_cloud(
        str(path), remove_nan_points=False, remove_infinite_points=False
    )
    if "label" not in cloud.point:
        raise InputError(f"{path}: open3d read no 'label' field")
    return cloud.point["label"].numpy().astype(np.int64).reshape(height, width)


def object_outcomes(objects: np.ndarray, found: np.ndarray) -> list[dict[str, Any]]:
    """How each labelled object came out.

    Args:
        objects: ``(H, W)`` labelled object per pixel (> 0), 0 for none.
        found: ``(H, W)`` symfuse object per pixel (>= 0), -1 for none.

    Returns:
        Per labelled object, in label order: ``object``, ``points``, ``outcome`` (one of
        :data:`OUTCOMES`), ``share`` (of its points in the symfuse object holding most of
        them) and ``purity`` (its share of that symfuse object).
    """
    sizes = np.bincount(found[found >= 0].ravel()) if (found >= 0).any() else np.zeros(0, int)
    result = []
    for label in np.unique(objects[objects > 0]):
        mine = found[objects == label]
        covered = mine[mine >= 0]
        share = purity = 0.0
        if len(covered):
            counts = np.bincount(covered)
            best = int(np.argmax(counts))
            share = counts[best] / len(mine)
            purity = counts[best] / sizes[best]
        if share >= MIN_SHARE:
            outcome = "isolated" if purity >= MIN_PURITY else "merged"
        else:
            outcome = "split" if len(covered) >= MIN_SHARE * len(mine) else "missed"
        result.append(
            {
                "object": int(label),
                "points": len(mine),
                "outcome": outcome,
                "share": float(share),
                "purity": float(purity),
            }
        )
    return result


def run_one(params: dict) -> dict[str, Any]:
    """One capture: support plane, segmentation, and each labelled object's outcome."""
    import json

    from pipeline.config import load_config
    from pipeline.run.completion import segment_scene

    path = Path(params["path"])
    registry = plugin_registry()
    config = load_config(
        registry,
        settings=params.get("config", {}),
        overrides=['sensor.use="recorded"', f"sensor.recorded.path={json.dumps(str(path))}"],
    )
    labels = read_labels(path)
    row: dict[str, Any] = {"category": params["category"]}
    started = time.perf_counter()
    found = np.full(labels.shape, -1)
    valid = labels >= 20
    try:
        observation = config.create(registry, "sensor").observe(None)
        valid = np.isfinite(observation.depth_m)
        row["sensor_s"] = time.perf_counter() - started
        started = time.perf_counter()
        segmenter = config.create(registry, "segmenter")
        observation, clouds, set_aside = segment_scene(segmenter, observation)
        row["segmenter_s"] = time.perf_counter() - started
        row["kept"], row["set_aside"] = len(clouds), len(set_aside)
        for index, cloud in enumerate(clouds):
            found[cloud.pixels[:, 0], cloud.pixels[:, 1]] = index
        row["plane_ok"] = bool(table_share(labels, observation) >= MIN_TABLE_SHARE)
    except (InputError, StageFailure) as exc:
        row["failure"] = str(exc)
        row["plane_ok"] = False
    objects = np.where(valid & (labels >= 20), labels // 10, 0)
    row["objects"] = object_outcomes(objects, found)
    return row


def table_share(labels: np.ndarray, observation) -> float:
    """Share of the table pixels (labels 1-9) within :data:`TABLE_TOLERANCE_M` of the
    support plane of ``observation`` (``z = table_height_m`` in its robot frame)."""
    from pipeline.perception.depth import backproject_depth

    points, pixels = backproject_depth(
        observation.depth_m, observation.intrinsics, observation.T_robot_camera
    )
    table = (labels[pixels[:, 0], pixels[:, 1]] >= 1) & (labels[pixels[:, 0], pixels[:, 1]] <= 9)
    if not table.any():
        return 0.0
    height = points[table, 2] - (observation.table_height_m or 0.0)
    return float(np.mean(np.abs(height) < TABLE_TOLERANCE_M))


def summary(rows: Sequence[dict]) -> list[list[Any]]:
    """Per category and over all: scenes, planes right, objects, each outcome, % isolated,
    median sensor and segmenter seconds."""
    groups: dict[str, list[dict]] = {}
    for row in rows:
        if "error" not in row:
            groups.setdefault(row["category"], []).append(row)
    table = []
    for name, group in [*sorted(groups.items()), ("all", [r for g in groups.values() for r in g])]:
        outcomes = [entry["outcome"] for row in group for entry in row["objects"]]
        counts = [outcomes.count(outcome) for outcome in OUTCOMES]
        times = [
            np.median([row[key] for row in group if key in row] or [np.nan])
            for key in ("sensor_s", "segmenter_s")
        ]
        table.append(
            [
                name,
                len(group),
                sum(row["plane_ok"] for row in group),
                len(outcomes),
                *counts,
                fmt(100.0 * counts[0] / max(len(outcomes), 1), 0),
                *(fmt(t, 2) for t in times),
            ]
        )
    return table


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv`` (one row per labelled object) and ``report.md`` (per category)."""
    from pipeline.experiments.sweep import write_csv
    from pipeline.reports.tables import format_table

    flat = [
        {"scene": row["key"], "category": row["category"], **entry}
        for row in rows
        if "error" not in row
        for entry in row["objects"]
    ]
    csv_path = write_csv(flat, Path(out_dir) / "results.csv")
    header = ["category", "scenes", "plane ok", "objects", *OUTCOMES, "% isolated"]
    header += ["sensor s", "segmenter s"]
    lines = [
        "# Scenes: labelled objects isolated, merged, split or missed",
        "",
        "An object is isolated when one symfuse object holds >= 50 % of its points and is "
        "made >= 80 % of them; missed when < 50 % of it is in any object (median seconds "
        "per scene).",
        "",
        "```",
        format_table(header, summary(rows)),
        "```",
    ]
    failures = [f"{row['key']}: {row['failure']}" for row in rows if "failure" in row]
    failures += [f"{row['key']}: {row['error']}" for row in rows if "error" in row]
    if failures:
        lines += ["", f"## Scenes without objects ({len(failures)})", ""]
        lines += [f"- `{line}`" for line in failures]
    report_path = Path(out_dir) / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, report_path]
