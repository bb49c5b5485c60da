"""The perception figures are written as PNG files."""

from __future__ import annotations

import numpy as np

from pipeline.reports.trial_pictures import plot_cloud_with_plane, plot_vc_scores
from pipeline.types import SymmetryHypothesis, SymmetryPlane


def test_plots_write_pngs(tmp_path):
    points = np.random.default_rng(0).uniform([0.5, -0.05, 0.0], [0.55, 0.05, 0.1], (500, 3))
    plane = SymmetryPlane(0.0, 0.56)
    cloud_png = plot_cloud_with_plane(points, plane, tmp_path / "cloud.png")
    hypotheses = [
        SymmetryHypothesis(SymmetryPlane(t, 0.5 + r), score=abs(r) * 5, violations=int(r * 1e3))
        for t in (-0.2, 0.0, 0.2)
        for r in (0.0, 0.01, 0.02)
    ]
    scores_png = plot_vc_scores(hypotheses, np.array([0.5, 0.0, 0.05]), tmp_path / "vc.png")
    for path in (cloud_png, scores_png):
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
