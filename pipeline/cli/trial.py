"""``symfuse trial``: one full simulated grasp trial, from the camera to the evaluation."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from pipeline.cli import (
    _add_config_options,
    _add_output_options,
    _add_units_option,
    _load,
    add_wide_option,
    counting_number,
)
from pipeline.cli.summary import CONSISTENCY_HEADER, consistency_cells, selection_line
from pipeline.cli.view import add_rerun_option, check_rerun, record_if_asked
from pipeline.entry import stop_if_interrupted
from pipeline.errors import EXIT_ESTIMATE_FAILED, EXIT_OK, estimate_failed
from pipeline.io.outdir import fresh_folder, staged_output
from pipeline.reports.tables import format_table, wrapped


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """The ``trial`` verb's options."""
    from pipeline.config import NEXT_GRASP_STRATEGIES

    parser = subparsers.add_parser(
        "trial",
        help="run one full simulated grasp trial (the default: CD drive, PG-70)",
        description="Simulate one trial in PyBullet: depth image, segmentation, symmetry "
        "initialisation, top grasp with taxel pads, fusion, and evaluation against the true "
        "object. With no options: the built-in CD drive grasped by the PG-70.",
    )
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--object", metavar="NAME", help="catalogue object (symfuse objects)")
    what.add_argument(
        "--mesh", type=Path, metavar="PATH", help="OBJ/STL/PLY mesh or URDF, in metres"
    )
    parser.add_argument(
        "--gripper",
        metavar="NAME",
        help="hand, one the world offers (pybullet, mujoco: pg70, sdh, and those of a world "
        "plugin: symfuse plugins lists the worlds), planned by planner.use "
        "when it plans for that hand, else by the best-scored installed planner that does; auto "
        "(the default): the hand with the best feasible grasp of any installed planner",
    )
    parser.add_argument("--init", metavar="NAME", help="symmetry initialiser (ps, vc, pca, ...)")
    parser.add_argument("--seed", type=counting_number(0), help="random seed of the trial")
    parser.add_argument("--yaw", type=float, metavar="DEG", help="object yaw on the table")
    parser.add_argument("--rest", metavar="K|random", help=REST_HELP)
    parser.add_argument(
        "--grasps",
        type=counting_number(1),
        metavar="N",
        help="grasp, release and grasp again N times, fusing after each (default 1)",
    )
    parser.add_argument(
        "--next-grasp",
        choices=NEXT_GRASP_STRATEGIES,
        help="how grasps after the first are chosen (default information)",
    )
    parser.add_argument(
        "--until-std",
        type=positive_mm,
        metavar="MM",
        help="stop once the plane offset and hidden side posterior stds are <= MM (> 0)",
    )
    parser.add_argument(
        "--symmetry",
        type=three_numbers,
        metavar="NX,NY,D",
        help="the --mesh file's true mirror plane, NX x + NY y = D in the file's frame and "
        "units, so the plane errors are scored",
    )
    _add_units_option(parser, "the --mesh file")
    _add_config_options(parser)
    _add_output_options(parser, default="runs/trial-OBJECT-seedN[-K]")
    add_rerun_option(parser)
    add_wide_option(parser)
    return parser


REST_HELP = (
    "place the object in its K-th most likely stable pose (0: the most likely), or one drawn "
    "with the seed (random); default: upright, as the mesh stands"
)


