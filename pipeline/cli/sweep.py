"""``symfuse sweep``: one of the paper's experiments as a resumable sweep of trials."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pipeline.cli import _add_config_options, _load, counting_number
from pipeline.errors import EXIT_ESTIMATE_FAILED, EXIT_OK, ConfigError


def _scans_folder(args: argparse.Namespace, experiment) -> Path | None:
    """``--scans DIR`` for an experiment that reads scans, each scan read once here: a bad
    one stops the sweep before its first trial rather than failing in each of its own.

    Raises:
        ConfigError: the experiment reads none, DIR is no folder or holds no
            ``*/textured.obj``.
        InputError: a scan cannot be read as an object (named).
    """
    from pipeline.catalogue.objects import load_object

    if args.scans is None:
        return None
    if not experiment.reads_scans:
        raise ConfigError(
            f"--scans: experiment '{args.experiment}' grasps no scans (objects and explore do)"
        )
    if not Path(args.scans).is_dir():
        raise ConfigError(f"--scans {args.scans}: no such folder")
    scans = sorted(Path(args.scans).glob("*/textured.obj"))
    if not scans:
        raise ConfigError(f"--scans {args.scans}: no */textured.obj in that folder")
    for scan in scans:
        load_object(scan)
    return Path(args.scans).resolve()


def _captures_folder(args: argparse.Namespace, experiment) -> Path | None:
    """``--captures DIR``, for an experiment that reads recorded captures.

    Raises:
        ConfigError: the experiment reads none.
    """
    if args.captures is None:
        return None
    if not experiment.reads_captures:
        raise ConfigError(
            f"--captures: experiment '{args.experiment}' reads no captures (scenes does)"
        )
    return Path(args.captures).resolve()


#: The trial keys a sweep's trials set themselves unless the user names them, even at the
#: default's own value: the paper's reproductions keep their single view
#: (docs/after-view.md), and a sweep's trials draw no pictures.
NAMED_TRIAL_KEYS = ("after_view", "pictures")


def user_settings(config) -> dict:
    """What the sweep's trials take from the user: the values that differ from the
    defaults, and each of :data:`NAMED_TRIAL_KEYS` whenever the user named it, so the
    choice travels with the config."""
    user = config.differing()
    for key in NAMED_TRIAL_KEYS:
        if f"trial.{key}" in config.changed:
            user.setdefault("trial", {})[key] = getattr(config.trial, key)
    return user


def _planned_tasks(args: argparse.Namespace, registry, config, experiment):
    """The sweep's output folder, its trials and the config sections they read, once the
    config is checked for them.

    Raises:
        ConfigError: the user set a section the trials do not read, a stage's parameters
            do not go together, or a chosen ``planner.use`` would not plan.
    """
    from pipeline.config import leaf_keys
    from pipeline.experiments import ExperimentOptions
    from pipeline.stages import STAGES

    estimator = config.choices["estimator"]
    resolved = config.to_dict()
    user = user_settings(config)
    sections = experiment.config_sections or tuple(resolved)
    # A --set counts even where it repeats the default: it would be ignored all the same.
    typed = {key.split(".")[0] for key, source in config.changed.items() if source == "--set"}
    unread = sorted((set(user) | typed) - set(sections))
    if unread:
        raise ConfigError(
            f"sweep {args.experiment}: its trials read only [{'], ['.join(sections)}] of the "
            f"config, not [{'], ['.join(unread)}]; remove those from --config/--set"
        )
    # A bad pair of a stage's parameters fails here, once, rather than in every trial.
    config.check_stages(registry, [stage for stage in STAGES if stage in sections])
    # The default folder is fixed, not fresh: typing the command again resumes the sweep.
    out = args.out or Path("runs") / f"sweep-{args.experiment}-{estimator}"
    options = ExperimentOptions(
        estimator=estimator,
        estimator_params=resolved["estimator"][estimator],
        config=user,
        quick=args.quick,
        grid=args.grid,
        seed=args.seed,
        repeats=args.repeats,
        out_dir=out.resolve(),
        scans=_scans_folder(args, experiment),
        captures=_captures_folder(args, experiment),
    )
    tasks = experiment.tasks(options)
    if "use" in user.get("planner", {}):
        from pipeline.experiments.paper_tasks import trial_config
        from pipeline.planning.hand_choice import check_planner_is_read

        # The trials of one hand read planner.use alike: the first of each stands for all.
        by_hand = {task.params["gripper"]: task for task in tasks if "gripper" in task.params}
        for task in by_hand.values():
            check_planner_is_read(trial_config(task.params), registry, leaf_keys(user))
    return out, tasks, sections


def run(args: argparse.Namespace) -> int:
    from pipeline.experiments import EXPERIMENTS
    from pipeline.experiments.sweep import prepare_sweep_folder, run_sweep, settings_section
    from pipeline.io.outdir import SWEEP_ROWS_FILE

    if args.scheduler and args.executor != "dask":
        raise ConfigError("--scheduler applies to --executor dask")
    registry, config = _load(args)
    experiment = EXPERIMENTS[args.experiment]
    if args.grid and not experiment.randomised:
        randomised = ", ".join(name for name, row in sorted(EXPERIMENTS.items()) if row.randomised)
        raise ConfigError(f"sweep {args.experiment}: --grid applies to {randomised} only")
    out, tasks, sections = _planned_tasks(args, registry, config, experiment)
    resolved, user = config.to_dict(), user_settings(config)
    read = {section: resolved[section] for section in sections}
    fingerprint = json.dumps(read, sort_keys=True)
    keys = [task.key for task in tasks]
    with prepare_sweep_folder(out, keys, overwrite=args.overwrite, inputs=args.config):
        config.write(out / "config.toml")
        try:
            rows = run_sweep(
                tasks,
                experiment.run_one,
                out / SWEEP_ROWS_FILE,
                workers=args.workers,
                executor=args.executor,
                scheduler=args.scheduler,
                fingerprint=fingerprint,
                rerun_stale=args.overwrite,
                preload=experiment.worker_imports,
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


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """The ``sweep`` verb's options."""
    from pipeline.experiments import EXPERIMENTS, experiment_descriptions

    parser = subparsers.add_parser(
        "sweep",
        help="run one of the paper's experiments as a resumable sweep",
        describe=lambda: (
            "Run an experiment's trials in parallel (or on Dask), appending each "
            "finished trial to OUT/results.jsonl at once; a re-run skips finished trials. "
            "Then write the CSV, figures and report.md. Experiments: "
            + "; ".join(f"{name}: {text}" for name, text in experiment_descriptions().items())
        ),
    )
    parser.add_argument(
        "experiment",
        choices=sorted(EXPERIMENTS),
        metavar="EXPERIMENT",
        help=", ".join(sorted(EXPERIMENTS)),
    )
    parser.add_argument("--estimator", metavar="NAME", help="estimator to run (default: config)")
    parser.add_argument("--quick", action="store_true", help="a reduced grid (smoke test)")
    parser.add_argument(
        "--grid",
        action="store_true",
        help="fig8, fig9, fig10: the paper's grid instead of randomly drawn cases",
    )
    parser.add_argument(
        "--scans",
        type=Path,
        metavar="DIR",
        help="objects, explore: also grasp every scanned mesh DIR/*/textured.obj (e.g. YCB scans)",
    )
    parser.add_argument(
        "--captures",
        type=Path,
        metavar="DIR",
        help="scenes: the labelled captures DIR/**/*.pcd (a 'label' field, OSD convention)",
    )
    parser.add_argument(
        "--rest",
        metavar="K|random",
        help="every trial's object in its K-th stable pose, or one drawn with the trial's "
        "seed (random); default: upright",
    )
    parser.add_argument("--seed", type=counting_number(0), default=0, help="base seed (default 0)")
    parser.add_argument(
        "--repeats", type=counting_number(1), help="trials per grid point (default: paper's)"
    )
    parser.add_argument(
        "--workers", type=counting_number(1), help="local processes (default: all cores)"
    )
    parser.add_argument(
        "--executor",
        choices=["local", "dask"],
        default="local",
        help="where the trials run: local processes, or a Dask cluster at --scheduler",
    )
    parser.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler (tcp://...)")
    _add_config_options(parser)
    parser.add_argument("--out", type=Path, metavar="DIR", help=SWEEP_OUT_HELP)
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="re-run rows made with another config; replace a folder that is not this sweep's",
    )
    return parser


SWEEP_OUT_HELP = (
    "output folder (default runs/sweep-EXPERIMENT-ESTIMATOR); an existing folder of the same "
    "sweep is resumed"
)
