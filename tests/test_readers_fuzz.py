"""Property-based fuzzing of every reader: clouds (PLY, PCD, NPY), contacts JSON, the TOML
config and meshes. Every malformed input must end in one ``symfuse: error:`` line and exit
code 2, never a traceback.

Each reader gets valid files broken in ways that make them certainly malformed (truncated,
a word where a number belongs, a declared size the body lacks, a wrong type for a key,
NaN, a scale in millimetres, random bytes). The runs are derandomised, so the suite is
repeatable; FUZZ_EXAMPLES bounds each test's examples (``SYMFUSE_FUZZ_EXAMPLES=2000`` and
``SYMFUSE_FUZZ_RANDOM=1`` for a deeper, randomised hunt).
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.catalogue.objects import load_object
from pipeline.cli import main
from pipeline.config import load_config
from pipeline.errors import EXIT_BAD_INPUT, InputError
from pipeline.io.formats import contacts_to_json, write_cloud
from pipeline.registry import load_registry
from pipeline.synthetic import make_case

FUZZ_EXAMPLES = int(os.environ.get("SYMFUSE_FUZZ_EXAMPLES", "50"))
FUZZ = settings(
    max_examples=FUZZ_EXAMPLES,
    deadline=None,
    derandomize=os.environ.get("SYMFUSE_FUZZ_RANDOM") != "1",
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

CASE = make_case(np.random.default_rng(5))
POINTS = CASE.cloud.points[:40]
GOOD_CONTACTS = contacts_to_json([CASE.contacts])
PLANE = "--plane=1,0,0.5"


def symfuse(*argv) -> tuple[int, str]:
    """Exit code and stderr of ``symfuse argv`` (stdout discarded)."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, err.getvalue()


def assert_one_line_exit_2(code: int, err: str) -> None:
    lines = err.strip().splitlines()
    assert code == EXIT_BAD_INPUT, err
    assert len(lines) == 1 and lines[0].startswith("symfuse: error: "), err


@contextlib.contextmanager
def folder():
    with tempfile.TemporaryDirectory(prefix="symfuse-fuzz-") as name:
        yield Path(name)


def fuse_on(cloud: Path, contacts: Path, out: Path) -> tuple[int, str]:
    return symfuse("fuse", "--cloud", cloud, "--contacts", contacts, PLANE, "--out", out)


# ------------------------------------------------------------------ text and bytes breakers

words = st.text("abcdefghijklmnopqrstuvwxyz_-#", min_size=1, max_size=8).filter(
    lambda w: _not_a_number(w)
)


def _not_a_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return True
    return False


def cut_before(data: bytes, keep_at_most: int):
    """``data`` cut to a prefix of at most ``keep_at_most`` bytes."""
    return st.integers(0, max(0, keep_at_most)).map(lambda n: data[:n])


def swap_token(text: str, value: str | None = None):
    """``text`` with one of its number tokens replaced by a word (or ``value``)."""
    tokens = text.split(" ")
    numeric = [i for i, token in enumerate(tokens) if not _not_a_number(token.strip())]

    def replace(index_and_word):
        index, word = index_and_word
        out = list(tokens)
        out[numeric[index % len(numeric)]] = value if value is not None else word
        return " ".join(out)

    return st.tuples(st.integers(0, 10**6), words).map(replace)


# ------------------------------------------------------------------ clouds


def ply_ascii(points: np.ndarray, declared: int | None = None, props: str = "xyz") -> str:
    header = [
        "ply",
        "format ascii 1.0",
        f"element vertex {len(points) if declared is None else declared}",
        *(f"property float {p}" for p in props),
        "end_header",
    ]
    return _with_rows(header, points)


def pcd_ascii(points: np.ndarray, declared: int | None = None, fields: str = "x y z") -> str:
    n = len(points) if declared is None else declared
    header = [
        "# .PCD v0.7",
        "VERSION 0.7",
        f"FIELDS {fields}",
        "SIZE 4 4 4",
        "TYPE F F F",
        "COUNT 1 1 1",
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA ascii",
    ]
    return _with_rows(header, points)


def _with_rows(header: list[str], points: np.ndarray) -> str:
    rows = [" ".join(f"{v:.6f}" for v in row) for row in points]
    return "\n".join(header + rows) + "\n"


def binary_file(suffix: str) -> bytes:
    with folder() as tmp:
        return write_cloud(tmp / f"c{suffix}", POINTS).read_bytes()


