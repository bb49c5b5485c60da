"""The ``symfuse`` command line.

Every deliberate failure (:class:`~pipeline.errors.SymfuseError`) is printed as one line,
``symfuse: error: ...``, with its exit code (:mod:`pipeline.errors`: 2 bad input or config,
3 a failed estimate, 4 a plugin raised, 130 interrupted); ``--debug`` shows the traceback
instead. Every verb that writes follows the output-folder policy of :mod:`pipeline.outdir`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import numpy as np

from . import __version__
from .cli_view import add_rerun_option, check_rerun, record_if_asked
from .errors import (
    EXIT_BAD_INPUT,
    EXIT_ESTIMATE_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    ConfigError,
    StageFailure,
    SymfuseError,
    estimate_failed,
)
from .outdir import fresh_folder, staged_output
from .stages import STAGES
from .tables import format_table

if TYPE_CHECKING:  # the CLI imports heavy modules only in the verbs that need them
    from .config import Config
    from .formats import RecordedGrasps
    from .registry import StageRegistry
    from .types import PointCloud, SymmetryPlane


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


def _add_output_options(parser: argparse.ArgumentParser, default: str | None) -> None:
    """``--out`` (required when ``default`` is None) and ``--overwrite``."""
    parser.add_argument(
        "--out",
        type=Path,
        required=default is None,
        metavar="DIR",
        help="output folder" + (f" (default: a fresh {default})" if default else ""),
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing, non-empty --out folder (whole, when the run ends)",
    )


def _add_units_option(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument(
        "--units",
        choices=["m", "mm"],
        help=f"length unit of {what} (default: metres; data that looks like millimetres "
        "is refused)",
    )


def counting_number(least: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer of at least ``least`` (a seed >= 0, a count >= 1)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got '{text}'") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"expected an integer >= {least}, got {value}")
        return value

    return parse


def _load(
    args: argparse.Namespace,
    extra_overrides: Sequence[str] = (),
    reads: Sequence[str] | None = None,
    registry=None,
):
    """The registry and the config of ``--config``, ``--set`` and ``extra_overrides`` (what
    the verb's own options stand for, applied last).

    Args:
        reads: the config sections the verb reads (None: all); see :func:`check_overrides`.
        registry: the installed plugins, when the caller has loaded them already.
    """
    from .config import load_config
    from .registry import load_registry

    registry = registry or load_registry()
    config = load_config(registry, args.config, [*args.overrides, *extra_overrides])
    check_overrides(args.verb, args.overrides, extra_overrides, reads)
    return registry, config


def check_overrides(
    verb: str, overrides: Sequence[str], options: Sequence[str], reads: Sequence[str] | None
) -> None:
    """Refuse a ``--set`` that would be ignored without a word: one in a section ``verb``
    does not read, or one whose key the verb's own options also set (they win).

    Args:
        overrides: the user's ``--set`` texts (``section.key=value``), already valid.
        options: the overrides the verb's options stand for.
        reads: the sections ``verb`` reads (None: all).

    Raises:
        ConfigError: naming the ``--set`` and why it would be ignored.
    """
    taken = {text.partition("=")[0].strip() for text in options}
    for text in overrides:
        key = text.partition("=")[0].strip()
        section = key.split(".")[0]
        if reads is not None and section not in reads:
            raise ConfigError(
                f"--set {text}: symfuse {verb} does not read [{section}] (it reads "
                f"[{'], ['.join(reads)}])"
            )
        if key in taken:
            raise ConfigError(
                f"--set {text}: symfuse {verb} sets {key} from its arguments; drop this --set"
            )


# --- symfuse plugins -------------------------------------------------------------------


def _cmd_plugins(args: argparse.Namespace) -> int:
    from .config import load_config
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
        # The effective defaults: the shipped config's values where it sets any.
        shipped = load_config(registry).params
        for registration in registry.registrations():
            values = shipped[registration.stage].get(registration.name)
            infos = describe(registration.cls.Params, values)
            print(f"\n[{registration.stage}.{registration.name}]")
            if not infos:
                print("  (no parameters)")
            for info in infos:
                print(f"  {info.name} = {info.default!r}  ({info.type_name}) {info.doc}")
    return EXIT_OK


# --- symfuse config --------------------------------------------------------------------


def _cmd_config(args: argparse.Namespace) -> int:
    _, config = _load(args)
    print(config.to_toml(), end="")
    return 0


# --- symfuse fuse ----------------------------------------------------------------------


def parse_plane(text: str):
    """``NX,NY,D`` as a :class:`~pipeline.types.SymmetryPlane` (``NX x + NY y = D``)."""
    from .types import SymmetryPlane

    fields = [field.strip() for field in text.split(",")]
    if len(fields) != 3:
        raise ConfigError(f"--plane '{text}': expected three numbers NX,NY,D, got {len(fields)}")
    try:
        nx, ny, d = (float(field) for field in fields)
    except ValueError:
        raise ConfigError(f"--plane '{text}': expected three numbers NX,NY,D") from None
    if not np.isfinite([nx, ny, d]).all():
        raise ConfigError(f"--plane '{text}': NX, NY and D must be finite")
    if nx == 0.0 and ny == 0.0:
        raise ConfigError(f"--plane '{text}': the normal (NX, NY) must be non-zero")
    return SymmetryPlane.from_normal(np.array([nx, ny]), d)


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


#: The config sections ``fuse`` reads.
FUSE_READS = ("initialiser", "estimator")


def _cmd_fuse(args: argparse.Namespace) -> int:
    from .formats import read_cloud, read_contacts

    check_rerun(args)
    overrides = [f"initialiser.use={args.init}"] if args.init else []
    registry, config = _load(args, overrides, reads=FUSE_READS)
    plane = parse_plane(args.plane) if args.plane else None
    inputs = [args.cloud, args.contacts, *args.config]
    with staged_output(args.out, overwrite=args.overwrite, inputs=inputs) as staging:
        cloud = read_cloud(args.cloud, units=args.units or "m")
        recorded = read_contacts(args.contacts, units=args.units)
        status = _fuse_into(staging, args, config, registry, cloud, recorded, plane)
    print(f"wrote {args.out}/ (result.json, config.toml, completed_stage{{0,1,2}}.ply)")
    record_if_asked(args, args.out)
    if estimate_failed(status):
        print(f"symfuse: error: estimate {status} (see {args.out}/result.json)", file=sys.stderr)
        return EXIT_ESTIMATE_FAILED
    return EXIT_OK


def _fuse_into(
    out: Path,
    args: argparse.Namespace,
    config: Config,
    registry: StageRegistry,
    cloud: PointCloud,
    recorded: RecordedGrasps,
    plane: SymmetryPlane | None,
) -> str:
    """Run the estimator and write its results into ``out``; return the final status.

    A :class:`StageFailure` is recorded in ``result.json`` (status ``failed``) and re-raised.
    """
    from .formats import (
        bias_to_json,
        estimate_to_json,
        plane_to_json,
        selection_to_json,
        write_completed_clouds,
        write_json,
    )
    from .runner import fuse

    config.write(out / "config.toml")
    started = time.perf_counter()
    document = {
        "symfuse": __version__,
        "command": "fuse",
        "inputs": {"cloud": str(args.cloud), "contacts": str(args.contacts)},
        "points": len(cloud),
        "grasps": [len(c) for c in recorded.contacts],
        "config": config.to_dict(),
    }
    try:
        run = fuse(config, registry, cloud, recorded.contacts, recorded.plans, plane)
    except StageFailure as exc:
        document.update(status="failed", reason=str(exc))
        write_json(out / "result.json", document)
        raise
    write_completed_clouds(out, run.result)
    document.update(
        init={
            "source": "--plane" if plane is not None else config.choices["initialiser"],
            "plane": plane_to_json(run.init.plane),
            "bias": bias_to_json(run.init.bias),
        },
        stages=estimate_to_json(run.result),
        **selection_to_json(run.result),
        status=run.result.final.status,
        seconds=time.perf_counter() - started,
    )
    write_json(out / "result.json", document)
    print(stage_summary(run.result))
    print(selection_line(run.result))
    return run.result.final.status


# --- symfuse trial ---------------------------------------------------------------------


def trial_overrides(args: argparse.Namespace, registry) -> list[str]:
    """The ``--set`` overrides the trial's shortcut options stand for; a named
    ``--gripper`` also selects the first installed planner that plans for that hand
    (:attr:`pipeline.stages.GraspPlanner.grippers`)."""
    from .hand_choice import AUTO, planner_for

    overrides = []
    if args.object or args.mesh:
        overrides.append(f"trial.object={json.dumps(str(args.object or args.mesh))}")
    if args.gripper:
        overrides.append(f"trial.gripper={args.gripper}")
        planner = planner_for(registry, args.gripper) if args.gripper != AUTO else None
        if planner is not None:
            overrides.append(f"planner.use={planner}")
    if args.init:
        overrides.append(f"initialiser.use={args.init}")
    if args.seed is not None:
        overrides.append(f"trial.seed={args.seed}")
    if args.yaw is not None:
        overrides.append(f"trial.yaw_deg={args.yaw}")
    if args.grasps is not None:
        overrides.append(f"trial.grasps={args.grasps}")
    if args.next_grasp:
        overrides.append(f"trial.next_grasp={args.next_grasp}")
    if args.until_std is not None:
        overrides.append(f"trial.until_std_mm={args.until_std}")
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
                f"{metrics['chamfer_mm']:.1f}",
                f"{metrics['fscore_5mm']:.2f}",
                f"{metrics['iou']:.2f}",
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
        "chamfer mm",
        "F@5mm",
        "IoU",
    ]
    return format_table(header + CONSISTENCY_HEADER, rows)


def grasps_summary(document: dict) -> str:
    """One row per grasp of a multi-grasp trial: how it was chosen, where it touched, the
    selected stage after fusing it with its deviation and consistency, and the two
    uncertainties of the stop rule; then why the trial stopped."""
    rows = []
    for entry in document["grasps"]:
        stage = entry["stages"][entry["selected_stage"]]
        metrics, consistency = stage["metrics"], stage.get("consistency") or {}
        angle = metrics.get("plane_angle_error_deg")
        rows.append(
            [
                entry["grasp"],
                entry["chosen_by"]["strategy"],
                " ".join(entry["pads_in_contact"]),
                entry["taxels_in_contact"],
                entry["selected_stage"],
                stage["status"],
                f"{metrics['deviation_m']['median'] * 1e3:.1f}",
                "-" if angle is None else f"{angle:.1f}",
                f"{metrics['plane_offset_error_mm']:.1f}",
                "yes" if consistency.get("consistent") else "NO",
                f"{entry['uncertainty']['plane_offset_std_mm']:.2f}",
                f"{entry['uncertainty']['hidden_side_std_mm']:.2f}",
            ]
        )
    header = [
        "grasp",
        "chosen by",
        "pads",
        "taxels",
        "stage",
        "status",
        "dev median mm",
        "plane err °",
        "offset err mm",
        "consistent",
        "offset std mm",
        "hidden std mm",
    ]
    return format_table(header, rows) + f"\nstopped: {document['stop_reason']}"


def _progress(message: str) -> None:
    print(f"... {message}", flush=True)


def _cmd_trial(args: argparse.Namespace) -> int:
    from .registry import load_registry
    from .trial import run_trial

    check_rerun(args)
    registry = load_registry()
    overrides = trial_overrides(args, registry)
    if args.units:
        overrides.append(f"trial.units={args.units}")
    registry, config = _load(args, overrides, registry=registry)
    settings = config.trial
    out = args.out or fresh_folder(
        Path("runs") / f"trial-{Path(settings.object).stem}-seed{settings.seed}"
    )
    started = time.perf_counter()
    inputs = [*args.config, *([args.mesh] if args.mesh else [])]
    with staged_output(out, overwrite=args.overwrite, inputs=inputs) as staging:
        record = run_trial(
            config, registry, staging, report=lambda m: print(f"... {m}", flush=True)
        )
    print(trial_summary(record))
    print(selection_line(record.result))
    grasp = record.document["grasp"]
    print(
        f"grasp: {record.document['hand']['reason']}; the object moved "
        f"{grasp['object_shift_mm']:.1f} mm and tilted {grasp['object_tilt_deg']:.1f} deg"
    )
    if len(record.document["grasps"]) > 1 or settings.until_std_mm > 0:
        print(grasps_summary(record.document))
    timings = ", ".join(f"{k} {v:.2f}" for k, v in record.timings.items())
    print(f"phases (s): {timings}; total {time.perf_counter() - started:.2f} s")
    print(f"wrote {out}/ (result.json, clouds, contacts.json, pictures)")
    record_if_asked(args, out)
    if estimate_failed(record.result.final.status):
        print(
            f"symfuse: error: estimate {record.result.final.status} (see {out}/result.json)",
            file=sys.stderr,
        )
        return EXIT_ESTIMATE_FAILED
    return EXIT_OK


# --- symfuse sweep ---------------------------------------------------------------------


def _scans_folder(args: argparse.Namespace, experiment) -> Path | None:
    """``--scans DIR`` for an experiment that reads scans.

    Raises:
        ConfigError: the experiment reads none, or DIR holds no ``*/textured.obj``.
    """
    if args.scans is None:
        return None
    if not getattr(experiment, "READS_SCANS", False):
        raise ConfigError(f"--scans: experiment '{args.experiment}' grasps no scans (explore does)")
    if not any(Path(args.scans).glob("*/textured.obj")):
        raise ConfigError(f"--scans {args.scans}: no */textured.obj in that folder")
    return Path(args.scans).resolve()


def _cmd_sweep(args: argparse.Namespace) -> int:
    import importlib

    from .config import changed_settings, load_config
    from .experiments import EXPERIMENTS, ExperimentOptions
    from .sweep import prepare_sweep_folder, run_sweep, settings_section

    if args.scheduler and args.executor != "dask":
        raise ConfigError("--scheduler applies to --executor dask")
    registry, config = _load(args, [f"estimator.use={args.estimator}"] if args.estimator else [])
    experiment = importlib.import_module(EXPERIMENTS[args.experiment])
    estimator = config.choices["estimator"]
    resolved = config.to_dict()
    user = changed_settings(resolved, load_config(registry).to_dict())
    sections = getattr(experiment, "CONFIG_SECTIONS", tuple(resolved))
    unread = sorted(set(user) - set(sections))
    if unread:
        raise ConfigError(
            f"sweep {args.experiment}: its trials read only [{'], ['.join(sections)}] of the "
            f"config, not [{'], ['.join(unread)}]; remove those from --config/--set"
        )
    # The default folder is fixed, not fresh: typing the command again resumes the sweep.
    out = args.out or Path("runs") / f"sweep-{args.experiment}-{estimator}"
    options = ExperimentOptions(
        estimator=estimator,
        estimator_params=resolved["estimator"][estimator],
        config=user,
        quick=args.quick,
        seed=args.seed,
        repeats=args.repeats,
        out_dir=out.resolve(),
        scans=_scans_folder(args, experiment),
    )
    tasks = experiment.tasks(options)
    read = {section: resolved[section] for section in sections}
    fingerprint = json.dumps(read, sort_keys=True)
    keys = [task.key for task in tasks]
    with prepare_sweep_folder(out, keys, overwrite=args.overwrite, inputs=args.config):
        config.write(out / "config.toml")
        try:
            rows = run_sweep(
                tasks,
                experiment.run_one,
                out / "results.jsonl",
                workers=args.workers,
                executor=args.executor,
                scheduler=args.scheduler,
                fingerprint=fingerprint,
                rerun_stale=args.overwrite,
            )
        except ValueError as exc:
            raise ConfigError(str(exc)) from exc
        written = experiment.report(rows, out)
        with (out / "report.md").open("a", encoding="utf-8") as report:
            report.write("\n" + settings_section(tasks, resolved, user, sections))
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
    return EXIT_OK


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
    sweep.add_argument(
        "--scans",
        type=Path,
        metavar="DIR",
        help="explore: also grasp every scanned mesh DIR/*/textured.obj (e.g. YCB scans)",
    )
    sweep.add_argument("--seed", type=counting_number(0), default=0, help="base seed (default 0)")
    sweep.add_argument(
        "--repeats", type=counting_number(1), help="trials per grid point (default: paper's)"
    )
    sweep.add_argument(
        "--workers", type=counting_number(1), help="local processes (default: all cores)"
    )
    sweep.add_argument("--executor", choices=["local", "dask"], default="local")
    sweep.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler (tcp://...)")
    _add_config_options(sweep)
    sweep.add_argument("--out", type=Path, metavar="DIR", help=SWEEP_OUT_HELP)
    sweep.add_argument(
        "--overwrite",
        action="store_true",
        help="re-run rows made with another config; replace a folder that is not this sweep's",
    )
    sweep.set_defaults(run=_cmd_sweep)


SWEEP_OUT_HELP = (
    "output folder (default runs/sweep-EXPERIMENT-ESTIMATOR); an existing folder of the same "
    "sweep is resumed"
)


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

    def error(self, message: str) -> NoReturn:
        """A command-line mistake as every other error: one line, exit code 2 (argparse
        would print the usage first and prefix the verb's name differently)."""
        verb = self.prog.removeprefix("symfuse").strip()
        where = f"{verb}: " if verb else ""
        hint = f"symfuse {verb} --help" if verb else "symfuse --help"
        self.exit(EXIT_BAD_INPUT, f"symfuse: error: {where}{message} (see {hint})\n")


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
        help="initial symmetry plane {p : NX x + NY y = D}",
    )
    start.add_argument(
        "--init",
        metavar="NAME",
        help="initialiser to guess the plane with (the default, vc, needs a depth image that "
        "recorded data lacks: use ps or pca)",
    )
    _add_units_option(fuse, "the cloud and the contacts (overrides the contacts' own)")
    _add_config_options(fuse)
    _add_output_options(fuse, default=None)
    add_rerun_option(fuse)
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
        metavar="NAME",
        help="hand, one the world offers (pybullet: pg70, sdh), which also selects a planner "
        "for it (pg70: top-parallel, sdh: top-three-finger); auto (the default): the hand "
        "with the best feasible grasp",
    )
    trial.add_argument("--init", metavar="NAME", help="symmetry initialiser (ps, vc, pca, ...)")
    trial.add_argument("--seed", type=counting_number(0), help="random seed of the trial")
    trial.add_argument("--yaw", type=float, metavar="DEG", help="object yaw on the table")
    trial.add_argument(
        "--grasps",
        type=counting_number(1),
        metavar="N",
        help="grasp, release and grasp again N times, fusing after each (default 1)",
    )
    from .config import NEXT_GRASP_STRATEGIES

    trial.add_argument(
        "--next-grasp",
        choices=NEXT_GRASP_STRATEGIES,
        help="how grasps after the first are chosen (default information)",
    )
    trial.add_argument(
        "--until-std",
        type=float,
        metavar="MM",
        help="stop once the plane offset and hidden side posterior stds are <= MM",
    )
    _add_units_option(trial, "the --mesh file")
    _add_config_options(trial)
    _add_output_options(trial, default="runs/trial-OBJECT-seedN[-K]")
    add_rerun_option(trial)
    trial.set_defaults(run=_cmd_trial)

    _add_sweep_parser(verbs)

    from . import cli_complete, cli_objects, cli_view

    cli_complete.add_parser(verbs).set_defaults(run=cli_complete.run)
    cli_objects.add_parser(verbs).set_defaults(run=cli_objects.run)
    cli_view.add_parser(verbs).set_defaults(run=cli_view.run)
    return parser


#: Options whose value may start with a minus sign (``--plane -1,0,0.2``).
SIGNED_VALUE_OPTIONS = ("--plane",)


def _join_signed_values(argv: Sequence[str]) -> list[str]:
    """``--plane -1,0,0.2`` as ``--plane=-1,0,0.2``: argparse takes a value that starts with
    ``-`` and is not a plain number for an option and reports "expected one argument"."""
    joined: list[str] = []
    for argument in argv:
        if joined and joined[-1] in SIGNED_VALUE_OPTIONS and argument.startswith("-"):
            joined[-1] = f"{joined[-1]}={argument}"
        else:
            joined.append(argument)
    return joined


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_signed_values(sys.argv[1:] if argv is None else argv))
    try:
        return args.run(args)
    except SymfuseError as exc:
        if args.debug:
            raise
        print(f"symfuse: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("symfuse: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader of stdout left (`symfuse objects | head`): nothing more to say, and
        # Python must not fail again flushing stdout at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except Exception as exc:
        if not interrupted(exc):
            raise
        print("symfuse: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` was caused by Ctrl-C: a compiled extension interrupted while it
    initialises (open3d's pybind11 module) raises ImportError from the KeyboardInterrupt."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False


if __name__ == "__main__":
    sys.exit(main())
