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
    from pipeline.trial import run_trial

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--libraries", action="store_true")
    args = parser.parse_args()
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
