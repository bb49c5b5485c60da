"""``symfuse complete``: segment, initialise and complete every object of a recorded view
(and fuse one with contacts)."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline import __version__
from pipeline.cli.view import add_rerun_option, check_rerun, record_if_asked
from pipeline.run.completion import (
    OBJECT_CHOICES,
    SET_ASIDE_REASON,
    SceneCompletion,
    failed,
    object_summary,
    pixel_box,
)

if TYPE_CHECKING:
    from pipeline.types import Contacts


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``complete`` verb to the CLI's subparsers and return its parser."""
    from pipeline.cli import _add_config_options, _add_output_options

    parser = subparsers.add_parser(
        "complete",
        help="complete every object of a recorded depth view (PCD, depth image, ROS bag)",
        description=(
            "Read a recorded depth view (a PCD in the camera frame, a depth PNG "
            "in mm or NPY in m with camera.json, or a ROS 1/2 bag), find the support plane "
            "and every object standing on it, initialise each one's symmetry plane and "
            "complete it; with --contacts, fuse them with one object. Writes objects.json, "
            "object_K/ (cloud.ply, completed_stage*.ply, model.*, result.json) and scene.png."
        ),
    )
    parser.add_argument("scan", type=Path, metavar="SCAN", help="the capture file or bag")
    parser.add_argument(
        "--camera",
        type=Path,
        metavar="FILE",
        help="camera.json of a depth image (default: beside it)",
    )
    parser.add_argument("--topic", metavar="NAME", help="bag topic (default: the first that fits)")
    parser.add_argument(
        "--contacts",
        type=Path,
        metavar="FILE",
        help="contacts JSON in the capture's robot frame (docs/formats.md): fuse them with one "
        "object",
    )
    parser.add_argument(
        "--object",
        metavar="WHICH",
        help=f"{'|'.join(OBJECT_CHOICES)}|K: objects to complete (default: all, or largest "
        "with --contacts); K numbers objects largest first from 0",
    )
    parser.add_argument(
        "--init", metavar="NAME", help="symmetry initialiser (default: the config's, vc)"
    )
    _add_config_options(parser)
    _add_output_options(parser, default=None)
    add_rerun_option(parser)
    return parser


#: The config sections ``complete`` reads.
READS = ("world", "sensor", "segmenter", "initialiser", "estimator", "model")
#: ``complete``'s own defaults, under ``--config`` and ``--set``: VC chooses between a
#: vertical plane and a vertical axis by the view's evidence (a mug seen from the side gets
#: its handle in the plane, docs/symmetry.md), where a trial keeps the paper's plane.
DEFAULTS = {"initialiser": {"vc": {"kind": "evidence"}}}


def after_view_reader(config, registry, recorded):
    """The grasps' after-views the contacts file names (``"after_depth"``), read for an
    object's cloud, the hand drawn by the configured world; None without any."""
    from functools import partial

    from pipeline.io.after_view_files import read_after_views

    if recorded is None or not any(path is not None for path in recorded.after_depth):
        return None
    world = registry.get("world", config.choices["world"]).cls
    return partial(read_after_views, recorded, world=world)


def run(args: argparse.Namespace) -> int:
    """Complete the capture's objects, write the results, print a table."""
    from pipeline.cli import _load
    from pipeline.cli.summary import one_sided_line
    from pipeline.errors import EXIT_ESTIMATE_FAILED, EXIT_OK, FAILED_STATUSES
    from pipeline.io.formats import read_contacts
    from pipeline.io.outdir import staged_output
    from pipeline.metrics.evaluation import one_sided_grasps
    from pipeline.run.completion import complete_scene

    check_rerun(args)
    registry, config = _load(args, reads=READS, defaults=DEFAULTS)
    inputs = [p for p in (args.scan, args.camera, args.contacts, *args.config) if p is not None]
    with staged_output(args.out, overwrite=args.overwrite, inputs=inputs) as staging:
        recorded = read_contacts(args.contacts) if args.contacts else None
        which = args.object or ("largest" if recorded else "all")
        started = time.perf_counter()
        scene = complete_scene(
            config,
            registry,
            which,
            recorded.contacts if recorded else (),
            recorded.plans if recorded else (),
            after_view_reader(config, registry, recorded),
        )
        sources = {
            "scan": str(args.scan),
            "contacts": str(args.contacts) if args.contacts else None,
        }
        write_outputs(
            staging,
            scene,
            config,
            sources,
            time.perf_counter() - started,
            recorded.contacts if recorded else (),
        )
    print(scene_table(scene))
    for completion in scene.objects:
        for flag in completion.flags:
            print(f"object {completion.index}: {flag}")
    if recorded and (note := one_sided_line(one_sided_grasps(recorded.contacts))):
        print(note)
    print(f"wrote {args.out}/ (objects.json, object_K/, scene.png, config.toml)")
    record_if_asked(args, args.out)
    problems = failed(scene.objects, FAILED_STATUSES)
    if problems:
        print(f"symfuse: error: {'; '.join(problems)} (see {args.out}/)", file=sys.stderr)
        return EXIT_ESTIMATE_FAILED
    return EXIT_OK


