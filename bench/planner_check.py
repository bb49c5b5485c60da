"""A hand's planner against a baseline: the same plans and candidate tables, and its speed.

Run: ``python bench/planner_check.py [--baseline REV] [--yaws 0,35,70] [--objects A,B]
[--hand sdh|pg70]``.
The planner's inputs are made once, by this tree, for every catalogue object (or those
named) at each yaw: the default trial's scene, simulated camera, segmenter and initialiser
(seed 0), as the trial's planner phase receives them. Then this tree and the baseline
revision (default: where this branch left ``main``, unpacked with ``git archive`` as
``sweep_speed.py`` does) each plan on the same inputs with the hand's planner (the SDH-2's
``top-three-finger``, by default, or the PG-70's ``top-parallel``) as the default config
sets it up, in a new process of their own, and the table
compares them: every candidate's summary (closing angle, height, spread, width, contact
coverages, tipping ratio, score, feasibility and reason) and the chosen plan (status,
palm pose, opening, spread, score, predicted contacts) must be equal, bit for bit; any
difference is listed with the largest numeric one. The processor time of each tree's
planning is summed over the cases (each case planned twice, the second timed).

Target (issue 41): the planner with ``--gripper auto`` within 0.4 s on the default trial,
which the SDH-2 planner dominates; the ratio here is what the SDH-2 candidates cost
against the baseline.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from sweep_speed import ROOT, default_baseline, unpack

#: Each hand's planner.
PLANNERS = {"sdh": "top-three-finger", "pg70": "top-parallel"}


def make_inputs(objects: list[str], yaws: list[float], path: Path) -> list[str]:
    """The planner's inputs for every object and yaw, saved to ``path`` (``.npz``); the
    cases' names."""
    from pipeline.catalogue.objects import list_objects, load_object
    from pipeline.config import load_config
    from pipeline.registry import load_registry
    from pipeline.run.trial import TrialStages
    from pipeline.types import SceneSetup

    registry = load_registry()
    names = objects or [info.name for info in list_objects()]
    arrays: dict[str, np.ndarray] = {}
    cases = []
    for name in names:
        for yaw in yaws:
            overrides = [f'trial.object="{name}"', f"trial.yaw_deg={yaw}", "trial.pictures=false"]
            config = load_config(registry, overrides=overrides)
            stages = TrialStages.build(config, registry)
            world = stages.world
            try:
                world.load_scene(SceneSetup(load_object(name), yaw_rad=math.radians(yaw), seed=0))
                observation = stages.sensor.observe(world)
                cloud = stages.segmenter.segment(observation)
                proposal = stages.initialiser.propose(cloud, observation)
            finally:
                world.close()
            case = f"{name}@{yaw:g}"
            cases.append(case)
            arrays[f"{case}:points"] = cloud.points
            arrays[f"{case}:viewpoint"] = cloud.viewpoint_m
            arrays[f"{case}:plane"] = np.array([proposal.plane.theta_rad, proposal.plane.offset_m])
    np.savez(path, cases=np.array(cases), **arrays)
    return cases


def plan_cases(inputs: Path, out: Path, hand: str = "sdh") -> None:
    """Plan every case of ``inputs`` for ``hand`` with the code on the import path; write
    the tables and the processor time to ``out`` (JSON)."""
    from pipeline.config import load_config
    from pipeline.planning.hand_choice import create_planner
    from pipeline.registry import load_registry
    from pipeline.sim.hand_models import GRIPPERS
    from pipeline.types import Bias, PointCloud, SymmetryInit, SymmetryPlane

    registry = load_registry()
    planner = create_planner(load_config(registry), registry, PLANNERS[hand])
    data = np.load(inputs)
    found, seconds = {}, 0.0
    for case in data["cases"]:
        cloud = PointCloud(data[f"{case}:points"], viewpoint_m=data[f"{case}:viewpoint"])
        theta, offset = data[f"{case}:plane"]
        proposal = SymmetryInit(plane=SymmetryPlane(float(theta), float(offset)), bias=Bias())
        planner.plan(cloud, proposal, GRIPPERS[hand])  # warm: caches as a trial has them
        started = time.process_time()
        plan = planner.plan(cloud, proposal, GRIPPERS[hand])
        seconds += time.process_time() - started
        found[str(case)] = {
            "plan": {
                "status": plan.status,
                "reason": plan.reason,
                "T_robot_hand": plan.T_robot_hand.tolist(),
                "opening_m": plan.opening_m,
                "spread_rad": plan.spread_rad,
                "score": plan.score,
                "predicted_contacts": np.asarray(plan.predicted_contacts).tolist(),
            },
            "candidates": [
                [
                    c.closing_angle_deg,
                    c.height_m,
                    c.spread_deg,
                    c.width_m,
                    list(c.contact_coverage),
                    c.tipping_ratio,
                    c.score,
                    c.feasible,
                    c.reason,
                ]
                for c in plan.candidates
            ],
        }
    out.write_text(json.dumps({"seconds": seconds, "cases": found}))


