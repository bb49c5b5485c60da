"""The experiments ``symfuse sweep NAME`` runs, as one table (:data:`EXPERIMENTS`).

Most of the paper's experiments differ only in their constants, so they are rows of a
kind: :class:`SymmetryGrid` (Figs. 8 and 9: synthetic cylinder, theta x r grid per tactile
angle) and :class:`MeasureTable` (Tables 1-3: one dimension of one object per stage and
initialiser). The experiments with their own grid or report are modules
(:class:`ModuleExperiment`: Fig. 10, the spray bottle, the three-finger set, the
initialisers).

Every row offers what the sweep engine needs: ``name``, ``description``,
``config_sections`` (the config sections its trials read; None: all), ``reads_scans``
(whether it grasps the scans of ``symfuse sweep --scans DIR``), ``reads_captures`` (whether
it scores the labelled captures of ``--captures DIR``), ``randomised`` (whether it
draws its cases at random unless ``symfuse sweep --grid`` asks for the paper's grid),
``tasks(options)``, ``run_one`` (a top-level, picklable function from a task's JSON params
to its JSON row), ``worker_imports`` (the modules local workers load once, before any
task: :data:`TRIAL_WORKER_IMPORTS` for full trials; a module experiment's
``WORKER_IMPORTS``) and ``report(rows, out_dir)`` (the CSV, figures and ``report.md``). Nothing
heavy is imported until a row is run, so listing the experiments stays cheap.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from pipeline.experiments import ExperimentOptions, SweepTask


class Experiment(Protocol):
    """What ``symfuse sweep`` runs."""

    name: str

    @property
    def description(self) -> str: ...
    @property
    def config_sections(self) -> tuple[str, ...] | None: ...
    @property
    def reads_scans(self) -> bool: ...
    @property
    def reads_captures(self) -> bool: ...
    @property
    def randomised(self) -> bool: ...
    @property
    def run_one(self) -> Callable[[dict], dict[str, Any]]: ...
    @property
    def worker_imports(self) -> tuple[str, ...]: ...
    def tasks(self, options: ExperimentOptions) -> list[SweepTask]: ...
    def report(self, rows: list[dict], out_dir: Path) -> list[Path]: ...


#: What the workers of an experiment whose tasks are full trials load once, before any
#: task (:mod:`pipeline.experiments.trial_worker`).
TRIAL_WORKER_IMPORTS = ("pipeline.experiments.trial_worker",)

#: Trials of a randomised Fig. 8 or 9 study.
RANDOM_TRIALS = 400


@dataclass(frozen=True)
class SymmetryGrid:
    """Synthetic cylinder, one gripper: the final diameter error over the initial symmetry
    error ``theta x r`` and the tactile angle, zero bias (:mod:`.synthetic_study`).

    By default :data:`RANDOM_TRIALS` trials (``repeats`` when given, 6 with ``quick``) draw
    theta in 0..90 deg, r in -50..50 mm and the tactile angle in ``tactile_span_deg``
    uniformly (:func:`~.synthetic_report.report_random`: failing shares per grid angle).
    With ``grid`` the paper's: theta 0..90 deg (11.25 deg steps) x r -50..50 mm (10 mm
    steps) per tactile angle; ``quick`` keeps theta {0, 45} and r {-20, +20}.

    Attributes:
        figure: the paper's figure number.
        hand: the hand as the reports name it.
        gripper: ``"parallel"`` or ``"three_finger"``.
        tactile_angles_deg: the grasp angles relative to the view (deg) of the grid.
        tactile_span_deg: the range the randomised study draws the tactile angle from (deg).
        claims: the paper's statements, quoted in the report.
    """

    name: str
    figure: int
    hand: str
    gripper: str
    tactile_angles_deg: tuple[float, ...]
    tactile_span_deg: tuple[float, float]
    claims: tuple[str, ...]

    @property
    def description(self) -> str:
        return (
            f"synthetic cylinder, {self.hand}: diameter error vs symmetry error "
            f"(paper Fig. {self.figure})"
        )

    @property
    def title(self) -> str:
        return f"Fig. {self.figure}: {self.hand}, synthetic cylinder"

    @property
    def config_sections(self) -> tuple[str, ...]:
        from pipeline.experiments.synthetic_study import CONFIG_SECTIONS

        return CONFIG_SECTIONS

    reads_scans = False
    reads_captures = False
    randomised = True

    @property
    def run_one(self) -> Callable[[dict], dict[str, Any]]:
        from pipeline.experiments.synthetic_study import run_trial

        return run_trial

    worker_imports = ()

    def tasks(self, options: ExperimentOptions) -> list[SweepTask]:
        from pipeline.experiments.synthetic_study import (
            R_MM_FULL,
            THETA_DEG_FULL,
            Draws,
            grid_tasks,
            random_tasks,
        )

        if not options.grid:
            draws = Draws(self.tactile_span_deg, theta_deg=(0.0, 90.0), r_mm=(-50.0, 50.0))
            count = options.repeats or (6 if options.quick else RANDOM_TRIALS)
            return random_tasks(options, gripper=self.gripper, count=count, draws=draws)
        return grid_tasks(
            options,
            gripper=self.gripper,
            tactile_angles_deg=self.tactile_angles_deg,
            thetas_deg=(0.0, 45.0) if options.quick else THETA_DEG_FULL,
            rs_mm=(-20.0, 20.0) if options.quick else R_MM_FULL,
        )

    def report(self, rows: list[dict], out_dir: Path) -> list[Path]:
        from pipeline.experiments.synthetic_report import report_grid, report_random

        if rows and all("/trial" in row.get("key", "") for row in rows):
            return report_random(
                rows,
                out_dir,
                name=self.name,
                title=self.title,
                claims=self.claims,
                tactile_angles_deg=self.tactile_angles_deg,
            )
        return report_grid(rows, out_dir, name=self.name, title=self.title, claims=self.claims)


@dataclass(frozen=True)
class MeasureTable:
    """One catalogue object grasped with the PG-70 in simulation: one dimension measured per
    stage and initialiser, ours beside the paper's (:mod:`.measure_report`).

    Five poses (object yaw -30..30 deg around the reference view) per initialiser,
    ``repeats`` seeds each (default 1: the paper's five runs); ``quick`` keeps one pose per
    initialiser.

    Attributes:
        paper_table: the paper's table number.
        label: the object as the reports name it.
        object: catalogue name.
        measure: ``"thickness"`` (box-like: with the side angle) or ``"diameter"``.
        true_mm: the object's true dimension (mm).
        paper_error_pct: init -> (Stage 0, Stage 2) error of the mean (%) in the paper.
        target_pct: the largest acceptable Stage 2 error after fusion (%).
        inits: the initialisers compared.
    """

    name: str
    paper_table: int
    label: str
    object: str
    measure: str
    true_mm: float
    paper_error_pct: Mapping[str, tuple[float, float]]
    target_pct: float
    inits: tuple[str, ...] = ("ps", "vc")
    config_sections = None
    reads_scans = False
    reads_captures = False
    randomised = False

    @property
    def description(self) -> str:
        return (
            f"{self.label}, PG-70: {self.measure} per stage with PS and VC initialisation "
            f"(paper Table {self.paper_table})"
        )

    @property
    def title(self) -> str:
        return f"Table {self.paper_table}: {self.label}, PG-70"

    @property
    def run_one(self) -> Callable[[dict], dict[str, Any]]:
        from pipeline.experiments.paper_trial import run_paper_trial

        return run_paper_trial

    worker_imports = TRIAL_WORKER_IMPORTS

    def tasks(self, options: ExperimentOptions) -> list[SweepTask]:
        from pipeline.experiments.paper_tasks import (
            QUICK_VIEW_OFFSET_DEG,
            VIEW_OFFSETS_DEG,
            object_tasks,
        )

        offsets = (QUICK_VIEW_OFFSET_DEG,) if options.quick else VIEW_OFFSETS_DEG
        return object_tasks(options, self.object, inits=self.inits, view_offsets_deg=offsets)

    def report(self, rows: list[dict], out_dir: Path) -> list[Path]:
        from pipeline.experiments.measure_report import report_measure

        return report_measure(rows, out_dir, self)


@dataclass(frozen=True)
class ModuleExperiment:
    """An experiment with its own grid or report, implemented by a module exposing
    ``DESCRIPTION``, ``tasks``, ``run_one``, ``report`` and optionally ``CONFIG_SECTIONS``,
    ``READS_SCANS`` and ``WORKER_IMPORTS``."""

    name: str
    module_name: str

    @property
    def module(self) -> Any:
        return importlib.import_module(self.module_name)

    @property
    def description(self) -> str:
        return self.module.DESCRIPTION

    @property
    def config_sections(self) -> tuple[str, ...] | None:
        return getattr(self.module, "CONFIG_SECTIONS", None)

    @property
    def reads_scans(self) -> bool:
        return getattr(self.module, "READS_SCANS", False)

    @property
    def reads_captures(self) -> bool:
        return getattr(self.module, "READS_CAPTURES", False)

    @property
    def randomised(self) -> bool:
        return getattr(self.module, "RANDOMISED", False)

    @property
    def run_one(self) -> Callable[[dict], dict[str, Any]]:
        return self.module.run_one

    @property
    def worker_imports(self) -> tuple[str, ...]:
        return getattr(self.module, "WORKER_IMPORTS", ())

    def tasks(self, options: ExperimentOptions) -> list[SweepTask]:
        return self.module.tasks(options)

    def report(self, rows: list[dict], out_dir: Path) -> list[Path]:
        return self.module.report(rows, out_dir)


#: Tables 1-3: name, paper table, object label, catalogue name, measure, true size (mm), the
#: paper's error of the mean (%) at Stages 0 and 2 per initialiser, target after fusion (%).
_MEASURE_TABLES = (
    ("table1", 1, "CD drive", "cd_drive", "thickness", 42.0,
     {"ps": (11.3, 1.9), "vc": (37.6, 1.4)}, 1.9),
    ("table2", 2, "plastic case", "plastic_case", "thickness", 44.0,
     {"ps": (11.9, 3.4), "vc": (35.8, 3.5)}, 3.4),
    ("table3", 3, "salt cylinder", "salt_cylinder", "diameter", 53.0,
     {"ps": (14.1, 4.4), "vc": (14.3, 4.6)}, 4.4),
)  # fmt: skip

_ROWS: tuple[Experiment, ...] = (
    SymmetryGrid(
        name="fig8",
        figure=8,
        hand="parallel jaw",
        gripper="parallel",
        tactile_angles_deg=(0.0, 45.0, -45.0, 90.0, -90.0),
        tactile_span_deg=(-90.0, 90.0),
        claims=(
            "tactile angle 0: diameter error < 4 mm for theta up to 45 deg and |r| <= 30 mm",
            "tactile angle +-45: more sensitive to the initialisation",
            "tactile angle +-90 (grasped from the sides): large errors in r are not corrected",
        ),
    ),
    SymmetryGrid(
        name="fig9",
        figure=9,
        hand="three fingers",
        gripper="three_finger",
        # At 0 the thumb touches the front and two fingers the back; at 180 two fingers
        # touch the front.
        tactile_angles_deg=(0.0, 90.0, -90.0, 180.0),
        tactile_span_deg=(-135.0, 225.0),
        claims=(
            "tactile angle 180 (two contacts on the front) is the best, less sensitive to theta",
            "tactile angle 0: a large theta may leave a back finger without correspondences",
            "tactile angles +-90 work reasonably well (two fingers still touch front and back)",
        ),
    ),
    ModuleExperiment("fig10", "pipeline.experiments.fig10"),
    *(MeasureTable(*row) for row in _MEASURE_TABLES),
    ModuleExperiment("spray", "pipeline.experiments.spray"),
    ModuleExperiment("kth", "pipeline.experiments.kth"),
    ModuleExperiment("init", "pipeline.experiments.init"),
    ModuleExperiment("explore", "pipeline.experiments.explore"),
    ModuleExperiment("scenes", "pipeline.experiments.scenes"),
    ModuleExperiment("objects", "pipeline.experiments.objects"),
    ModuleExperiment("kinds", "pipeline.experiments.kinds"),
    ModuleExperiment("graspability", "pipeline.experiments.graspability"),
)

#: Experiment name -> its definition.
EXPERIMENTS: dict[str, Experiment] = {row.name: row for row in _ROWS}


def experiment_descriptions() -> dict[str, str]:
    """Experiment name -> its one-line description."""
    return {name: row.description for name, row in sorted(EXPERIMENTS.items())}