PLY_BINARY, PCD_BINARY = binary_file(".ply"), binary_file(".pcd")
PLY_TEXT, PCD_TEXT = ply_ascii(POINTS), pcd_ascii(POINTS)
BAD_VALUES = ("nan", "inf", "-inf", "1e6")  # non-finite, or 1000 m away: millimetres

malformed_ply = st.one_of(
    st.binary(max_size=400),
    st.binary(max_size=400).map(lambda b: b"ply\n" + b),
    cut_before(PLY_BINARY, len(PLY_BINARY) - 1),
    cut_before(PLY_TEXT.encode(), PLY_TEXT.rindex("\n", 0, len(PLY_TEXT) - 1)),
    swap_token(PLY_TEXT).map(str.encode),
    st.sampled_from(BAD_VALUES).flatmap(lambda v: swap_token(PLY_TEXT, v)).map(str.encode),
    st.integers(len(POINTS) + 1, 10**6).map(lambda n: ply_ascii(POINTS, n).encode()),
    st.sampled_from(["xy", "xz", "yz", "abc"]).map(
        lambda p: (
            ply_ascii(POINTS[:, :2], None, p).encode()
            if len(p) == 2
            else ply_ascii(POINTS, None, p).encode()
        )
    ),
    st.sampled_from(["-3", "x", "1.5", ""]).map(
        lambda n: PLY_TEXT.replace(f"element vertex {len(POINTS)}", f"element vertex {n}").encode()
    ),
    st.just(PLY_TEXT.replace("format ascii 1.0", "format ascii").encode()),
    st.just(ply_ascii(POINTS[:0]).encode()),
)

malformed_pcd = st.one_of(
    st.binary(max_size=400),
    cut_before(PCD_BINARY, len(PCD_BINARY) - 1),
    cut_before(PCD_TEXT.encode(), PCD_TEXT.rindex("\n", 0, len(PCD_TEXT) - 1)),
    swap_token(PCD_TEXT.split("DATA ascii\n")[1]).map(
        lambda body: (PCD_TEXT.split("DATA ascii\n")[0] + "DATA ascii\n" + body).encode()
    ),
    st.sampled_from(BAD_VALUES).map(
        lambda v: pcd_ascii(np.vstack([POINTS, [[float(v), 0.0, 0.0]]])).encode()
    ),
    st.integers(len(POINTS) + 1, 10**6).map(lambda n: pcd_ascii(POINTS, n).encode()),
    st.sampled_from(["x y", "x y w", "a b c"]).map(lambda f: pcd_ascii(POINTS, None, f).encode()),
    st.sampled_from(["DATA bogus", "POINTS -1", "WIDTH x", "SIZE 4 4"]).map(
        lambda line: PCD_TEXT.replace(line.split()[0] + " ", line + "\n#", 1).encode()
    ),
    st.just(pcd_ascii(POINTS[:0]).encode()),
)


def npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


NPY_GOOD = npy_bytes(POINTS)
malformed_npy = st.one_of(
    st.binary(max_size=300),
    cut_before(NPY_GOOD, len(NPY_GOOD) - 1),
    st.sampled_from([(0, 3), (5,), (5, 2), (5, 4), (5, 3, 1), (0,)]).map(
        lambda shape: npy_bytes(np.full(shape, 0.5))
    ),
    st.sampled_from(["U3", "c16", "?", "V8"]).map(
        lambda dtype: npy_bytes(np.zeros((4, 3), dtype=dtype))
    ),
    st.sampled_from([math.nan, math.inf, -math.inf, 500.0]).map(
        lambda v: npy_bytes(np.vstack([POINTS, [[v, 0.5, 0.1]]]))
    ),
)


@pytest.mark.parametrize(
    ("suffix", "strategy"),
    [(".ply", malformed_ply), (".pcd", malformed_pcd), (".npy", malformed_npy)],
)
def test_a_malformed_cloud_is_one_line_exit_2(suffix, strategy):
    @FUZZ
    @given(data=strategy)
    def check(data: bytes) -> None:
        with folder() as tmp:
            (tmp / f"cloud{suffix}").write_bytes(data)
            (tmp / "contacts.json").write_text(json.dumps(GOOD_CONTACTS))
            code, err = fuse_on(tmp / f"cloud{suffix}", tmp / "contacts.json", tmp / "out")
            assert_one_line_exit_2(code, err)
            assert not (tmp / "out").exists()

    check()


