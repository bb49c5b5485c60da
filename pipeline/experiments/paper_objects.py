"""Shared machinery of the paper's real-object experiments, reproduced in simulation.

Tables 1-3 (CD drive, plastic case, salt cylinder: thickness or diameter per stage), the
spray bottle (paper Figs. 14-19) and the three-finger set (Figs. 20-23). One task is one full
simulated trial (:func:`pipeline.trial.run_trial`): an object, an initialiser (``ps`` or
``vc``), an object yaw and a seed.

Object yaw. The paper placed each object "in different pose compared to Kinect". Here a
trial's ``view_offset_deg`` is its yaw relative to the *reference view*, the yaw at which
the catalogue's symmetry-plane normal points along the camera's viewing direction (the
camera sees one half of the object squarely and mirroring completes the other; for
rotational objects the reference yaw is 0). The actual ``yaw_deg`` given to the trial is
stored in the params beside it. The camera is the sensors' default viewpoint (azimuth
:data:`CAMERA_AZIMUTH_DEG` about +z, looking at the object).

Task parameters (JSON; units in the names):

    object             catalogue name or mesh path
    init               initialiser name (``ps``, ``vc``)
    gripper            ``pg70`` | ``sdh``
    view_offset_deg    yaw relative to the reference view; yaw_deg: the trial's object yaw
    seed               the trial's seed (scene, sensor and tactile noise)
    overrides          further ``--set`` strings of the experiment (planner, sensor)
    config             the user's config values other than the estimator's, where they
                       differ from the defaults; the trial's config starts from them
    estimator          estimator name; estimator_params: its parameters
    trial_dir          folder for the trial's files, or None (a temporary folder, deleted)

Result rows (flat; ``k`` = stage 0, 1, 2): ``failed`` (None, or the reason a stage refused:
empty segmentation, refused or unexecuted grasp, rejected initialisation), ``status`` (the
final stage's, or ``"failed"``), ``diverged``, ``points``, ``taxels_in_contact``,
``seconds``, ``timings``, and per stage ``stage{k}_status``, ``stage{k}_iterations``,
``stage{k}_deviation_{min,q1,median,q3,max,mean}_mm`` and every scalar metric of
:func:`pipeline.evaluation.evaluate_stage` as ``stage{k}_<metric>`` (thickness, side angle,
diameter, plane errors, and the shape scores: ``chamfer_mm``, ``precision_2mm``,
``recall_2mm``, ``fscore_2mm``, the same at 5 mm, ``iou``).

Every report has a "Shape scores" table (Chamfer distance, F-score at 2 and 5 mm, IoU per
stage and group) and those scores per trial, beside the paper's measures.
"""

from __future__ import annotations

import contextlib
import functools
import math
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from ..catalogue import list_objects
from ..errors import ConfigError, StageFailure
from ..formats import consistency_fields
from ..perception.grasp_geometry import narrowest_width
from ..plots import BoxPanel, box_plot_figure
from ..sim.camera import CameraParams
from ..sweep import write_csv
from . import ExperimentOptions, SweepTask
from .synthetic_study import failures_section, fmt, task_seed

#: Camera azimuth about +z of the simulated sensors' default viewpoint (deg).
CAMERA_AZIMUTH_DEG = float(CameraParams.azimuth_deg)
#: Object yaws relative to the reference view (deg): five poses, like the paper's five runs.
VIEW_OFFSETS_DEG = (-30.0, -15.0, 0.0, 15.0, 30.0)
#: The view offset of ``quick`` runs (deg).
QUICK_VIEW_OFFSET_DEG = 10.0
#: A trial diverged when the estimator says so, or when its final median deviation from the
#: true surface exceeds Stage 0's by more than this (mm).
DIVERGED_GROWTH_MM = 5.0
#: "Clearly better than Stage 0": the final error is at most this fraction of Stage 0's.
CLEARLY_BETTER_RATIO = 0.5
#: The paper's average deviation after fusion "when the method's conditions hold" (mm).
DEVIATION_TARGET_MM = 5.0
#: Deviation summary fields, in box-plot order, then the mean.
FIVE_NUMBERS = ("min", "q1", "median", "q3", "max")
STAGES = (0, 1, 2)
#: Display names of the initialisers.
INIT_LABELS = {"ps": "PS", "vc": "VC", "pca": "PCA"}
#: The shape scores the reports show per stage: (row field after ``stage{k}_``, column
#: label, decimals). See :func:`pipeline.evaluation.shape_scores`.
SHAPE_SCORES = (
    ("chamfer_mm", "Chamfer (mm)", 1),
    ("fscore_2mm", "F@2mm", 2),
    ("fscore_5mm", "F@5mm", 2),
    ("iou", "IoU", 2),
)


