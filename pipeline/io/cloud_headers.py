"""Structural checks of PLY and PCD point-cloud files, made before open3d reads them.

open3d's readers are lenient to the point of returning garbage: a truncated file, a header
declaring more points than the file holds, or a row with a word where a number belongs
gives a cloud of the declared size filled with whatever was in memory, and only a message
on the console. :func:`check_cloud_file` reads the header and checks that the body holds
every declared point (byte sizes for binary data, one row of numbers per point for ASCII),
so a malformed file is an :class:`~pipeline.errors.InputError` naming what is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import InputError

#: Bytes per value of every PLY scalar type.
PLY_SIZES = {
    "char": 1, "int8": 1, "uchar": 1, "uint8": 1,
    "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
    "int": 4, "int32": 4, "uint": 4, "uint32": 4,
    "float": 4, "float32": 4, "double": 8, "float64": 8,
}  # fmt: skip
PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
PCD_DATA = ("ascii", "binary", "binary_compressed")
#: Headers longer than this are not headers.
MAX_HEADER_BYTES = 1 << 16


@dataclass(frozen=True)
class _Element:
    name: str
    count: int
    properties: tuple[str, ...]
    row_bytes: int | None  # None: a list property makes rows variable


def check_cloud_file(path: Path) -> None:
    """Check the header and body size of a ``.ply`` or ``.pcd`` file (other suffixes pass).

    Raises:
        InputError: naming ``path`` and the problem.
    """
    suffix = path.suffix.lower()
    if suffix not in (".ply", ".pcd"):
        return
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror}") from None
    if suffix == ".ply":
        _check_ply(data, path)
    else:
        _check_pcd(data, path)


def _header(data: bytes, path: Path, end: bytes, first_line: bytes | None) -> tuple[list, int]:
    """The header's lines (split into words) up to the line starting with ``end``, and the
    byte offset where the body starts."""
    if first_line is not None and data.split(b"\n", 1)[0].rstrip(b"\r") != first_line:
        raise InputError(f"{path}: not a {path.suffix[1:].upper()} file (bad first line)")
    lines, position = [], 0
    while True:
        stop = data.find(b"\n", position)
        if stop < 0 or stop > MAX_HEADER_BYTES:
            raise InputError(f"{path}: no complete header (no '{end.decode()}' line)")
        raw = data[position:stop].rstrip(b"\r")
        position = stop + 1
        try:
            words = raw.decode("ascii").split()
        except UnicodeDecodeError:
            raise InputError(f"{path}: the header is not ASCII text") from None
        lines.append(words)
        if words and words[0].encode() == end:
            return lines, position


def _count(text: str, what: str, path: Path) -> int:
    if not text.isdigit():
        raise InputError(f"{path}: {what} must be a non-negative integer, got {text!r}")
    return int(text)


def _check_ply(data: bytes, path: Path) -> None:
    lines, body_start = _header(data, path, b"end_header", b"ply")
    fmt, elements = None, []
    for words in lines[1:-1]:
        if not words or words[0] in ("comment", "obj_info"):
            continue
        keyword = words[0]
        if keyword == "format" and len(words) == 3 and words[1] in PLY_FORMATS:
            fmt = words[1]
        elif keyword == "element" and len(words) == 3:
            elements.append(_Element(words[1], _count(words[2], "an element count", path), (), 0))
        elif keyword == "property" and elements and len(words) == 3 and words[1] in PLY_SIZES:
            last = elements[-1]
            size = None if last.row_bytes is None else last.row_bytes + PLY_SIZES[words[1]]
            elements[-1] = _Element(last.name, last.count, (*last.properties, words[2]), size)
        elif keyword == "property" and elements and len(words) == 5 and words[1] == "list":
            last = elements[-1]
            elements[-1] = _Element(last.name, last.count, (*last.properties, words[4]), None)
        else:
            raise InputError(f"{path}: bad PLY header line {' '.join(words)!r}")
    if fmt is None:
        raise InputError(f"{path}: the PLY header has no valid 'format' line")
    names = [element.name for element in elements]
    if "vertex" not in names:
        raise InputError(f"{path}: the PLY file has no 'vertex' element")
    before = elements[: names.index("vertex")]
    vertex = elements[names.index("vertex")]
    if not {"x", "y", "z"} <= set(vertex.properties):
        raise InputError(f"{path}: the PLY vertices lack an x, y or z property")
    if fmt == "ascii" and vertex.row_bytes is not None:
        rows = data[body_start:].splitlines()
        skip = sum(element.count for element in before)
        _check_ascii_rows(rows[skip : skip + vertex.count], vertex.count, len(vertex.properties),
                          path)  # fmt: skip
    elif vertex.row_bytes is not None and all(e.row_bytes is not None for e in before):
        needed = sum(e.count * e.row_bytes for e in before) + vertex.count * vertex.row_bytes
        _check_body_bytes(len(data) - body_start, needed, vertex.count, path)


def _check_pcd(data: bytes, path: Path) -> None:
    lines, body_start = _header(data, path, b"DATA", None)
    header = {words[0].upper(): words[1:] for words in lines if words and words[0] != "#"}
    fields = header.get("FIELDS", [])
    if not {"x", "y", "z"} <= set(fields):
        raise InputError(f"{path}: the PCD FIELDS lack x, y or z")
    sizes = [_count(v, "SIZE", path) for v in header.get("SIZE", [])]
    counts = [_count(v, "COUNT", path) for v in header.get("COUNT", ["1"] * len(fields))]
    if not (len(sizes) == len(counts) == len(header.get("TYPE", [])) == len(fields)):
        raise InputError(f"{path}: the PCD SIZE, TYPE and COUNT do not match FIELDS")
    width = _count((header.get("WIDTH") or ["?"])[0], "WIDTH", path)
    height = _count((header.get("HEIGHT") or ["1"])[0], "HEIGHT", path)
    points = _count((header.get("POINTS") or [str(width * height)])[0], "POINTS", path)
    if points != width * height:
        raise InputError(f"{path}: PCD POINTS {points} is not WIDTH x HEIGHT")
    kind = (header.get("DATA") or ["?"])[0]
    if kind not in PCD_DATA:
        raise InputError(f"{path}: PCD DATA must be one of {', '.join(PCD_DATA)}")
    row_bytes = sum(size * count for size, count in zip(sizes, counts, strict=True))
    body = len(data) - body_start
    if kind == "ascii":
        rows = data[body_start:].splitlines()
        _check_ascii_rows(rows[:points], points, sum(counts), path)
    elif kind == "binary":
        _check_body_bytes(body, points * row_bytes, points, path)
    else:
        compressed = int.from_bytes(data[body_start : body_start + 4], "little")
        expanded = int.from_bytes(data[body_start + 4 : body_start + 8], "little")
        if body < 8 + compressed or expanded != points * row_bytes:
            raise InputError(f"{path}: the compressed PCD body does not hold {points} points")


def _check_ascii_rows(rows: list[bytes], points: int, values: int, path: Path) -> None:
    if len(rows) < points:
        raise InputError(f"{path}: the header declares {points} points, the file holds {len(rows)}")
    for number, row in enumerate(rows):
        words = row.split()
        try:
            finite = len(words) == values and all(math.isfinite(float(word)) for word in words)
        except ValueError:
            finite = False
        if not finite:  # open3d reads "nan" or "inf" as whatever was in memory
            raise InputError(f"{path}: point {number} is not a row of {values} finite numbers")


def _check_body_bytes(body: int, needed: int, points: int, path: Path) -> None:
    if body < needed:
        raise InputError(
            f"{path}: the header declares {points} points ({needed} bytes), the file holds "
            f"{body} bytes (truncated?)"
        )