# ------------------------------------------------------------------ contacts


def _paths(value, prefix=()):
    """Every path into a JSON value (dict keys and list indices), the root included."""
    yield prefix
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from _paths(item, (*prefix, index))


def _set(document, path, value):
    document = copy.deepcopy(document)
    if not path:
        return value
    target = document
    for step in path[:-1]:
        target = target[step]
    target[path[-1]] = value
    return document


def _delete(document, path):
    document = copy.deepcopy(document)
    target = document
    for step in path[:-1]:
        target = target[step]
    del target[path[-1]]
    return document


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner, max_size=3)
    ),
    max_leaves=6,
)
#: Leaves of a contacts document a reader must check, and values each must refuse.
REQUIRED = {"units", "grasps", "taxels", "position", "normal", "pad"}


def _breaks(document, path, value) -> bool:
    """Whether writing ``value`` at ``path`` certainly makes the document invalid."""
    key = path[-1] if path else None
    old = _get(document, path)
    if key == "index":
        return not (isinstance(value, int) and not isinstance(value, bool) and value >= 0)
    if key in ("position", "normal"):
        ok = (
            isinstance(value, list)
            and len(value) == 3
            and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        )
        return not ok or (key == "normal" and not any(value))
    if key == "pad":
        return not (isinstance(value, str) and value)
    if key == "units":
        return value not in ("m", "mm")
    if key == "frame":
        return value != "robot"
    if isinstance(key, int) and len(path) >= 2 and path[-2] in ("position", "normal"):
        return not (
            isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
        )
    return type(value) is not type(old)  # a list, object, plan or document of another kind


def _get(document, path):
    for step in path:
        document = document[step]
    return document


CONTACT_PATHS = [p for p in _paths(GOOD_CONTACTS) if "plan" not in p]


GOOD_TEXT = json.dumps(GOOD_CONTACTS)
malformed_contacts = st.one_of(
    st.tuples(st.sampled_from(CONTACT_PATHS), json_values)
    .filter(lambda pv: _breaks(GOOD_CONTACTS, *pv))
    .map(lambda pv: json.dumps(_set(GOOD_CONTACTS, *pv)).encode()),
    st.sampled_from([p for p in CONTACT_PATHS if p and p[-1] in REQUIRED]).map(
        lambda path: json.dumps(_delete(GOOD_CONTACTS, path)).encode()
    ),
    cut_before(GOOD_TEXT.encode(), len(GOOD_TEXT) - 1),
    st.sampled_from(["NaN", "Infinity", "1e400", "1" + "0" * 400]).map(
        lambda v: GOOD_TEXT.replace(
            json.dumps(GOOD_CONTACTS["grasps"][0]["taxels"][0]["position"][0]), v, 1
        ).encode()
    ),
    st.sampled_from([1000.0, -2000.0]).map(
        lambda v: json.dumps(
            _set(GOOD_CONTACTS, ("grasps", 0, "taxels", 0, "position", 0), v)
        ).encode()
    ),
    st.integers(1, 3000).map(lambda depth: ("[" * depth + "]" * depth).encode()),
    st.binary(max_size=200),
)


@FUZZ
@given(data=malformed_contacts)
def test_malformed_contacts_are_one_line_exit_2(data: bytes) -> None:
    with folder() as tmp:
        np.save(tmp / "cloud.npy", POINTS)
        (tmp / "contacts.json").write_bytes(data)
        code, err = fuse_on(tmp / "cloud.npy", tmp / "contacts.json", tmp / "out")
        assert_one_line_exit_2(code, err)
        assert not (tmp / "out").exists()


# ------------------------------------------------------------------ TOML config

DEFAULTS = load_config(load_registry()).to_dict()
#: Dotted parameter keys of the defaults (no list items, no ``use``).
LEAVES = [
    p
    for p in _paths(DEFAULTS)
    if p
    and all(isinstance(step, str) for step in p)
    and not isinstance(_get(DEFAULTS, p), dict)
    and p[-1] != "use"
]