# ------------------------------------------------------------------------- tasks


def reference_yaw_deg(object_name: str) -> float:
    """The yaw (deg, in (-90, 90]) at which the object's symmetry-plane normal lies along the
    camera's viewing direction; 0 for objects without a single mirror plane."""
    infos = {info.name: info for info in list_objects()}
    if object_name not in infos:
        raise ConfigError(f"experiment object '{object_name}' is not in the catalogue")
    plane = infos[object_name].symmetry_plane
    if plane is None:
        return 0.0
    yaw = (CAMERA_AZIMUTH_DEG - math.degrees(plane.theta_rad)) % 180.0
    return yaw - 180.0 if yaw > 90.0 else yaw


def trial_root(options: ExperimentOptions) -> Path | None:
    """Where per-trial folders go: ``<out_dir>/trials``, or None (trial files not kept)."""
    return None if options.out_dir is None else Path(options.out_dir) / "trials"


def user_settings(options: ExperimentOptions) -> dict[str, Any]:
    """The user's config changes a trial starts from (``config`` in the params); the
    estimator's travel as ``estimator`` and ``estimator_params``."""
    return {section: value for section, value in options.config.items() if section != "estimator"}


def paper_task(key: str, params: dict[str, Any]) -> SweepTask:
    """The task of ``params``, its :attr:`SweepTask.settings` from :func:`trial_overrides`."""
    return SweepTask(key=key, params=params, settings=tuple(trial_overrides(params)))


def object_tasks(
    options: ExperimentOptions,
    object_name: str,
    *,
    inits: Sequence[str],
    view_offsets_deg: Sequence[float],
    gripper: str = "pg70",
    overrides: Sequence[str] = (),
    repeats: int | None = None,
) -> list[SweepTask]:
    """One task per (init, view offset, repeat) for ``object_name``: ``repeats`` trials with
    different seeds per pose (default ``options.repeats``, else 1)."""
    root = trial_root(options)
    base_yaw = reference_yaw_deg(object_name)
    repeats = repeats or options.repeats or 1
    tasks = []
    for init in inits:
        for offset in view_offsets_deg:
            for repeat in range(repeats):
                key = f"{object_name}/{init}/view{offset:+g}/rep{repeat}"
                tasks.append(
                    paper_task(
                        key,
                        {
                            "object": object_name,
                            "init": init,
                            "gripper": gripper,
                            "view_offset_deg": float(offset),
                            "yaw_deg": float(base_yaw + offset),
                            "seed": task_seed(options.seed, key),
                            "overrides": list(overrides),
                            "config": user_settings(options),
                            "estimator": options.estimator,
                            "estimator_params": dict(options.estimator_params),
                            "trial_dir": None if root is None else str(root / key),
                        },
                    )
                )
    return tasks


def toml_value(value: Any) -> str:
    """``value`` as a TOML literal, for the right-hand side of a ``--set`` override."""
    return tomli_w.dumps({"v": value}).partition("=")[2].strip()


#: The paper's grasps, whatever the planners' defaults: closing along the proposed plane's
#: normal at the object's top (``strategy = "paper"`` of both shipped planners).
PAPER_GRASP = ("planner.top-parallel.strategy=paper", "planner.top-three-finger.strategy=paper")


def trial_overrides(params: Mapping[str, Any]) -> list[str]:
    """The ``--set`` strings that turn the sweep's config into the trial of ``params``: its
    object, hand, seed, yaw and initialiser, the paper's grasp strategy
    (:data:`PAPER_GRASP`, unless ``paper_grasp`` is false: the planners' own), the
    experiment's overrides and the estimator."""
    estimator = params["estimator"]
    overrides = [
        f"trial.object={toml_value(params['object'])}",
        f"trial.gripper={params['gripper']}",
        *(PAPER_GRASP if params.get("paper_grasp", True) else ()),
        f"trial.seed={int(params['seed'])}",
        f"trial.yaw_deg={toml_value(float(params['yaw_deg']))}",
        f"initialiser.use={params['init']}",
        *params["overrides"],
        f"estimator.use={estimator}",
    ]
    overrides += [
        f"estimator.{estimator}.{key}={toml_value(value)}"
        for key, value in params["estimator_params"].items()
    ]
    return overrides


