"""Paper Figs. 20-23: the three-finger set (SDH-2, stereo head, VC initialisation).

Eight objects with the paper's number of poses each (Table 4: box 4, bread 1, coffee 5,
cup 8, jam 3, salt cylinder 2, salt box 5, sedan 1), spread evenly over object yaws of
-30..30 deg around each object's reference view; ``repeats`` overrides the count for every
object. ``quick`` runs one pose of two objects. The report draws the paper's Fig. 23:
deviation box-and-whiskers per object and stage, each box averaged over the object's poses.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.experiments import ExperimentOptions, SweepTask
from pipeline.experiments.definitions import TRIAL_WORKER_IMPORTS
from pipeline.experiments.deviation_report import report_deviation
from pipeline.experiments.paper_tasks import QUICK_VIEW_OFFSET_DEG, object_tasks
from pipeline.experiments.paper_trial import run_paper_trial
from pipeline.experiments.rows import group_rows

NAME = "kth"
#: Each task is a full trial: the workers load its modules once.
WORKER_IMPORTS = TRIAL_WORKER_IMPORTS

DESCRIPTION = "three-finger set, SDH-2 + stereo, VC: deviation per object and stage (paper Fig. 23)"

#: Catalogue object -> number of poses in the paper (Table 4).
POSES = {
    "box": 4,
    "bread": 1,
    "coffee": 5,
    "cup": 8,
    "jam": 3,
    "salt_cylinder_kth": 2,
    "saltbox": 5,
    "sedan": 1,
}
QUICK_OBJECTS = ("box", "coffee")
#: Half-width of the yaw range the poses are spread over (deg).
YAW_SPREAD_DEG = 30.0
OVERRIDES = ("planner.use=top-three-finger", "sensor.use=pybullet-stereo")
PAPER = (
    "Fusion improves the reconstruction for most objects (box, coffee, cup, sedan); the "
    "deformable bread and the rigid salt cylinder gain little or lose slightly; one of three "
    "jam cases diverges (front-to-front initialisation).",
    "Overall about 5 mm average deviation after fusion when the method's conditions hold.",
)


def view_offsets(count: int) -> tuple[float, ...]:
    """``count`` yaws evenly spread over +-:data:`YAW_SPREAD_DEG` (0 for a single pose)."""
    if count == 1:
        return (0.0,)
    return tuple(float(v) for v in np.linspace(-YAW_SPREAD_DEG, YAW_SPREAD_DEG, count))


def tasks(options: ExperimentOptions) -> list[SweepTask]:
    if options.quick:
        plan = {name: (QUICK_VIEW_OFFSET_DEG,) for name in QUICK_OBJECTS}
    else:
        plan = {name: view_offsets(options.repeats or count) for name, count in POSES.items()}
    result = []
    for name, offsets in plan.items():
        result += object_tasks(
            options,
            name,
            inits=("vc",),
            view_offsets_deg=offsets,
            gripper="sdh",
            overrides=OVERRIDES,
            repeats=1,
        )
    return result


def run_one(params: dict) -> dict[str, Any]:
    return run_paper_trial(params)


def report(rows: list[dict], out_dir: Path) -> list[Path]:
    """``results.csv``, ``kth.png`` (deviation boxes per object and stage) and ``report.md``;
    the targets are checked per object."""
    order = list(POSES)
    by_object = dict(
        sorted(
            group_rows(rows, lambda row: row["params"]["object"]).items(),
            key=lambda item: order.index(item[0]) if item[0] in order else len(order),
        )
    )
    categories = [(float(i), group) for i, group in enumerate(by_object.values(), start=1)]
    labels = [f"{i} {name}" for i, name in enumerate(by_object, start=1)]
    legend = "\n".join(", ".join(labels[i : i + 3]) for i in range(0, len(labels), 3))
    return report_deviation(
        rows,
        out_dir,
        name=NAME,
        title="Three-finger set, SDH-2, VC",
        groups=by_object,
        figures=[(NAME, categories, f"object:\n{legend}")],
        paper=PAPER,
    )
