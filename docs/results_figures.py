"""Draw the pictures of docs/results.md: one per shape score, from a real trial.

    python docs/results_figures.py               # runs the trial below, writes docs/images/
    python docs/results_figures.py --run DIR     # or draws from a finished trial's folder

The trial is the README's (CD drive, VC initialisation, 14 mm / 2 deg calibration error), so
Stage 0 and Stage 2 differ visibly. Every score is computed in 3-D by the same functions
``symfuse trial`` uses; the pictures show a horizontal slab through the middle of the object,
seen from above.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Polygon as PolygonPatch
from scipy.spatial import cKDTree

from pipeline.io.formats import read_cloud
from pipeline.metrics import (
    hull_iou,
    nearest_distances,
    point_to_mesh_distances,
    sample_surface,
    solid_grid,
    surface_scores,
)
from pipeline.metrics.evaluation import SURFACE_SAMPLES

IMAGES = Path(__file__).resolve().parent / "images"
TRIAL = [
    "trial.object=cd_drive",
    "initialiser.use=vc",
    "trial.yaw_deg=20",
    "sensor.pybullet-kinect.calibration_translation_m=[0.012,-0.008,0.0]",
    "sensor.pybullet-kinect.calibration_yaw_deg=2.0",
    "trial.pictures=false",
]
STAGES = (0, 2)
#: Half the height of the slab drawn (m).
SLAB_M = 0.004
#: F-score threshold the picture shows (m).
TAU_M = 0.002


def run_trial(out_dir: Path) -> Path:
    from pipeline.config import load_config
    from pipeline.registry import load_registry
    from pipeline.run.trial import run_trial as run

    registry = load_registry()
    run(load_config(registry, overrides=TRIAL), registry, out_dir)
    return out_dir


class Scene:
    """A trial's true mesh and completed models with the 3-D distances behind the scores."""

    def __init__(self, run_dir: Path) -> None:
        self.mesh = trimesh.load(run_dir / "object_final.ply", force="mesh")
        self.samples = sample_surface(self.mesh.vertices, self.mesh.faces, SURFACE_SAMPLES)
        self.solid = solid_grid(self.mesh.vertices, self.mesh.faces)
        self.models = {k: read_cloud(run_dir / f"completed_stage{k}.ply").points for k in STAGES}
        low, high = self.mesh.bounds
        self.z = 0.5 * (low[2] + high[2])

    def to_truth(self, k: int) -> np.ndarray:
        return point_to_mesh_distances(self.models[k], self.mesh.vertices, self.mesh.faces)

    def to_model(self, k: int) -> np.ndarray:
        return nearest_distances(self.samples, self.models[k])

    def scores(self, k: int) -> dict[str, float]:
        return surface_scores(self.to_truth(k), self.to_model(k))

    def in_slab(self, points: np.ndarray) -> np.ndarray:
        return np.abs(points[:, 2] - self.z) < SLAB_M

    def outline(self, mesh: trimesh.Trimesh) -> list[np.ndarray]:
        """The (x, y) rings of a mesh's cross-section at the slab's height."""
        section = mesh.section(plane_origin=[0.0, 0.0, self.z], plane_normal=[0.0, 0.0, 1.0])
        return [] if section is None else [ring[:, :2] for ring in section.discrete]


def _axes_grid(title: str):
    figure = Figure(figsize=(10.0, 4.8))
    FigureCanvasAgg(figure)
    axes = figure.subplots(1, len(STAGES))
    figure.suptitle(title)
    return figure, axes


def _finish(ax, scene: Scene, heading: str) -> None:
    for ring in scene.outline(scene.mesh):
        ax.plot(ring[:, 0] * 1e3, ring[:, 1] * 1e3, color="black", lw=1.2)
    ax.set_title(heading, fontsize=10)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")


def _save(figure: Figure, out: Path, caption: str) -> Path:
    figure.text(0.01, 0.01, caption, fontsize=8)
    figure.savefig(out, dpi=90)
    return out