def trial_config(params: Mapping[str, Any]):
    """The resolved config of the trial of ``params``: the defaults, then the user's
    changes (``config``), then the experiment's :func:`trial_overrides`."""
    from ..config import load_config

    return load_config(
        _registry(), settings=params.get("config", {}), overrides=trial_overrides(params)
    )


@functools.cache
def _registry():
    from ..registry import load_registry

    return load_registry()


def run_paper_trial(params: Mapping[str, Any]) -> dict[str, Any]:
    """Run one trial from its task params and return its result row (see the module doc).

    The trial runs with :func:`trial_config`. Its folder is replaced whole (a re-run never
    mixes files of two runs). A :class:`StageFailure` becomes a row with ``failed`` set; any other
    exception propagates (the sweep engine records it as an error row).
    """
    from ..outdir import staged_output
    from ..trial import run_trial

    registry = _registry()
    config = trial_config(params)
    started = time.perf_counter()
    with contextlib.ExitStack() as stack:
        trial_dir = params.get("trial_dir")
        if trial_dir is None:
            trial_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="symfuse-"))
        try:
            with staged_output(Path(trial_dir), overwrite=True) as staging:
                record = run_trial(config, registry, staging)
        except StageFailure as exc:
            return {
                "failed": str(exc),
                "status": "failed",
                "diverged": False,
                "seconds": time.perf_counter() - started,
            }
        row = trial_row(record.document, record.metrics)
    row["seconds"] = time.perf_counter() - started
    return row