def differences(base: object, new: object, where: str = "") -> list[tuple[str, float]]:
    """Where ``base`` and ``new`` differ (NaN equals NaN), with the numeric difference
    (NaN for a non-numeric one)."""
    if isinstance(base, dict) and isinstance(new, dict):
        if set(base) != set(new):
            return [(where + ": keys", math.nan)]
        return [d for k in base for d in differences(base[k], new[k], f"{where}/{k}")]
    if isinstance(base, list) and isinstance(new, list):
        if len(base) != len(new):
            return [(f"{where}: length {len(base)} vs {len(new)}", math.nan)]
        return [d for a, b in zip(base, new, strict=True) for d in differences(a, b, where)]
    if isinstance(base, float) and isinstance(new, float):
        if base == new or (base != base and new != new):
            return []
        return [(where, abs(base - new))]
    return [] if base == new else [(where, math.nan)]


def run_tree(tree: Path, inputs: Path, out: Path, hand: str) -> dict:
    """:func:`plan_cases` in a new process with ``tree``'s code first on the path."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tree), str(ROOT / "bench")])}
    command = [sys.executable, str(ROOT / "bench/planner_check.py")]
    command += ["--plan", str(inputs), str(out), "--hand", hand]
    subprocess.run(command, env=env, cwd=tree, check=True)
    return json.loads(out.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="git revision to compare with (default: merge base)")
    parser.add_argument("--yaws", default="0,35,70", help="object yaws (deg), comma-separated")
    parser.add_argument("--objects", default="", help="catalogue objects (default: all)")
    parser.add_argument("--hand", choices=sorted(PLANNERS), default="sdh", help="hand planned for")
    parser.add_argument("--plan", nargs=2, type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.plan:
        plan_cases(*args.plan, args.hand)
        return
    revision = args.baseline or default_baseline()
    yaws = [float(y) for y in args.yaws.split(",")]
    objects = [o for o in args.objects.split(",") if o]
    with tempfile.TemporaryDirectory(prefix="symfuse-planner-check-") as folder:
        inputs = Path(folder) / "inputs.npz"
        cases = make_inputs(objects, yaws, inputs)
        base = run_tree(
            unpack(revision, Path(folder)), inputs, Path(folder) / "base.json", args.hand
        )
        new = run_tree(ROOT, inputs, Path(folder) / "new.json", args.hand)
    print(f"{PLANNERS[args.hand]} on {len(cases)} cases, baseline {revision[:10]}")
    print(f"{'case':<26} {'candidates':>10} {'feasible':>8} {'plan':>8}  same")
    unequal = 0
    for case in cases:
        table = new["cases"][case]["candidates"]
        feasible = sum(1 for row in table if row[7])
        found = differences(base["cases"][case], new["cases"][case])
        unequal += bool(found)
        status = new["cases"][case]["plan"]["status"]
        print(f"{case:<26} {len(table):>10} {feasible:>8} {status:>8}  {'no' if found else 'yes'}")
        for where, size in found[:5]:
            print(f"    differs at {where} (by {size:.3g})")
    ratio = base["seconds"] / new["seconds"]
    print(
        f"processor time of the second plan, summed: baseline {base['seconds']:.2f} s, "
        f"this tree {new['seconds']:.2f} s ({ratio:.2f}x faster); "
        f"cases differing: {unequal} of {len(cases)}"
    )


if __name__ == "__main__":
    main()
