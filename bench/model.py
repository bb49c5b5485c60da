"""Model-files benchmark: what writing the model (every stage's mesh, the collision parts
and the URDF, docs/method.md §12) adds to the default trial, and how the collision parts
compare with the convex decompositions of maintained libraries.

Run: ``python bench/model.py [--repeats N] [--libraries]``. Runs the default trial
(pictures off) ``N`` times in one warm process and prints the median of its ``model``
phase against the median of the rest of the trial, measured in the same runs, in wall and
in processor time (the model's alone by writing the last run's model again, as often;
processor time is what a busy machine does not stretch). Target: the model phase at most
0.5 s. ``--libraries`` also times, on the last trial's selected mesh,
vhacdx (through ``trimesh.decomposition``) and coacd when installed, beside the parts the
trial made: seconds, parts, their volume over the mesh's, and how far they reach past the
mesh's bounding box.

``python bench/model.py --scans DIR [--out RUNS] [--workers N]`` instead runs ``symfuse
trial --mesh DIR/<name>/textured.obj`` on every scan (resuming in ``RUNS``) and prints per
scan whether every model mesh reads back watertight (trimesh) and the selected stage's
Chamfer distance of its mesh against its points', with the share within 10 % for the scans
at even and at odd positions of the sorted list (targets: watertight in at least 98 % of
the trials with a model; the mesh within 10 % of the points).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from summary import record

TARGET_S = 0.5


def trial_phases(repeats: int, folder: Path) -> dict[str, float]:
    """Median wall seconds of the model phase and of the rest of the trial, and median
    processor seconds of the trial and of writing its model."""
    from pipeline.asset.files import write_model
    from pipeline.config import load_config
    from pipeline.registry import load_registry
    from pipeline.run.trial import run_trial

    registry = load_registry()
    config = load_config(registry, overrides=["trial.pictures=false"])
    run_trial(config, registry, folder / "warmup")
    model, rest, cpu, model_cpu = [], [], [], []
    for k in range(repeats):
        started, started_cpu = time.perf_counter(), time.process_time()
        record_ = run_trial(config, registry, folder / f"run{k}")
        total = time.perf_counter() - started
        cpu.append(time.process_time() - started_cpu)
        model.append(record_.timings["model"])
        rest.append(total - record_.timings["model"])
    # The object frame's origin is on the table.
    table = record_.document["model"]["T_robot_object"][2][3]
    for k in range(repeats):
        again = folder / f"again{k}"
        again.mkdir()
        started_cpu = time.process_time()
        write_model(again, record_.result, config.model, table)
        model_cpu.append(time.process_time() - started_cpu)
    median = statistics.median
    return {
        "model": median(model),
        "rest": median(rest),
        "cpu": median(cpu),
        "model_cpu": median(model_cpu),
    }


def part_quality(parts: list, mesh) -> tuple[int, float, float]:
    """Parts, their summed volume over the mesh's, their largest reach past its bounding
    box (mm)."""
    volume = sum(abs(part.volume) for part in parts) / mesh.volume
    low = np.min([part.bounds[0] for part in parts], axis=0)
    high = np.max([part.bounds[1] for part in parts], axis=0)
    reach = max(0.0, float(np.max(np.r_[mesh.bounds[0] - low, high - mesh.bounds[1]])))
    return len(parts), volume, 1e3 * reach


def libraries(run: Path) -> list[tuple[str, float, list]]:
    """(name, seconds, parts) of each installed library on the run's selected mesh."""
    import trimesh

    mesh = trimesh.load(run / "model.obj", force="mesh")
    found = []
    started = time.perf_counter()
    hulls = trimesh.decomposition.convex_decomposition(
        mesh, maxConvexHulls=16, resolution=10_000, maxNumVerticesPerCH=32
    )
    hulls = hulls if isinstance(hulls, list) else [hulls]
    parts = [trimesh.Trimesh(h["vertices"], h["faces"]) for h in hulls]
    found.append(("vhacdx (16 hulls, 10k voxels)", time.perf_counter() - started, parts))
    try:
        import coacd
    except ImportError:
        return found
    coacd.set_log_level("error")
    started = time.perf_counter()
    pieces = coacd.run_coacd(coacd.Mesh(mesh.vertices, mesh.faces), threshold=0.05, seed=0)
    parts = [trimesh.Trimesh(v, f) for v, f in pieces]
    found.append(("coacd (threshold 0.05)", time.perf_counter() - started, parts))
    return found


def scan_trial(scan: Path, out: Path) -> Path:
    """``symfuse trial --mesh`` on one scan into ``out/<name>`` (kept when it is there)."""
    import subprocess
    import sys

    folder = out / scan.name
    if not (folder / "result.json").is_file():
        command = [
            sys.executable,
            "-m",
            "pipeline.cli",
            "trial",
            "--mesh",
            str(scan / "textured.obj"),
        ]
        subprocess.run([*command, "--set", "trial.pictures=false", "--out", str(folder)],
                       capture_output=True, check=False)  # fmt: skip
    return folder