def scene_table(scene: SceneCompletion) -> str:
    """One row per object: number, points, footprint, plane, status; then one per cluster
    set aside at the edge of the view."""
    import numpy as np

    from pipeline.reports.tables import format_table

    rows = []
    for completion in scene.objects:
        entry = object_summary(completion)
        plane = completion.result.final.plane if completion.result else None
        rows.append(
            [
                completion.index,
                len(completion.cloud),
                " x ".join(f"{v * 1e3:.0f}" for v in entry["footprint_extents_m"]),
                f"{entry['height_m'] * 1e3:.0f}",
                "-" if plane is None else f"{np.degrees(plane.theta_rad):.1f}",
                "-" if plane is None else f"{plane.offset_m * 1e3:.1f}",
                shown_status(completion),
            ]
        )
    rows += [
        ["-", len(cloud), "-", "-", "-", "-", f"set aside: {SET_ASIDE_REASON}"]
        for cloud in scene.set_aside
    ]
    header = ["object", "points", "footprint mm", "height mm", "plane θ°", "offset mm", "status"]
    return format_table(header, rows)


def shown_status(completion) -> str:
    """The status as the table and scene.png show it: ``flagged`` after it when the
    capture says something against the completion (objects.json says what)."""
    return f"{completion.status}, flagged" if completion.flags else completion.status


def write_outputs(
    out: Path,
    scene: SceneCompletion,
    config,
    inputs: dict[str, Any],
    seconds: float,
    grasps: Sequence[Contacts] = (),
) -> None:
    """Every file ``complete`` writes, into ``out`` (created if needed); ``grasps``: the
    contacts given, fused with the selected object."""
    import numpy as np

    from pipeline.io.formats import write_cloud, write_json
    from pipeline.reports.figures import SceneObjectView, plot_scene
    from pipeline.run.result_document import (
        estimate_entries,
        init_to_json,
        start_document,
        write_document,
        write_estimate_files,
    )

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    config.write(out / "config.toml")
    observation = scene.observation
    views = []
    for completion in scene.objects:
        folder = out / f"object_{completion.index}"
        folder.mkdir(exist_ok=True)
        write_cloud(folder / "cloud.ply", completion.cloud.points)
        document = start_document("complete", inputs=inputs, **object_summary(completion))
        if completion.init is not None:
            source = config.choices["initialiser"]
            document["init"] = init_to_json(completion.init, source, status=True)
        if completion.result is not None:
            # As `fuse` writes it: the contacts fused (taxels per grasp), the stage the
            # evidence supports best and why, and the estimator's time (s).
            fused = len(completion.result.stages) > 1
            document.update(
                grasps=[len(c) for c in grasps] if fused else [],
                **estimate_entries(completion.result),
                seconds=sum(stage.seconds for stage in completion.result.stages),
            )
            _, document["model"] = write_estimate_files(
                folder,
                completion.result,
                config.model,
                observation.table_height_m,
                completion.cloud.viewpoint_m,
            )
        write_document(folder, {**document, "config": config.to_dict()})
        final = completion.result.final if completion.result else None
        views.append(
            SceneObjectView(
                completion.index,
                completion.cloud.pixels,
                completion.cloud.points,
                None if final is None else final.completed,
                None if final is None else final.plane,
                shown_status(completion),
            )
        )
    write_json(
        out / "objects.json",
        {
            "symfuse": __version__,
            "inputs": inputs,
            "frame": "support plane" if observation.frame_from_support else "recorded",
            "T_robot_camera": np.asarray(observation.T_robot_camera).tolist(),
            "intrinsics": vars(observation.intrinsics),
            "objects": [object_summary(c) for c in scene.objects],
            "set_aside_at_view_edge": [
                {"points": len(cloud), "pixels": pixel_box(cloud.pixels)}
                for cloud in scene.set_aside
            ],
            "seconds": seconds,
        },
    )
    plot_scene(
        observation.rgb,
        views,
        out / "scene.png",
        title=str(inputs["scan"]),
        set_aside=[(cloud.pixels, SET_ASIDE_REASON) for cloud in scene.set_aside],
    )
