"""Slow: plane accuracy of VC and PS over random yaws (the study ``bench/vc.py`` prints)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench" / "vc.py"


@pytest.mark.slow
def test_vc_and_ps_recover_the_plane_on_most_views(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH.parent))  # the bench's own helpers (summary)
    spec = importlib.util.spec_from_file_location("bench_vc", BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rows = {(obj, method): ok / total for obj, method, ok, total, _, _ in bench.accuracy(10, 1)}
    for obj in ("box", "cylinder", "spray-bottle"):
        assert rows[(obj, "vc")] >= 0.8, obj
        assert rows[(obj, "vc")] > rows[(obj, "pca")], obj
    assert rows[("box", "ps")] >= 0.8 and rows[("cylinder", "ps")] >= 0.8
