"""The ``symfuse`` command line.

Every deliberate failure (:class:`~pipeline.errors.SymfuseError`) is printed as one line,
``symfuse: error: ...``, with its exit code (2 for bad input or config, 3 for a run whose
estimate failed); ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from . import __version__
from .errors import ConfigError, SymfuseError
from .stages import STAGES
from .tables import format_table

#: Exit code of a run that wrote its results but whose estimate failed.
EXIT_ESTIMATE_FAILED = 3


def _add_config_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        action="append",
        type=Path,
        default=[],
        metavar="FILE",
        help="TOML config merged over the defaults (repeatable; later files win)",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override one config value, e.g. --set estimator.use=icp (repeatable)",
    )


def _load(args: argparse.Namespace, extra_overrides: Sequence[str] = ()):
    from .config import load_config
    from .registry import load_registry

    registry = load_registry()
    config = load_config(registry, args.config, [*args.overrides, *extra_overrides])
    return registry, config


# --- symfuse plugins -------------------------------------------------------------------


def _cmd_plugins(args: argparse.Namespace) -> int:
    from .params import describe
    from .registry import load_registry

    registry = load_registry()
    rows = []
    for stage in STAGES:
        names = registry.names(stage)
        if not names:
            rows.append([stage, "(none installed)", "", "", ""])
        for name in names:
            reg = registry.get(stage, name)
            rows.append(
                [stage, name, reg.origin.distribution, reg.origin.version, reg.cls.description()]
            )
    print(format_table(["stage", "name", "distribution", "version", "description"], rows))
    if args.params:
        for registration in registry.registrations():
            infos = describe(registration.cls.Params)
            print(f"\n[{registration.stage}.{registration.name}]")
            if not infos:
                print("  (no parameters)")
            for info in infos:
                print(f"  {info.name} = {info.default!r}  ({info.type_name}) {info.doc}")
    return 0


# --- symfuse config --------------------------------------------------------------------


def _cmd_config(args: argparse.Namespace) -> int:
    _, config = _load(args)
    print(config.to_toml(), end="")
    return 0


# --- symfuse fuse ----------------------------------------------------------------------


def _parse_plane(text: str):
    from .types import SymmetryPlane

    try:
        nx, ny, d = (float(v) for v in text.split(","))
        return SymmetryPlane.from_normal(np.array([nx, ny]), d)
    except ValueError as exc:
        raise ConfigError(f"--plane '{text}': expected NX,NY,D with a non-zero normal") from exc


#: Columns of the self-diagnosis in the stage tables.
CONSISTENCY_HEADER = ["taxel rms mm", "NIS / bound", "free space / limit", "consistent"]


def consistency_cells(stage) -> list[str]:
    """A stage's self-diagnosis as table cells ('-' where a check did not run)."""
    c = stage.consistency
    if c is None:
        return ["-"] * len(CONSISTENCY_HEADER)
    free = (
        "-"
        if c.free_space_violations is None
        else f"{c.free_space_violations} / {c.free_space_limit}"
    )
    rms = "-" if not np.isfinite(c.taxel_rms_m) else f"{c.taxel_rms_m * 1e3:.1f}"
    nis = "-" if not np.isfinite(c.nis) else f"{c.nis:.2f} / {c.nis_threshold:.2f}"
    return [rms, nis, free, "yes" if c.consistent else "NO"]


def selection_line(result) -> str:
    """Which stage the estimator stands behind, and why."""
    return f"selected: Stage {result.selected.stage} ({result.selection_reason})"


def stage_summary(result) -> str:
    """A small table of Stage 0/1/2: status, plane, bias, iterations, time, self-diagnosis."""
    rows = []
    for stage in result.stages:
        rows.append(
            [
                stage.stage,
                stage.status,
                f"{np.degrees(stage.plane.theta_rad):.2f}",
                f"{stage.plane.offset_m * 1e3:.1f}",
                f"{np.degrees(stage.bias.yaw_rad):.2f}",
                " ".join(f"{v * 1e3:.1f}" for v in stage.bias.translation_m),
                stage.iterations,
                f"{stage.seconds * 1e3:.0f}",
                *consistency_cells(stage),
            ]
        )
    header = ["stage", "status", "plane θ°", "offset mm", "yaw°", "bias t (mm)", "iter", "ms"]
    return format_table(header + CONSISTENCY_HEADER, rows)