def _wrong_for(value):
    """Values of a type a parameter declared like ``value`` refuses."""
    if isinstance(value, bool):
        return st.one_of(st.integers(), st.floats(allow_nan=False), st.text(max_size=4))
    if isinstance(value, int):
        return st.one_of(
            st.text(max_size=4),
            st.booleans(),
            st.floats(0.1, 0.9),
            st.lists(st.integers(), max_size=2),
        )
    if isinstance(value, float):
        return st.one_of(
            st.text(max_size=4),
            st.booleans(),
            st.lists(st.floats(), max_size=2),
            st.dictionaries(st.text("ab", min_size=1, max_size=2), st.integers(), max_size=2),
        )
    if isinstance(value, list):
        return st.one_of(
            st.text(max_size=4),
            st.integers(),
            st.lists(st.text(max_size=3), min_size=1, max_size=3),
        )
    return st.one_of(st.integers(), st.booleans(), st.floats(allow_nan=False))


wrong_type = st.sampled_from(LEAVES).flatmap(
    lambda path: _wrong_for(_get(DEFAULTS, path)).map(lambda v: _set(DEFAULTS, path, v))
)
unknown_key = st.tuples(
    st.sampled_from([p[:-1] for p in LEAVES]), st.text("qz_", min_size=1, max_size=6)
).map(lambda pk: _set(DEFAULTS, (*pk[0], pk[1]), 1))
unknown_name = st.tuples(
    st.sampled_from([s for s in DEFAULTS if "use" in DEFAULTS[s]]),
    st.text("qz-", min_size=1, max_size=6),
).map(lambda sn: _set(DEFAULTS, (sn[0], "use"), sn[1]))
bad_syntax = st.sampled_from(["= 1", "[unclosed", "a = ", "a = 1\na = 2", 'x = "open']).flatmap(
    lambda line: st.integers(0, 20).map(
        lambda n: "\n".join([*tomli_w.dumps(DEFAULTS).splitlines()[:n], line]) + "\n"
    )
)
malformed_config = st.one_of(
    wrong_type.map(tomli_w.dumps),
    unknown_key.map(tomli_w.dumps),
    unknown_name.map(tomli_w.dumps),
    st.sampled_from(["trial = 3", "sensor = [1]", "bogus = 1", "[estimator]\nuse = 4"]),
    bad_syntax,
    st.binary(max_size=100).map(lambda b: b"\xff" + b),
)


@FUZZ
@given(text=malformed_config)
def test_a_malformed_config_is_one_line_exit_2(text) -> None:
    with folder() as tmp:
        path = tmp / "bad.toml"
        path.write_bytes(text if isinstance(text, bytes) else text.encode())
        assert_one_line_exit_2(*symfuse("config", "--config", path))


# ------------------------------------------------------------------ meshes


def _encoded(data) -> bytes:
    return data.encode() if isinstance(data, str) else data


BOX = trimesh.creation.box((0.05, 0.08, 0.1))
OBJ_TEXT = BOX.export(file_type="obj")
STL_BYTES = BOX.export(file_type="stl")
malformed_meshes = st.one_of(
    st.tuples(st.sampled_from([".obj", ".stl", ".ply"]), st.binary(max_size=300)),
    st.tuples(st.just(".stl"), cut_before(STL_BYTES, len(STL_BYTES) - 1)),
    st.tuples(
        st.just(".obj"),
        st.sampled_from(BAD_VALUES[:3]).flatmap(lambda v: swap_token(OBJ_TEXT, v)).map(str.encode),
    ),
    st.tuples(st.just(".obj"), st.just(b"v 0 0 0\nv 1 0 0\n")),  # no faces
    st.tuples(st.sampled_from([".obj", ".stl"]), st.just(trimesh.creation.box((45, 80, 100)))).map(
        lambda sm: (sm[0], _encoded(sm[1].export(file_type=sm[0][1:])))
    ),
)


@FUZZ
@given(file=malformed_meshes)
def test_a_malformed_mesh_is_refused_or_read_whole(file) -> None:
    """A mesh reader may repair what trimesh repairs; anything it refuses ends the trial
    with one line and exit 2 before any simulation."""
    suffix, data = file
    with folder() as tmp:
        path = tmp / f"mesh{suffix}"
        path.write_bytes(data)
        try:
            obj = load_object(path)
        except InputError:
            code, err = symfuse("trial", "--mesh", path, "--out", tmp / "out")
            assert_one_line_exit_2(code, err)
            assert not (tmp / "out").exists()
        else:
            assert np.isfinite(obj.mesh.vertices).all() and len(obj.mesh.faces) > 0
            assert max(obj.mesh.extents) <= 2.0
