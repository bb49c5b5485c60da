"""``symfuse fuse``: the estimator on a recorded cloud and recorded contacts."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.cli import (
    _add_config_options,
    _add_output_options,
    _add_units_option,
    _load,
    add_wide_option,
)
from pipeline.cli.summary import one_sided_line, selection_line, stage_summary
from pipeline.cli.view import add_rerun_option, check_rerun, record_if_asked
from pipeline.errors import (
    EXIT_ESTIMATE_FAILED,
    EXIT_OK,
    ConfigError,
    InputError,
    StageFailure,
    estimate_failed,
)
from pipeline.io.outdir import staged_output
from pipeline.reports.tables import wrapped

if TYPE_CHECKING:
    from pipeline.config import Config
    from pipeline.io.formats import RecordedGrasps
    from pipeline.registry import StageRegistry
    from pipeline.types import DepthObservation, PointCloud, SymmetryPlane


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """The ``fuse`` verb's options."""
    parser = subparsers.add_parser(
        "fuse",
        help="run the estimator on a recorded cloud and contacts",
        description="Fuse a recorded object cloud (robot frame, metres) with recorded taxel "
        "contacts, and the depth image the cloud came from when given; writes result.json, "
        "config.toml, completed_stage{0,1,2}.ply and the model's mesh and URDF to --out.",
    )
    parser.add_argument("--cloud", type=Path, required=True, help="PLY, PCD or NPY (N x 3)")
    parser.add_argument(
        "--contacts", type=Path, required=True, help="contacts JSON (docs/formats.md)"
    )
    start = parser.add_mutually_exclusive_group()
    start.add_argument(
        "--plane",
        metavar="NX,NY,D",
        help="initial symmetry plane {p : NX x + NY y = D}",
    )
    start.add_argument(
        "--init",
        metavar="NAME",
        help="initialiser to guess the plane with (the default, vc, needs --depth; without "
        "it use ps or pca)",
    )
    parser.add_argument(
        "--depth",
        type=Path,
        metavar="FILE",
        help="the depth image the cloud came from (16-bit PNG in mm or NPY in m) with a "
        "camera.json that gives T_robot_camera: the estimator then checks its model against "
        "the space the camera saw empty, as a trial does",
    )
    parser.add_argument(
        "--camera",
        type=Path,
        metavar="FILE",
        help="camera.json of --depth (default: beside it)",
    )
    parser.add_argument(
        "--after-depth",
        type=Path,
        metavar="FILE",
        help="the after-view of grasp 1: a depth image (16-bit PNG in mm or NPY in m) the "
        "camera took while the hand held the object, fused as a measurement of how the grasp "
        "moved it (docs/after-view.md; later grasps: 'after_depth' in the contacts file). "
        "The contacts file must give the grasp's plan and hand pose",
    )
    parser.add_argument(
        "--after-camera",
        type=Path,
        metavar="FILE",
        help="camera.json of --after-depth (default: beside it)",
    )
    _add_units_option(parser, "the cloud (the contacts file states its own, which must agree)")
    _add_config_options(parser)
    _add_output_options(parser, default=None)
    add_rerun_option(parser)
    add_wide_option(parser)
    return parser


def parse_plane(text: str):
    """``NX,NY,D`` as a :class:`~pipeline.types.SymmetryPlane` (``NX x + NY y = D``)."""
    from pipeline.io.units import FARTHEST_M
    from pipeline.types import SymmetryPlane

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
    plane = SymmetryPlane.from_normal(np.array([nx, ny]), d)
    if abs(plane.offset_m) > FARTHEST_M:
        raise ConfigError(
            f"--plane '{text}': the plane passes {abs(plane.offset_m):.3g} m from the robot "
            f"base, beyond any tabletop object (D is in metres, over the normal's length)"
        )
    return plane


#: The config sections ``fuse`` reads.
FUSE_READS = ("world", "initialiser", "estimator", "model")


