"""``symfuse objects``: the catalogue table and the mesh export."""

from __future__ import annotations

import argparse

import pytest
import trimesh

from pipeline.catalogue.objects import list_objects
from pipeline.cli import objects as cli_objects


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="symfuse")
    cli_objects.add_parser(parser.add_subparsers(dest="verb"))
    return parser.parse_args(argv)


def test_the_table_has_one_line_per_object_with_its_size_and_symmetry(capsys):
    assert cli_objects.run(parse(["objects"])) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:2] == ["name", "kind"]
    by_name = {line.split()[0]: line for line in lines[2:]}  # after the header and its rule
    assert set(by_name) == {info.name for info in list_objects()}
    assert by_name["cd_drive"].split()[1:8] == ["box", "42", "x", "170", "x", "146", "planar"]
    assert "53 x 53 x 130" in by_name["salt_cylinder"]
    assert all(line.split()[8] == "yes" for line in by_name.values())


def test_export_writes_meshes_that_reload_as_the_same_solids(tmp_path, capsys):
    out = tmp_path / "meshes"
    assert cli_objects.run(parse(["objects", "--export", str(out)])) == 0
    written = capsys.readouterr().out.split()
    assert len(written) == 2 * len(list_objects())
    cup = trimesh.load(out / "cup.obj", force="mesh")
    assert cup.is_watertight
    assert cup.extents * 1000 == pytest.approx([112.0, 82.0, 95.0], abs=1e-6)
    drive = trimesh.load(out / "cd_drive.stl", force="mesh")
    assert drive.volume == pytest.approx(0.042 * 0.170 * 0.146, rel=1e-5)


def test_export_of_one_format_only(tmp_path):
    cli_objects.run(parse(["objects", "--export", str(tmp_path), "--format", "stl"]))
    assert {path.suffix for path in tmp_path.iterdir()} == {".stl"}


def test_overwrite_replaces_an_export_and_nothing_else(tmp_path):
    from pipeline.errors import ConfigError

    out = tmp_path / "meshes"
    export = ["objects", "--export", str(out), "--format"]
    assert cli_objects.run(parse([*export, "stl"])) == 0
    assert cli_objects.run(parse([*export, "obj", "--overwrite"])) == 0
    assert {path.suffix for path in out.iterdir()} == {".obj"}
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match=r"--export .*holds no earlier symfuse run"):
        cli_objects.run(parse([*export, "obj", "--overwrite"]))
    assert (out / "notes.txt").read_text() == "mine"