def trial_row(document: Mapping[str, Any], metrics: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The flat result row of a finished trial from its ``result.json`` document and the
    per-stage metrics (deviations converted to millimetres)."""
    row: dict[str, Any] = {
        "failed": None,
        "status": document["status"],
        "points": document.get("points"),
        "taxels_in_contact": document.get("taxels_in_contact"),
        "timings": dict(document.get("timings", {})),
        "selected_stage": document.get("selected_stage"),
    }
    for stage_json, stage_metrics in zip(document["stages"], metrics, strict=True):
        prefix = f"stage{stage_json['stage']}"
        row[f"{prefix}_status"] = stage_json.get("status")
        row[f"{prefix}_iterations"] = stage_json.get("iterations")
        row.update(consistency_fields(prefix, stage_json.get("consistency")))
        for name, value in stage_metrics.items():
            if name == "deviation_m":
                for field, metres in value.items():
                    if field != "count":
                        row[f"{prefix}_deviation_{field}_mm"] = 1e3 * float(metres)
            elif name == "thickness_error" and isinstance(value, str):
                row[f"{prefix}_thickness_fit_failed"] = value
            elif isinstance(value, int | float):
                row[f"{prefix}_{name}"] = float(value)
    row["diverged"] = is_diverged(row)
    if document.get("next_grasp"):
        row["stop_reason"] = document.get("stop_reason")
        row["grasps_made"] = len(document["grasps"])
        for entry in document["grasps"]:
            row.update(grasp_fields(entry))
    return row


def grasp_fields(entry: Mapping[str, Any]) -> dict[str, Any]:
    """The row fields of one grasp of a multi-grasp trial (``grasp{k}_...``): how it was
    chosen, its taxels, and Stage 2's and the selected stage's deviation, plane errors,
    status and consistency after fusing it, with the stop rule's two stds (mm)."""
    prefix = f"grasp{entry['grasp']}"
    fields: dict[str, Any] = {
        f"{prefix}_strategy": entry["chosen_by"]["strategy"],
        f"{prefix}_taxels": entry["taxels_in_contact"],
        f"{prefix}_selected_stage": entry["selected_stage"],
        f"{prefix}_offset_std_mm": entry["uncertainty"]["plane_offset_std_mm"],
        f"{prefix}_hidden_std_mm": entry["uncertainty"]["hidden_side_std_mm"],
    }
    for label, stage in (
        ("stage2", entry["stages"][-1]),
        ("selected", entry["stages"][entry["selected_stage"]]),
    ):
        metrics = stage["metrics"]
        consistency = stage.get("consistency") or {}
        fields.update(
            {
                f"{prefix}_{label}_status": stage["status"],
                f"{prefix}_{label}_consistent": consistency.get("consistent"),
                f"{prefix}_{label}_deviation_median_mm": 1e3 * metrics["deviation_m"]["median"],
                f"{prefix}_{label}_plane_angle_error_deg": metrics.get("plane_angle_error_deg"),
                f"{prefix}_{label}_plane_offset_error_mm": metrics.get("plane_offset_error_mm"),
            }
        )
    return fields


def is_diverged(row: Mapping[str, Any]) -> bool:
    """See :data:`DIVERGED_GROWTH_MM`."""
    last = max((k for k in STAGES if f"stage{k}_status" in row), default=None)
    if last is None:
        return False
    if row[f"stage{last}_status"] == "diverged":
        return True
    first = row.get("stage0_deviation_median_mm")
    final = row.get(f"stage{last}_deviation_median_mm")
    if first is None or final is None:
        return False
    return bool(final - first > DIVERGED_GROWTH_MM)


# ------------------------------------------------------------------------- scanned meshes


def scan_trial_params(
    mesh_path: Path,
    *,
    seed: int = 0,
    estimator: str = "iekf",
    estimator_params: Mapping[str, Any] | None = None,
    trial_dir: Path | None = None,
) -> dict[str, Any]:
    """Task params of one trial on a scanned mesh file (e.g. a YCB ``textured.obj``).

    The PG-70 is used when the object's narrowest horizontal width plus the parallel-jaw
    planner's default jaw clearance fits the PG-70 aperture (PS initialisation, the narrow
    direction turned toward the camera so the jaws close along it); otherwise the SDH-2
    (VC initialisation, three-finger top grasp, object yaw 0).
    """
    from ..catalogue import load_object
    from ..sim.hands import GRIPPERS

    mesh = load_object(mesh_path).mesh
    width_m, direction_rad = narrowest_width(np.asarray(mesh.vertices)[:, :2])
    clearance_m = _registry().get("planner", "top-parallel").cls.Params().jaw_clearance_m
    if width_m + clearance_m <= GRIPPERS["pg70"].max_aperture_m:
        gripper, init, overrides = "pg70", "ps", []
        yaw_deg = math.degrees(math.radians(CAMERA_AZIMUTH_DEG) - direction_rad)
    else:
        gripper, init, overrides = "sdh", "vc", ["planner.use=top-three-finger"]
        yaw_deg = 0.0
    return {
        "object": str(mesh_path),
        "init": init,
        "gripper": gripper,
        "view_offset_deg": 0.0,
        "yaw_deg": (yaw_deg + 180.0) % 360.0 - 180.0,
        "narrowest_width_mm": 1e3 * width_m,
        "seed": int(seed),
        "overrides": overrides,
        "estimator": estimator,
        "estimator_params": dict(estimator_params or {}),
        "trial_dir": None if trial_dir is None else str(trial_dir),
    }


# ------------------------------------------------------------------------- row selection


@dataclass(frozen=True)
class RowCounts:
    """How the rows of one group ended: finished, failed (a stage refused), diverged,
    raised (an exception: the sweep's error rows)."""

    total: int
    finished: int
    failed: int
    diverged: int
    raised: int

    def text(self) -> str:
        return (
            f"{self.finished}/{self.total} finished, {self.failed} failed, "
            f"{self.diverged} diverged, {self.raised} raised"
        )


def finished_rows(rows: Iterable[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Rows of trials that ran to the end (neither raised nor failed)."""
    return [row for row in rows if "error" not in row and not row.get("failed")]


def count_rows(rows: Sequence[Mapping[str, Any]]) -> RowCounts:
    finished = finished_rows(rows)
    return RowCounts(
        total=len(rows),
        finished=len(finished),
        failed=sum(1 for row in rows if "error" not in row and row.get("failed")),
        diverged=sum(1 for row in finished if row.get("diverged")),
        raised=sum(1 for row in rows if "error" in row),
    )


def failure_lines(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """``key: reason`` for every row that raised or failed."""
    lines = []
    for row in rows:
        if "error" in row:
            lines.append(f"{row.get('key', '?')}: {row['error']}")
        elif row.get("failed"):
            lines.append(f"{row.get('key', '?')}: failed: {row['failed']}")
    return lines


def value(row: Mapping[str, Any], name: str) -> float:
    """A numeric field of a row; NaN when missing or None."""
    field = row.get(name)
    return math.nan if field is None else float(field)


def group_rows(
    rows: Iterable[Mapping[str, Any]], key: Callable[[Mapping[str, Any]], Any]
) -> dict[Any, list[Mapping[str, Any]]]:
    """Rows grouped by ``key(row)``, groups in first-seen order."""
    groups: dict[Any, list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault(key(row), []).append(row)
    return groups


def mean_value(rows: Sequence[Mapping[str, Any]], name: str) -> float:
    """The mean of a numeric field over ``rows``, ignoring missing values; NaN if none."""
    values = np.array([value(row, name) for row in rows])
    return float(np.nanmean(values)) if np.isfinite(values).any() else math.nan


def mean_five_numbers(rows: Sequence[Mapping[str, Any]], stage: int) -> np.ndarray:
    """The deviation box (min, q1, median, q3, max; mm) of ``stage`` averaged over ``rows``:
    the paper's Fig. 23 averages the box-and-whisker data of an object's poses."""
    table = np.array(
        [[value(row, f"stage{stage}_deviation_{name}_mm") for name in FIVE_NUMBERS] for row in rows]
    )
    return np.nanmean(table, axis=0)


# ------------------------------------------------------------------------- figures


def deviation_box_figure(
    categories: Sequence[tuple[float, Sequence[Mapping[str, Any]]]],
    out_path: Path,
    *,
    xlabel: str,
    title: str,
) -> Path:
    """Deviation box-and-whisker plots, one panel per stage, one box per category.

    Each box is the category's averaged five-number summary (:func:`mean_five_numbers`).
    It is drawn by handing :func:`pipeline.plots.box_plot_figure` those five values as the
    sample: their 0/25/50/75/100th percentiles (linear interpolation) are exactly the five
    values, so the drawn box is the summary itself.
    """
    panels = []
    for stage in STAGES:
        panels.append(
            BoxPanel(
                f"Stage {stage}",
                np.array([position for position, _ in categories], dtype=np.float64),
                [mean_five_numbers(group, stage) for _, group in categories],
            )
        )
    return box_plot_figure(
        panels,
        out_path,
        xlabel=xlabel,
        ylabel="deviation from the true surface (mm)",
        threshold=DEVIATION_TARGET_MM,
        ylim=(0.0, 40.0),
        title=title,
    )


# ------------------------------------------------------------------------- shape scores

#: Per-trial table columns of the shape scores.
SHAPE_HEADER = [f"{label} S0 / S1 / S2" for _, label, _ in SHAPE_SCORES]


def shape_cells(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """One ``S0 / S1 / S2`` cell per shape score, each stage's mean over ``rows`` (one row:
    that trial's scores)."""
    return [
        " / ".join(fmt(mean_value(rows, f"stage{k}_{field}"), digits) for k in STAGES)
        for field, _, digits in SHAPE_SCORES
    ]


def shape_score_section(groups: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """The "Shape scores" table: per group, the shape scores averaged over its finished
    trials, per stage."""
    lines = [
        "## Shape scores",
        "",
        "Symmetric Chamfer distance between the completed model and the true surface (mm, "
        "lower is better), F-score at 2 and 5 mm (share of the model within the distance of "
        "the true surface and of the true surface within it of the model, combined; 1 is "
        "perfect) and the volumetric IoU of the model's convex hull with the true solid. "
        "The true surface leaves out the face the object stands on. Averaged over a group's "
        "finished trials.",
        "",
        "| group | trials | " + " | ".join(SHAPE_HEADER) + " |",
        "|---|---|" + "---|" * len(SHAPE_HEADER),
    ]
    for label, group in groups.items():
        cells = shape_cells(finished_rows(group))
        lines.append(f"| {label} | {count_rows(group).text()} | " + " | ".join(cells) + " |")
    return lines


# ------------------------------------------------------------------------- measure tables


@dataclass(frozen=True)
class MeasureStudy:
    """A Table 1-3 style study: one dimension measured per stage and initialiser.

    Attributes:
        name: experiment name (file names).
        title: report title.
        measure: ``"thickness"`` (box-like: with the side angle) or ``"diameter"``.
        true_mm: the object's true dimension (mm).
        paper_error_pct: init -> (Stage 0, Stage 2) error of the mean (%) in the paper.
        target_pct: the largest acceptable Stage 2 error after fusion (%).
    """

    name: str
    title: str
    measure: str
    true_mm: float
    paper_error_pct: Mapping[str, tuple[float, float]]
    target_pct: float


def measure_statistics(
    rows: Sequence[Mapping[str, Any]], measure: str, true_mm: float, stage: int
) -> dict[str, float]:
    """Mean and std (mm) of the measured dimension over ``rows`` at ``stage``, the error of
    the mean in percent (the paper's "error %"), and the mean per-trial absolute error (%).
    NaN when no row has the measure."""
    values = np.array([value(row, f"stage{stage}_{measure}_mm") for row in rows])
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return {"mean": math.nan, "std": math.nan, "error_pct": math.nan, "abs_error_pct": math.nan}
    mean = float(np.mean(values))
    return {
        "mean": mean,
        "std": float(np.std(values, ddof=1)) if len(values) > 1 else 0.0,
        "error_pct": abs(mean - true_mm) / true_mm * 100.0,
        "abs_error_pct": float(np.mean(np.abs(values - true_mm))) / true_mm * 100.0,
    }


def _measure_table(rows: Sequence[Mapping[str, Any]], study: MeasureStudy, init: str) -> list[str]:
    """The paper-style table of one initialiser: one line per trial, then mean, std, error."""
    with_angle = study.measure == "thickness"
    unit = f"{study.measure.capitalize()} (mm)"
    header = ["trial", "view (deg)", f"{unit} S0", "S1", "S2"]
    if with_angle:
        header += ["Angle (deg) S0", "S1", "S2"]
    header += [*SHAPE_HEADER, "final status"]
    lines = [
        f"### {INIT_LABELS.get(init, init)}-initialisation",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    finished = finished_rows(rows)
    for number, row in enumerate(finished, start=1):
        cells = [str(number), f"{row['params']['view_offset_deg']:+g}"]
        cells += [fmt(value(row, f"stage{k}_{study.measure}_mm"), 2) for k in STAGES]
        if with_angle:
            cells += [fmt(value(row, f"stage{k}_side_angle_deg"), 2) for k in STAGES]
        cells += shape_cells([row])
        cells.append(str(row.get("status")) + (" (diverged)" if row.get("diverged") else ""))
        lines.append("| " + " | ".join(cells) + " |")
    statistics = [measure_statistics(finished, study.measure, study.true_mm, k) for k in STAGES]
    angles = [
        np.array([value(row, f"stage{k}_side_angle_deg") for row in finished]) for k in STAGES
    ]
    no_shape = [""] * len(SHAPE_HEADER)
    blank = [""] * (3 if with_angle else 0) + no_shape + [""]
    for label, field in (("mean", "mean"), ("std. dev.", "std")):
        cells = [label, ""] + [fmt(s[field], 2) for s in statistics]
        if with_angle:
            reduce = np.nanmean if field == "mean" else _nanstd
            cells += [fmt(float(reduce(a)), 2) if np.isfinite(a).any() else "-" for a in angles]
        cells += shape_cells(finished) if field == "mean" else no_shape
        lines.append("| " + " | ".join([*cells, ""]) + " |")
    for label, field in (
        ("error % (of the mean)", "error_pct"),
        ("mean abs. error %", "abs_error_pct"),
    ):
        cells = [label, ""] + [f"{fmt(s[field])} %" for s in statistics] + blank
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _nanstd(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.std(finite, ddof=1)) if len(finite) > 1 else 0.0


def report_measure(
    rows: Sequence[Mapping[str, Any]], out_dir: Path, study: MeasureStudy
) -> list[Path]:
    """``results.csv``, ``<name>_error.png`` (per-trial error % per stage and init),
    ``<name>_deviation.png`` (deviation boxes per init and stage) and ``report.md`` (the
    paper-style table per init, ours beside the paper's numbers, targets met or missed)."""
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    by_init = group_rows(rows, lambda row: row["params"]["init"])
    lines = [
        f"# {study.title}",
        "",
        f"True {study.measure}: {study.true_mm:g} mm. Every trial is one simulated grasp "
        "(object yaw relative to the reference view in the 'view' column). 'error %' is the "
        "paper's: |mean - true| / true; the mean per-trial absolute error is given too.",
        "",
        "## Ours beside the paper",
        "",
        "| init | trials | S0 error % ours (paper) | S2 error % ours (paper) | S2 mean abs. "
        f"error % | S2 <= {study.target_pct:g} % | S2 <= {CLEARLY_BETTER_RATIO:g} x S0 |",
        "|---|---|---|---|---|---|---|",
    ]
    verdicts = []
    tables: list[str] = []
    for init, group in by_init.items():
        finished = finished_rows(group)
        stage0 = measure_statistics(finished, study.measure, study.true_mm, 0)
        stage2 = measure_statistics(finished, study.measure, study.true_mm, 2)
        paper0, paper2 = study.paper_error_pct.get(init, (math.nan, math.nan))
        accurate = bool(stage2["error_pct"] <= study.target_pct)
        better = bool(stage2["error_pct"] <= CLEARLY_BETTER_RATIO * stage0["error_pct"])
        verdicts.append((accurate, better))
        lines.append(
            f"| {INIT_LABELS.get(init, init)} | {count_rows(group).text()} "
            f"| {fmt(stage0['error_pct'])} ({fmt(paper0)}) | {fmt(stage2['error_pct'])} "
            f"({fmt(paper2)}) | {fmt(stage2['abs_error_pct'])} | {_met(accurate)} "
            f"| {_met(better)} |"
        )
        tables += ["", *_measure_table(group, study, init)]
    ps_diverged = count_rows(by_init.get("ps", [])).diverged
    lines += [
        "",
        f"- Stage 2 error <= {study.target_pct:g} % (paper's after-fusion figure): "
        f"{_met(bool(verdicts) and all(a for a, _ in verdicts))} "
        f"({sum(a for a, _ in verdicts)}/{len(verdicts)} initialisers).",
        f"- Stage 2 clearly better than Stage 0 (error at most {CLEARLY_BETTER_RATIO:g} x "
        f"Stage 0's): {_met(bool(verdicts) and all(b for _, b in verdicts))} "
        f"({sum(b for _, b in verdicts)}/{len(verdicts)} initialisers).",
        f"- No diverged trial with PS: {_met(ps_diverged == 0)} "
        f"({ps_diverged} diverged). A trial diverges when the estimator says so or its median "
        f"deviation grows by more than {DIVERGED_GROWTH_MM:g} mm over Stage 0.",
        "",
        *shape_score_section(
            {INIT_LABELS.get(init, init): group for init, group in by_init.items()}
        ),
        "",
        "## Per trial",
        *tables,
    ]
    figures = _measure_figures(by_init, out_dir, study)
    lines += ["", *[f"![{path.stem}]({path.name})" for path in figures]]
    lines += failures_section(failure_lines(rows))
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, *figures, report_path]


def _met(condition: bool) -> str:
    return "met" if condition else "MISSED"


def _measure_figures(
    by_init: Mapping[str, Sequence[Mapping[str, Any]]], out_dir: Path, study: MeasureStudy
) -> list[Path]:
    inits = [init for init, group in by_init.items() if finished_rows(group)]
    if not inits:
        return []
    panels = []
    for init in inits:
        finished = finished_rows(by_init[init])
        samples = []
        for stage in STAGES:
            measured = np.array(
                [value(row, f"stage{stage}_{study.measure}_mm") for row in finished]
            )
            measured = measured[np.isfinite(measured)]
            samples.append(np.abs(measured - study.true_mm) / study.true_mm * 100.0)
        panels.append(
            BoxPanel(f"{INIT_LABELS.get(init, init)}-initialisation", np.array(STAGES), samples)
        )
    error_path = box_plot_figure(
        panels,
        out_dir / f"{study.name}_error.png",
        xlabel="stage",
        ylabel=f"{study.measure} error (%)",
        threshold=study.target_pct,
        title=f"{study.title}: per-trial {study.measure} error",
    )
    categories = [(float(i), finished_rows(by_init[init])) for i, init in enumerate(inits, start=1)]
    labels = ", ".join(
        f"{i} {INIT_LABELS.get(init, init)}" for i, init in enumerate(inits, start=1)
    )
    deviation_path = deviation_box_figure(
        categories,
        out_dir / f"{study.name}_deviation.png",
        xlabel=f"initialisation ({labels})",
        title=f"{study.title}: deviation (mean box over trials)",
    )
    return [error_path, deviation_path]


# ------------------------------------------------------------------------- deviation studies


def deviation_verdict(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Stage 0/1/2 averaged medians and means of the deviation over finished ``rows`` (mm)
    and whether Stage 2's median is below Stage 0's."""
    finished = finished_rows(rows)
    summary: dict[str, Any] = {}
    for stage in STAGES:
        for field in ("median", "mean"):
            summary[f"stage{stage}_{field}"] = mean_value(
                finished, f"stage{stage}_deviation_{field}_mm"
            )
    summary["improves"] = bool(summary["stage2_median"] < summary["stage0_median"])
    return summary


def report_deviation(
    rows: Sequence[Mapping[str, Any]],
    out_dir: Path,
    *,
    name: str,
    title: str,
    groups: Mapping[str, Sequence[Mapping[str, Any]]],
    figures: Sequence[tuple[str, Sequence[tuple[float, Sequence[Mapping[str, Any]]]], str]],
    paper: Sequence[str],
) -> list[Path]:
    """``results.csv``, deviation box plots and ``report.md`` of a geometric-deviation study.

    Args:
        groups: label -> rows; the targets are checked per group (an object, or an
            object with one initialiser): Stage 2 median deviation below Stage 0's, and the
            mean deviation after fusion averaged over all groups <= 5 mm.
        figures: (file stem, categories, x label) per figure; categories are (position,
            rows) pairs for :func:`deviation_box_figure`.
        paper: the paper's statements, quoted in the report.
    """
    out_dir = Path(out_dir)
    csv_path = write_csv(rows, out_dir / "results.csv")
    lines = [f"# {title}", "", "Paper:", "", *[f"- {claim}" for claim in paper], ""]
    lines += [
        "Ours: deviation of every completed point from the true surface (mm), per trial "
        "summarised as min/q1/median/q3/max/mean; below, averaged over a group's finished "
        "trials.",
        "",
        "| group | trials | median S0 / S1 / S2 | mean S0 / S1 / S2 | S2 median < S0 |",
        "|---|---|---|---|---|",
    ]
    verdicts = {}
    for label, group in groups.items():
        summary = deviation_verdict(group)
        verdicts[label] = summary
        medians = " / ".join(fmt(summary[f"stage{k}_median"]) for k in STAGES)
        means = " / ".join(fmt(summary[f"stage{k}_mean"]) for k in STAGES)
        lines.append(
            f"| {label} | {count_rows(group).text()} | {medians} | {means} "
            f"| {'yes' if summary['improves'] else 'NO'} |"
        )
    finals = [v["stage2_mean"] for v in verdicts.values() if math.isfinite(v["stage2_mean"])]
    average = float(np.mean(finals)) if finals else math.nan
    improving = [label for label, v in verdicts.items() if v["improves"]]
    counts = count_rows(rows)
    lines += [
        "",
        f"- Stage 2 median deviation below Stage 0 on every group: "
        f"{_met(bool(verdicts) and len(improving) == len(verdicts))} "
        f"({len(improving)}/{len(verdicts)}).",
        f"- Mean deviation after fusion, averaged over the groups: {fmt(average)} mm "
        f"(target <= {DEVIATION_TARGET_MM:g} mm): "
        f"{_met(average <= DEVIATION_TARGET_MM)}.",
        f"- Trials: {counts.text()} (diverged: the estimator says so or the median deviation "
        f"grows by more than {DIVERGED_GROWTH_MM:g} mm over Stage 0).",
    ]
    lines += ["", *shape_score_section(groups)]
    lines += ["", "## Per trial", "", *_deviation_trial_table(rows)]
    paths = []
    for stem, categories, xlabel in figures:
        usable = [(position, finished_rows(group)) for position, group in categories]
        usable = [(position, group) for position, group in usable if group]
        if not usable:
            continue
        path = deviation_box_figure(
            usable, out_dir / f"{stem}.png", xlabel=xlabel, title=f"{title} ({stem})"
        )
        paths.append(path)
        lines += ["", f"![{stem}]({path.name})"]
    lines += failures_section(failure_lines(rows))
    report_path = out_dir / "report.md"
    report_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [csv_path, *paths, report_path]


def _deviation_trial_table(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per finished trial: median deviation, plane errors and shape scores per
    stage."""
    header = [
        "trial",
        "median dev. S0 / S1 / S2 (mm)",
        "plane angle err. S0 / S2 (deg)",
        "plane offset err. S0 / S2 (mm)",
        *SHAPE_HEADER,
        "final status",
    ]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in finished_rows(rows):
        medians = " / ".join(fmt(value(row, f"stage{k}_deviation_median_mm")) for k in STAGES)
        angles = " / ".join(fmt(value(row, f"stage{k}_plane_angle_error_deg")) for k in (0, 2))
        offsets = " / ".join(fmt(value(row, f"stage{k}_plane_offset_error_mm")) for k in (0, 2))
        status = str(row.get("status")) + (" (diverged)" if row.get("diverged") else "")
        cells = [str(row.get("key", "?")), medians, angles, offsets, *shape_cells([row]), status]
        lines.append("| " + " | ".join(cells) + " |")
    return lines