FAILED_STATUSES = ("no_correspondence", "diverged", "inconsistent")


def _cmd_fuse(args: argparse.Namespace) -> int:
    from .formats import (
        bias_to_json,
        estimate_to_json,
        plane_to_json,
        read_cloud,
        read_contacts,
        selection_to_json,
        write_completed_clouds,
        write_json,
    )
    from .runner import fuse

    overrides = [f"initialiser.use={args.init}"] if args.init else []
    registry, config = _load(args, overrides)
    cloud = read_cloud(args.cloud)
    recorded = read_contacts(args.contacts)
    plane = _parse_plane(args.plane) if args.plane else None
    started = time.perf_counter()
    run = fuse(config, registry, cloud, recorded.contacts, recorded.plans, plane)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_completed_clouds(out, run.result)
    config.write(out / "config.toml")
    final_status = run.result.final.status
    write_json(
        out / "result.json",
        {
            "symfuse": __version__,
            "command": "fuse",
            "inputs": {"cloud": str(args.cloud), "contacts": str(args.contacts)},
            "points": len(cloud),
            "grasps": [len(c) for c in recorded.contacts],
            "init": {
                "source": "--plane" if plane is not None else config.choices["initialiser"],
                "plane": plane_to_json(run.init.plane),
                "bias": bias_to_json(run.init.bias),
            },
            "stages": estimate_to_json(run.result),
            **selection_to_json(run.result),
            "status": final_status,
            "seconds": time.perf_counter() - started,
            "config": config.to_dict(),
        },
    )
    print(stage_summary(run.result))
    print(selection_line(run.result))
    print(f"wrote {out}/result.json, config.toml, completed_stage{{0,1,2}}.ply")
    if final_status in FAILED_STATUSES:
        print(f"symfuse: error: estimate {final_status} (see {out}/result.json)", file=sys.stderr)
        return EXIT_ESTIMATE_FAILED
    return 0


# --- symfuse trial ---------------------------------------------------------------------

#: The planner ``--gripper`` selects along with the hand.
PLANNER_FOR_GRIPPER = {"pg70": "top-parallel", "sdh": "top-three-finger"}


def trial_overrides(args: argparse.Namespace) -> list[str]:
    """The ``--set`` overrides the trial's shortcut options stand for."""
    overrides = []
    if args.object or args.mesh:
        overrides.append(f"trial.object={json.dumps(str(args.object or args.mesh))}")
    if args.gripper:
        overrides += [
            f"trial.gripper={args.gripper}",
            f"planner.use={PLANNER_FOR_GRIPPER[args.gripper]}",
        ]
    if args.init:
        overrides.append(f"initialiser.use={args.init}")
    if args.seed is not None:
        overrides.append(f"trial.seed={args.seed}")
    if args.yaw is not None:
        overrides.append(f"trial.yaw_deg={args.yaw}")
    return overrides


def trial_summary(record) -> str:
    """Stage 0/1/2 table with the trial's evaluation next to the estimate."""
    rows = []
    for stage, metrics in zip(record.result.stages, record.metrics, strict=True):
        measure = next(
            (
                f"{metrics[f'{name}_mm']:.1f} ({metrics[f'{name}_error_pct']:.1f} %)"
                for name in ("thickness", "diameter")
                if f"{name}_mm" in metrics
            ),
            "-",
        )
        angle = metrics.get("plane_angle_error_deg")
        rows.append(
            [
                stage.stage,
                stage.status,
                stage.iterations,
                f"{metrics['deviation_m']['median'] * 1e3:.1f}",
                f"{metrics['deviation_m']['mean'] * 1e3:.1f}",
                measure,
                "-" if angle is None else f"{angle:.1f}",
                f"{metrics['plane_offset_error_mm']:.1f}",
                *consistency_cells(stage),
            ]
        )
    header = [
        "stage",
        "status",
        "iter",
        "dev median mm",
        "dev mean mm",
        "measure mm",
        "plane err °",
        "offset err mm",
    ]
    return format_table(header + CONSISTENCY_HEADER, rows)


