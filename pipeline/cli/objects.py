"""``symfuse objects``: list the object catalogue, or export its meshes for other tools."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import ConfigError, InputError
from pipeline.reports.tables import format_table

EXPORT_FORMATS = ("obj", "stl")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``objects`` verb to the CLI's subparsers and return its parser."""
    parser = subparsers.add_parser(
        "objects",
        help="list the object catalogue or export its meshes",
        description=(
            "List the paper's objects that symfuse models (name, generator kind, bounding box "
            "in mm, symmetry, watertightness, description), or write their meshes (metres, "
            "base on z = 0) with --export. Any OBJ/STL/PLY file can be used wherever an "
            "object name is expected."
        ),
    )
    parser.add_argument(
        "--export",
        metavar="DIR",
        type=Path,
        help="write every catalogue mesh to DIR as <name>.obj and <name>.stl",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing, non-empty --export folder",
    )
    parser.add_argument(
        "--format",
        choices=EXPORT_FORMATS,
        action="append",
        help="export only this format (repeatable; default: obj and stl)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    """Print the catalogue table, or export the meshes when ``--export`` is given."""
    if args.export is not None:
        from pipeline.io.outdir import staged_output

        with staged_output(
            args.export, overwrite=args.overwrite, replaceable=holds_export, option="--export"
        ) as staging:
            written = export_meshes(staging, tuple(args.format or EXPORT_FORMATS))
        for path in written:
            print(args.export / path.name)
        return 0
    for option, given in (("--overwrite", args.overwrite), ("--format", args.format)):
        if given:
            raise ConfigError(f"{option} applies to --export DIR")
    print(catalogue_table())
    return 0


def catalogue_table() -> str:
    """The catalogue as a plain-text table, one object per line."""
    header = ("name", "kind", "x, y, z (mm)", "symmetry", "watertight", "description")
    rows = []
    from pipeline.catalogue.objects import list_objects, load_object  # trimesh: only when used

    for info in list_objects():
        mesh = load_object(info.name).mesh
        size_mm = " x ".join(f"{extent * 1000.0:.0f}" for extent in mesh.extents)
        watertight = "yes" if mesh.is_watertight else "no"
        rows.append((info.name, info.kind, size_mm, info.symmetry, watertight, info.description))
    return format_table(header, rows)


def holds_export(folder: Path) -> bool:
    """Whether ``folder`` holds only meshes an export writes (``<catalogue name>.<format>``),
    the only folder ``--overwrite`` may replace."""
    from pipeline.catalogue.objects import list_objects

    names = {f"{info.name}.{suffix}" for info in list_objects() for suffix in EXPORT_FORMATS}
    return all(path.is_file() and path.name in names for path in Path(folder).iterdir())


def export_meshes(directory: Path, formats: tuple[str, ...] = EXPORT_FORMATS) -> list[Path]:
    """Write every catalogue mesh to ``directory`` (created if missing) in ``formats``;
    returns the files written."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{directory}: cannot create export folder ({exc.strerror})") from exc
    written = []
    from pipeline.catalogue.objects import list_objects, load_object  # trimesh: only when used

    for info in list_objects():
        mesh = load_object(info.name).mesh
        for suffix in formats:
            path = directory / f"{info.name}.{suffix}"
            mesh.export(path)
            written.append(path)
    return written