def scan_row(folder: Path) -> dict | None:
    """Watertightness of every model mesh and the selected stage's two Chamfer distances
    (mm); None when the trial left no model (no grasp, a failed segmentation)."""
    import json

    import trimesh

    result = folder / "result.json"
    document = json.loads(result.read_text()) if result.is_file() else {}
    if document.get("model", {}).get("status") != "ok":
        return None
    meshes = [*folder.glob("model_stage*.obj"), folder / "model.obj"]
    selected = document.get("selected_stage")
    metrics = document["stages"][2 if selected is None else selected]["metrics"]
    return {
        "watertight": all(trimesh.load(path, force="mesh").is_watertight for path in meshes),
        "points": metrics["chamfer_mm"],
        "mesh": metrics["mesh_chamfer_mm"],
    }


def scans(root: Path, out: Path, workers: int) -> None:
    from concurrent.futures import ThreadPoolExecutor

    paths = sorted(path.parent for path in root.glob("*/textured.obj"))
    with ThreadPoolExecutor(workers) as pool:
        folders = list(pool.map(lambda scan: scan_trial(scan, out), paths))
    rows = {folder.name: scan_row(folder) for folder in folders}
    print(f"{'scan':<28} {'watertight':>10} {'points mm':>10} {'mesh mm':>8} {'ratio':>6}")
    for name, row in rows.items():
        if row is None:
            print(f"{name:<28} {'no model':>10}")
        else:
            ratio = row["mesh"] / row["points"]
            print(f"{name:<28} {row['watertight']!s:>10} {row['points']:>10.2f} "
                  f"{row['mesh']:>8.2f} {ratio:>6.2f}")  # fmt: skip
    for label, names in (("even", list(rows)[0::2]), ("odd", list(rows)[1::2])):
        kept = [rows[n] for n in names if rows[n] is not None]
        closed = sum(row["watertight"] for row in kept)
        within = sum(row["mesh"] <= 1.1 * row["points"] for row in kept)
        ratios = [row["mesh"] / row["points"] for row in kept] or [float("nan")]
        print(f"{label} positions: {len(kept)}/{len(names)} trials with a model, watertight "
              f"{closed}/{len(kept)}, mesh within 10 % of the points {within}/{len(kept)}, "
              f"median ratio {statistics.median(ratios):.2f}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--libraries", action="store_true")
    parser.add_argument("--scans", type=Path, help="folder of scans DIR/*/textured.obj")
    parser.add_argument("--out", type=Path, help="keep the scans' trial folders here")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    if args.scans is not None:
        with tempfile.TemporaryDirectory() as folder:
            scans(args.scans, args.out or Path(folder), args.workers)
        return
    with tempfile.TemporaryDirectory() as folder:
        run = Path(folder) / f"run{args.repeats - 1}"
        times = trial_phases(args.repeats, Path(folder))
        share = times["model"] / (times["model"] + times["rest"])
        met = "yes" if times["model"] <= TARGET_S else "no"
        print(f"default trial, pictures off, median of {args.repeats} (s)")
        print(f"{'measure':<46} {'measured':>9} {'target':>7}  met")
        rows = [
            ("the trial without the model files (wall)", f"{times['rest']:>9.3f}"),
            (
                "the model files: every stage, parts, URDF (wall)",
                f"{times['model']:>9.3f} {TARGET_S:>7.1f}  {met}",
            ),
            ("their share of the trial (wall)", f"{share:>9.1%}"),
            ("the trial (processor)", f"{times['cpu']:>9.3f}"),
            ("the model files (processor)", f"{times['model_cpu']:>9.3f}"),
        ]
        for label, shown in rows:
            print(f"{label:<46} {shown}")
        record(
            f"model files in the default trial (trial without them {times['rest']:.2f} s; "
            f"processor {times['model_cpu']:.2f} of {times['cpu']:.2f} s)",
            times["model"],
            "s",
            TARGET_S,
        )
        if args.libraries:
            import trimesh

            mesh = trimesh.load(run / "model.obj", force="mesh")
            ours = trimesh.load(
                run / "model_collision.obj", split_object=True, group_material=False
            )
            ours = list(ours.geometry.values()) if isinstance(ours, trimesh.Scene) else [ours]
            print()
            print(f"{'convex parts of the selected mesh':<34} {'s':>6} {'parts':>6} "
                  f"{'volume':>7} {'reach mm':>9}")  # fmt: skip
            rows = [("symfuse (in the model phase)", float("nan"), ours), *libraries(run)]
            for name, seconds, parts in rows:
                count, volume, reach = part_quality(parts, mesh)
                print(f"{name:<34} {seconds:>6.2f} {count:>6d} {volume:>7.3f} {reach:>9.2f}")


if __name__ == "__main__":
    main()