def _cmd_trial(args: argparse.Namespace) -> int:
    from .trial import run_trial

    registry, config = _load(args, trial_overrides(args))
    settings = config.trial
    out = args.out or Path("runs") / f"trial-{Path(settings.object).stem}-seed{settings.seed}"
    started = time.perf_counter()
    record = run_trial(config, registry, out, report=lambda m: print(f"... {m}", flush=True))
    print(trial_summary(record))
    print(selection_line(record.result))
    timings = ", ".join(f"{k} {v:.2f}" for k, v in record.timings.items())
    print(f"phases (s): {timings}; total {time.perf_counter() - started:.2f} s")
    print(f"wrote {out}/ (result.json, clouds, contacts.json, pictures)")
    if record.result.final.status in FAILED_STATUSES:
        print(f"symfuse: error: estimate {record.result.final.status}", file=sys.stderr)
        return EXIT_ESTIMATE_FAILED
    return 0


# --- symfuse sweep ---------------------------------------------------------------------


def _cmd_sweep(args: argparse.Namespace) -> int:
    import importlib

    from .experiments import EXPERIMENTS, ExperimentOptions
    from .sweep import run_sweep

    _, config = _load(args, [f"estimator.use={args.estimator}"] if args.estimator else [])
    experiment = importlib.import_module(EXPERIMENTS[args.experiment])
    estimator = config.choices["estimator"]
    out = args.out or Path("runs") / f"sweep-{args.experiment}-{estimator}"
    out.mkdir(parents=True, exist_ok=True)
    options = ExperimentOptions(
        estimator=estimator,
        estimator_params=config.to_dict()["estimator"][estimator],
        quick=args.quick,
        seed=args.seed,
        repeats=args.repeats,
        out_dir=out.resolve(),
    )
    tasks = experiment.tasks(options)
    config.write(out / "config.toml")
    try:
        rows = run_sweep(
            tasks,
            experiment.run_one,
            out / "results.jsonl",
            workers=args.workers,
            executor=args.executor,
            scheduler=args.scheduler,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc
    written = experiment.report(rows, out)
    for path in written:
        print(f"wrote {path}")
    failed = [row for row in rows if "error" in row]
    if failed:
        print(
            f"symfuse: error: {len(failed)} of {len(rows)} trials raised; first: "
            f"{failed[0]['key']}: {failed[0]['error']} (rows in {out}/results.jsonl)",
            file=sys.stderr,
        )
        return EXIT_ESTIMATE_FAILED
    return 0


def _add_sweep_parser(verbs) -> None:
    from .experiments import EXPERIMENTS, experiment_descriptions

    sweep = verbs.add_parser(
        "sweep",
        help="run one of the paper's experiments as a resumable sweep",
        describe=lambda: (
            "Run an experiment's trials in parallel (or on Dask), appending each "
            "finished trial to OUT/results.jsonl at once; a re-run skips finished trials. "
            "Then write the CSV, figures and report.md. Experiments: "
            + "; ".join(f"{name}: {text}" for name, text in experiment_descriptions().items())
        ),
    )
    sweep.add_argument(
        "experiment",
        choices=sorted(EXPERIMENTS),
        metavar="EXPERIMENT",
        help=", ".join(sorted(EXPERIMENTS)),
    )
    sweep.add_argument("--estimator", metavar="NAME", help="estimator to run (default: config)")
    sweep.add_argument("--quick", action="store_true", help="a reduced grid (smoke test)")
    sweep.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    sweep.add_argument("--repeats", type=int, help="trials per grid point (default: paper's)")
    sweep.add_argument("--workers", type=int, help="local processes (default: all cores)")
    sweep.add_argument("--executor", choices=["local", "dask"], default="local")
    sweep.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler (tcp://...)")
    _add_config_options(sweep)
    sweep.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="output folder (default runs/sweep-EXPERIMENT-ESTIMATOR)",
    )
    sweep.set_defaults(run=_cmd_sweep)


# --- the parser ------------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose description can be computed only when help is shown
    (``describe=``), so building the CLI never imports what only the help text needs."""

    def __init__(self, *args, describe: Callable[[], str] | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._describe = describe

    def format_help(self) -> str:
        if self._describe is not None:
            self.description = self._describe()
        return super().format_help()


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="symfuse",
        description="Visuo-tactile reconstruction of symmetric objects: mirror-complete a "
        "single depth view, grasp, and fuse taxel contacts with the cloud (IEKF).",
    )
    parser.add_argument("--version", action="version", version=f"symfuse {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)

    plugins = verbs.add_parser(
        "plugins",
        help="list the installed stage implementations",
        description="List every stage with its installed implementations: name, "
        "distribution, version and description.",
    )
    plugins.add_argument("--params", action="store_true", help="also list every parameter")
    plugins.set_defaults(run=_cmd_plugins)

    config = verbs.add_parser(
        "config",
        help="print the resolved configuration",
        description="Print the configuration that a run with these options would use, "
        "every parameter included, as TOML.",
    )
    _add_config_options(config)
    config.set_defaults(run=_cmd_config)

    fuse = verbs.add_parser(
        "fuse",
        help="run the estimator on a recorded cloud and contacts",
        description="Fuse a recorded object cloud (robot frame, metres) with recorded taxel "
        "contacts; writes result.json, config.toml and completed_stage{0,1,2}.ply to --out.",
    )
    fuse.add_argument("--cloud", type=Path, required=True, help="PLY, PCD or NPY (N x 3)")
    fuse.add_argument("--contacts", type=Path, required=True, help="contacts JSON (README)")
    start = fuse.add_mutually_exclusive_group()
    start.add_argument(
        "--plane",
        metavar="NX,NY,D",
        help="initial symmetry plane {p : NX x + NY y = D}; write --plane=-1,0,0.2 when NX < 0",
    )
    start.add_argument("--init", metavar="NAME", help="initialiser to guess the plane with")
    _add_config_options(fuse)
    fuse.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    fuse.set_defaults(run=_cmd_fuse)

    trial = verbs.add_parser(
        "trial",
        help="run one full simulated grasp trial (the default: CD drive, PG-70)",
        description="Simulate one trial in PyBullet: depth image, segmentation, symmetry "
        "initialisation, top grasp with taxel pads, fusion, and evaluation against the true "
        "object. With no options: the built-in CD drive grasped by the PG-70.",
    )
    what = trial.add_mutually_exclusive_group()
    what.add_argument("--object", metavar="NAME", help="catalogue object (symfuse objects)")
    what.add_argument(
        "--mesh", type=Path, metavar="PATH", help="OBJ/STL/PLY mesh or URDF, in metres"
    )
    trial.add_argument(
        "--gripper",
        choices=sorted(PLANNER_FOR_GRIPPER),
        help="hand; also selects its planner (pg70: top-parallel, sdh: top-three-finger)",
    )
    trial.add_argument("--init", metavar="NAME", help="symmetry initialiser (ps, vc, pca, ...)")
    trial.add_argument("--seed", type=int, help="random seed of the trial")
    trial.add_argument("--yaw", type=float, metavar="DEG", help="object yaw on the table")
    _add_config_options(trial)
    trial.add_argument(
        "--out", type=Path, metavar="DIR", help="output folder (default runs/trial-OBJECT-seedN)"
    )
    trial.set_defaults(run=_cmd_trial)

    _add_sweep_parser(verbs)

    from . import cli_objects

    cli_objects.add_parser(verbs).set_defaults(run=cli_objects.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except SymfuseError as exc:
        if args.debug:
            raise
        print(f"symfuse: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("symfuse: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