def chamfer_figure(scene: Scene, out: Path) -> Path:
    figure, axes = _axes_grid(
        "Chamfer distance: mean of the two directions' nearest distances (slab at mid-height)"
    )
    for ax, k in zip(axes, STAGES, strict=True):
        model, to_truth, to_model = scene.models[k], scene.to_truth(k), scene.to_model(k)
        slab = scene.in_slab(model)
        drawn = ax.scatter(
            model[slab, 0] * 1e3,
            model[slab, 1] * 1e3,
            c=to_truth[slab] * 1e3,
            s=4,
            cmap="viridis",
            vmin=0.0,
            vmax=10.0,
        )
        # A few true-surface samples with a line to their nearest model point.
        samples = scene.samples[scene.in_slab(scene.samples)][::6]
        _, index = cKDTree(model).query(samples)
        for start, end in zip(samples, model[index], strict=True):
            ax.plot([start[0] * 1e3, end[0] * 1e3], [start[1] * 1e3, end[1] * 1e3], "r-", lw=0.6)
        ax.plot(samples[:, 0] * 1e3, samples[:, 1] * 1e3, "r.", ms=2)
        chamfer = 0.5e3 * (to_truth.mean() + to_model.mean())
        _finish(
            ax,
            scene,
            f"Stage {k}: ({to_truth.mean() * 1e3:.1f} + {to_model.mean() * 1e3:.1f}) / 2 "
            f"= {chamfer:.1f} mm",
        )
    figure.colorbar(drawn, ax=list(axes), label="model point to true surface (mm)")
    return _save(
        figure,
        out,
        "dots: model points (colour: distance to the true surface); red: true-surface "
        "samples and the line to their nearest model point; black: true outline",
    )


def fscore_figure(scene: Scene, out: Path) -> Path:
    figure, axes = _axes_grid(
        f"F-score at {TAU_M * 1e3:g} mm: precision (model near truth) and recall (truth "
        "covered by model)"
    )
    for ax, k in zip(axes, STAGES, strict=True):
        model, to_truth, to_model = scene.models[k], scene.to_truth(k), scene.to_model(k)
        slab = scene.in_slab(model)
        right = to_truth < TAU_M
        ax.plot(*(model[slab & right, :2].T * 1e3), ".", color="tab:green", ms=2)
        ax.plot(*(model[slab & ~right, :2].T * 1e3), ".", color="tab:red", ms=2)
        sample_slab = scene.in_slab(scene.samples)
        covered = to_model < TAU_M
        ax.plot(
            *(scene.samples[sample_slab & covered, :2].T * 1e3),
            "o",
            mfc="none",
            color="tab:blue",
            ms=3,
            mew=0.6,
        )
        ax.plot(
            *(scene.samples[sample_slab & ~covered, :2].T * 1e3),
            "x",
            color="tab:orange",
            ms=3,
            mew=0.8,
        )
        scores = scene.scores(k)
        label = f"{TAU_M * 1e3:g}mm"
        _finish(
            ax,
            scene,
            f"Stage {k}: P {scores[f'precision_{label}']:.2f}, R {scores[f'recall_{label}']:.2f}"
            f", F {scores[f'fscore_{label}']:.2f}",
        )
    return _save(
        figure,
        out,
        f"model points within {TAU_M * 1e3:g} mm of the true surface: green (else red); true-"
        f"surface samples with a model point within {TAU_M * 1e3:g} mm: blue circles (else "
        "orange crosses)",
    )


def iou_figure(scene: Scene, out: Path) -> Path:
    import shapely

    figure, axes = _axes_grid(
        "Volumetric IoU: the model's convex hull against the true solid (section at mid-height)"
    )
    for ax, k in zip(axes, STAGES, strict=True):
        hull = trimesh.convex.convex_hull(scene.models[k])
        truth_rings, hull_rings = scene.outline(scene.mesh), scene.outline(hull)
        truth_area = shapely.union_all([shapely.Polygon(r) for r in truth_rings])
        hull_area = shapely.union_all([shapely.Polygon(r) for r in hull_rings])
        common = truth_area.intersection(hull_area)
        for polygon in getattr(common, "geoms", [common]):
            if not polygon.is_empty:
                xy = np.asarray(polygon.exterior.coords) * 1e3
                ax.add_patch(PolygonPatch(xy, color="tab:purple", alpha=0.35, lw=0))
        for ring in hull_rings:
            ax.plot(ring[:, 0] * 1e3, ring[:, 1] * 1e3, color="tab:purple", lw=1.2)
        iou = hull_iou(scene.models[k], scene.solid)
        section_iou = common.area / hull_area.union(truth_area).area
        _finish(ax, scene, f"Stage {k}: IoU {iou:.2f} (this section alone {section_iou:.2f})")
    return _save(
        figure,
        out,
        "black: true outline; purple: the completed model's hull; shaded: both (the IoU is "
        "their common volume over their joint volume, in 3-D)",
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, help="a finished trial's folder (default: run one)")
    parser.add_argument("--out", type=Path, default=IMAGES, help="where the PNGs go")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="symfuse-results-") as scratch:
        scene = Scene(args.run or run_trial(Path(scratch)))
        for draw, name in (
            (chamfer_figure, "metric_chamfer.png"),
            (fscore_figure, "metric_fscore.png"),
            (iou_figure, "metric_iou.png"),
        ):
            print(f"wrote {draw(scene, args.out / name)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