def three_numbers(text: str) -> tuple[float, float, float]:
    """An argparse ``type``: ``NX,NY,D``, three finite numbers."""
    try:
        values = tuple(float(field) for field in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected three numbers NX,NY,D, got '{text}'")
    return values


def run_name(obj: str) -> str:
    """The object's part of a trial's default folder name: a catalogue name as it is, a
    mesh or URDF file by its folder and its name (``003_cracker_box-textured``), since
    scans come as one folder per object of files named alike."""
    path = Path(obj)
    if not path.suffix:
        return obj
    folder = path.resolve().parent.name
    return f"{folder}-{path.stem}" if folder else path.stem


#: The columns of the stage table only ``--wide`` shows (all are in ``result.json``).
WIDE_STAGE_COLUMNS = ("dev mean mm", "chamfer mm", "F@5mm", "IoU", *CONSISTENCY_HEADER[:-1])


def trial_summary(record, wide: bool = False) -> str:
    """Stage 0/1/2 table with the trial's evaluation next to the estimate; without
    ``wide`` less :data:`WIDE_STAGE_COLUMNS`, to fit a terminal."""
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
    return format_table(header + CONSISTENCY_HEADER, rows, () if wide else WIDE_STAGE_COLUMNS)


#: The columns of the grasp table only ``--wide`` shows; without it the two stds share one.
WIDE_GRASP_COLUMNS = ("pads", "consistent", "offset std mm", "hidden std mm", "shape std mm")


def grasps_summary(document: dict, wide: bool = False) -> str:
    """One row per grasp of a multi-grasp trial: how it was chosen, where it touched, the
    selected stage after fusing it with its deviation and consistency, and the two
    uncertainties of the stop rule (``stds mm``: the plane offset's, then the hidden
    shape's; ``--wide`` adds the hidden side's with the object's place); each later grasp
    released unfused in its place; then why the trial stopped. ``dev mm`` is the median
    deviation, ``plane °`` and ``offset err`` (mm) the plane's errors. Without ``wide``
    less :data:`WIDE_GRASP_COLUMNS`."""
    rows = []
    for entry in document["grasps"]:
        stage = entry["stages"][entry["selected_stage"]]
        metrics, consistency = stage["metrics"], stage.get("consistency") or {}
        angle = metrics.get("plane_angle_error_deg")
        known = entry["uncertainty"]
        rows.append(
            [
                entry["grasp"],
                entry["chosen_by"]["strategy"],
                entry["gripper"],
                " ".join(entry["pads_in_contact"]),
                entry["taxels_in_contact"],
                entry["selected_stage"],
                stage["status"],
                f"{metrics['deviation_m']['median'] * 1e3:.1f}",
                "-" if angle is None else f"{angle:.1f}",
                f"{metrics['plane_offset_error_mm']:.1f}",
                "yes" if consistency.get("consistent") else "NO",
                f"{known['plane_offset_std_mm']:.2f}",
                f"{known['hidden_side_std_mm']:.2f}",
                f"{known['hidden_shape_std_mm']:.2f}",
                f"{known['plane_offset_std_mm']:.1f} / {known['hidden_shape_std_mm']:.1f}",
            ]
        )
    for unfused in document.get("unfused_grasps", []):
        rows.append(
            [
                unfused["grasp"],
                unfused["chosen_by"]["strategy"],
                unfused["gripper"],
                " ".join(unfused.get("pads_in_contact", [])) or "-",
                unfused.get("taxels_in_contact", 0),
                "-",
                "not fused",
                *["-"] * 8,
            ]
        )
    rows.sort(key=lambda row: row[0])
    header = [
        "grasp",
        "chosen by",
        "hand",
        "pads",
        "taxels",
        "stage",
        "status",
        "dev mm",
        "plane °",
        "offset err",
        "consistent",
        "offset std mm",
        "hidden std mm",
        "shape std mm",
        "stds mm",
    ]
    table = format_table(header, rows, ("stds mm",) if wide else WIDE_GRASP_COLUMNS)
    return table + "\n" + wrapped(f"stopped: {document['stop_reason']}")


def grasp_line(document: dict) -> str:
    """The first grasp in one line (before wrapping): why its hand was chosen, how the
    descent went, what the pads touched and how the object moved (``result.json``'s
    ``hand``, ``grasp`` and first fused ``grasps`` entry)."""
    grasp = document["grasp"]
    moved_aside = (
        f"; the descent met the object and moved aside {grasp['reapproaches']} time(s)"
        if grasp["reapproaches"]
        else ""
    )
    fused = document.get("grasps") or [{}]
    taxels = fused[0].get("taxels_in_contact")
    touched = (
        f"; {taxels} taxels in contact ({', '.join(fused[0]['pads_in_contact'])})"
        if taxels is not None
        else ""
    )
    return (
        f"grasp: {document['hand']['reason']}{moved_aside}{touched}; the object moved "
        f"{grasp['object_shift_mm']:.1f} mm, turned {grasp['object_turn_deg']:.1f} deg "
        f"and tilted {grasp['object_tilt_deg']:.1f} deg"
    )


def _progress(message: str) -> None:
    stop_if_interrupted()
    print(wrapped(f"... {message}"), flush=True)


def run(args: argparse.Namespace) -> int:
    from pipeline.planning.hand_choice import next_try
    from pipeline.run.trial import run_trial

    check_rerun(args)
    registry, config = _load(args)
    config.check_trial(registry)
    settings = config.trial
    out = args.out or fresh_folder(
        Path("runs") / f"trial-{run_name(settings.object)}-seed{settings.seed}"
    )
    started = time.perf_counter()
    inputs = [*args.config, *([args.mesh] if args.mesh else [])]
    with staged_output(out, overwrite=args.overwrite, inputs=inputs) as staging:
        record = run_trial(config, registry, staging, report=_progress)
    print(trial_summary(record, args.wide))
    print(wrapped(selection_line(record.result)))
    if "completion" in record.document.get("init", {}):
        print(wrapped(f"init: {record.document['init']['completion']}"))
    print(wrapped(grasp_line(record.document)))
    if settings.grasps > 1 or settings.until_std_mm > 0:
        print(grasps_summary(record.document, args.wide))
    timings = ", ".join(f"{k} {v:.2f}" for k, v in record.timings.items())
    print(wrapped(f"phases (s): {timings}; total {time.perf_counter() - started:.2f} s"))
    pictures = ", pictures" if settings.pictures else ""
    print(f"wrote {out}/ (result.json, clouds, contacts.json{pictures})")
    record_if_asked(args, out)
    if estimate_failed(record.result.final.status):
        hands = registry.get("world", config.choices["world"]).cls.hands
        print(
            f"symfuse: error: estimate {record.result.final.status} (see {out}/result.json)"
            f"{next_try(hands, record.document['gripper'])}",
            file=sys.stderr,
        )
        return EXIT_ESTIMATE_FAILED
    return EXIT_OK


def positive_mm(text: str) -> float:
    """An argparse ``type`` for ``--until-std``: a finite number above 0 (mm). A threshold
    of 0 is never reached, so the option would stop nothing (the config's 0 means off)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of mm, got '{text}'") from None
    if not (math.isfinite(value) and value > 0.0):
        never = " (0 would never stop the trial)" if value == 0.0 else ""
        raise argparse.ArgumentTypeError(f"expected a number of mm above 0, got {text}{never}")
    return value