def run(args: argparse.Namespace) -> int:
    from pipeline.io.formats import read_cloud, read_contacts

    check_rerun(args)
    registry, config = _load(args, reads=FUSE_READS)
    plane = parse_plane(args.plane) if args.plane else None
    if args.camera and not args.depth:
        raise ConfigError("--camera describes the camera of --depth, which is not given")
    if args.after_camera and not args.after_depth:
        raise ConfigError(
            "--after-camera describes the camera of --after-depth, which is not given"
        )
    given = (args.depth, args.camera, args.after_depth, args.after_camera)
    inputs = [args.cloud, args.contacts, *filter(None, given), *args.config]
    with staged_output(args.out, overwrite=args.overwrite, inputs=inputs) as staging:
        cloud = read_cloud(args.cloud, units=args.units or "m")
        recorded = read_contacts(args.contacts, units=args.units)
        view = read_view(args.depth, args.camera) if args.depth else None
        views = recorded_after_views(config, registry, recorded, cloud, args)
        status = _fuse_into(staging, args, config, registry, cloud, recorded, plane, (view, views))
    print(f"wrote {args.out}/ (result.json, config.toml, completed_stage{{0,1,2}}.ply, model.*)")
    record_if_asked(args, args.out)
    if estimate_failed(status):
        print(f"symfuse: error: estimate {status} (see {args.out}/result.json)", file=sys.stderr)
        return EXIT_ESTIMATE_FAILED
    return EXIT_OK


def read_view(depth: Path, camera: Path | None) -> DepthObservation:
    """``--depth`` (with ``--camera``) as the estimator's view of the scene.

    Raises:
        InputError: unreadable, or its camera has no pose in the robot frame (the cloud and
            the contacts are in that frame).
    """
    from pipeline.io.captures import depth_camera_path, read_depth_image

    capture = read_depth_image(depth, camera, None)
    if capture.T_robot_camera is None:
        raise InputError(
            f"{depth_camera_path(depth, camera)}: no T_robot_camera: the cloud and the "
            "contacts are in the robot frame, so the depth image's camera must be placed in it"
        )
    return capture.view(capture.T_robot_camera, capture.table_height_m)


def recorded_after_views(
    config: Config,
    registry: StageRegistry,
    recorded: RecordedGrasps,
    cloud: PointCloud,
    args: argparse.Namespace,
) -> tuple:
    """The grasps' after-views (``--after-depth`` and the contacts file's), the hand drawn
    by the configured world (the estimator's ``after_view`` decides whether they count)."""
    from pipeline.io.after_view_files import read_after_views

    world = registry.get("world", config.choices["world"]).cls
    return read_after_views(recorded, cloud, world, (args.after_depth, args.after_camera))


def _fuse_into(
    out: Path,
    args: argparse.Namespace,
    config: Config,
    registry: StageRegistry,
    cloud: PointCloud,
    recorded: RecordedGrasps,
    plane: SymmetryPlane | None,
    views: tuple[DepthObservation | None, tuple],
) -> str:
    """Run the estimator and write its results into ``out``; return the final status.
    ``views``: the first view (``--depth``) and the grasps' after-views.

    A :class:`StageFailure` is recorded in ``result.json`` (status ``failed``) and re-raised.
    """
    from pipeline.metrics.evaluation import one_sided_grasps
    from pipeline.run.result_document import (
        estimate_entries,
        init_to_json,
        record_failure,
        start_document,
        write_document,
        write_estimate_files,
    )
    from pipeline.run.runner import fuse

    view, after_views = views
    config.write(out / "config.toml")
    started = time.perf_counter()
    document = start_document(
        "fuse",
        inputs={
            "cloud": str(args.cloud),
            "contacts": str(args.contacts),
            **({"depth": str(args.depth)} if view is not None else {}),
            **({"after_depth": str(args.after_depth)} if args.after_depth else {}),
        },
        after_views=[view is not None for view in after_views],
        points=len(cloud),
        grasps=[len(c) for c in recorded.contacts],
        one_sided_grasps=one_sided_grasps(recorded.contacts),
        config=config.to_dict(),
    )
    try:
        run = fuse(
            config, registry, cloud, recorded.contacts, recorded.plans, plane, view, after_views
        )
    except StageFailure as exc:
        record_failure(out, document, str(exc))
        raise
    table_z = view.table_height_m if view is not None else None
    _, document["model"] = write_estimate_files(
        out, run.result, config.model, table_z, cloud.viewpoint_m
    )
    source = "--plane" if plane is not None else config.choices["initialiser"]
    document.update(
        init=init_to_json(run.init, source),
        **estimate_entries(run.result),
        status=run.result.final.status,
        seconds=time.perf_counter() - started,
    )
    write_document(out, document)
    print(stage_summary(run.result, args.wide))
    print(wrapped(selection_line(run.result)))
    if note := one_sided_line(document["one_sided_grasps"]):
        print(wrapped(note))
    return run.result.final.status
