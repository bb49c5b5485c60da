"""``symfuse symmetry``: the mirror planes and rotation axes of an object, found by search."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TextIO

from pipeline.errors import InputError


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``symmetry`` verb to the CLI's subparsers and return its parser."""
    from pipeline.cli import _add_units_option

    parser = subparsers.add_parser(
        "symmetry",
        help="find an object's mirror planes and rotation axes",
        description=(
            "Search a catalogue object or a mesh file for its mirror planes (any orientation) "
            "and rotation axes, in the mesh file's own frame, and print them; --out writes "
            "them as a symmetry.json (docs/symmetry.md), which a trial of the mesh reads "
            "when it lies beside it."
        ),
    )
    parser.add_argument("object", metavar="OBJECT", help="catalogue name or mesh file")
    parser.add_argument(
        "--out", metavar="FILE", type=Path, help="write the symmetries to FILE (a new file)"
    )
    _add_units_option(parser, "the mesh file")
    return parser


def run(args: argparse.Namespace) -> int:
    """Print the symmetries found, and write them with ``--out``."""
    from pipeline.catalogue.objects import load_object
    from pipeline.reports.tables import format_table
    from pipeline.symmetry.search import SearchSettings, mesh_symmetries
    from pipeline.symmetry.truth_file import symmetries_to_json

    if args.out is not None and args.out.exists():
        raise InputError(f"{args.out}: already exists; --out writes a new file")
    obj = load_object(args.object, recentre=False, units=args.units or "m")
    # The file is created before the search, which takes a while, so a place it cannot be
    # written is refused before anything runs; it is removed again if the search fails.
    handle = _create(args.out) if args.out is not None else None
    try:
        found = mesh_symmetries(obj.mesh.vertices, obj.mesh.faces)
    except BaseException:
        if handle is not None:
            handle.close()
            args.out.unlink()
        raise
    rows = [
        [
            symmetry.kind,
            " ".join(f"{v:+.3f}" for v in symmetry.direction),
            " ".join(f"{v * 1e3:.1f}" for v in symmetry.point_m),
            f"{symmetry.residual_m * 1e3:.2f}",
        ]
        for symmetry in found.symmetries
    ]
    print(
        format_table(["kind", "normal or direction", "point (mm)", "residual (mm)"], rows)
        if rows
        else f"{obj.name}: no mirror plane or rotation axis"
    )
    print(
        f"kept: the symmetries moving at most {SearchSettings().outlier_share:.0%} of the "
        f"surface farther than {found.tolerance_m * 1e3:.2f} mm from it (sampling floor "
        f"{found.floor_m * 1e3:.2f} mm)"
    )
    if handle is not None:
        name = Path(obj.source).name if obj.source != "catalogue" else obj.name
        search = {"floor": found.floor_m, "tolerance": found.tolerance_m}
        with handle:
            json.dump(symmetries_to_json(found.symmetries, name, search), handle, indent=2)
        print(args.out)
    return 0


def _create(path: Path) -> TextIO:
    """``path`` opened as a new file for writing.

    Raises:
        InputError: it exists, or its folder cannot be written.
    """
    try:
        return path.open("x")
    except FileExistsError:
        raise InputError(f"{path}: already exists; --out writes a new file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None
