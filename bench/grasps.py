"""Grasps on every catalogue object and YCB scan: the hand chosen, opposing contacts, tilt.

Run ``python bench/grasps.py`` (nice it on a shared machine). For each object - the
catalogue, and every ``*/textured.obj`` under ``--ycb DIR`` (default: the folder named by
``$SYMFUSE_SCANS``; none when unset) - and each of ``--yaws`` random yaws (seeded), one
simulated grasp as a trial makes it: render, segment, propose a plane, plan and choose the
hand (``--gripper``, default ``auto``), grasp, read the taxels. No estimator, no pictures.
``--only`` runs objects whose name contains a string; ``--out`` keeps ``results.jsonl`` (a
re-run resumes).

Prints per object: the hand(s) chosen, the grasps with contacts on two opposing sides
(:func:`pipeline.metrics.evaluation.opposing_contacts`), the median object tilt and shift during the
grasp and the grasps that tilted it less than 5 deg. Targets: opposing contacts in at least
90 % of the yaws and tilt below 5 deg in at least 95 %, for every object a hand can hold.
"""

from __future__ import annotations

import argparse
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.catalogue.objects import list_objects, load_object
from pipeline.config import load_config
from pipeline.errors import StageFailure
from pipeline.experiments import SweepTask
from pipeline.experiments.scanned import SCANS_ENV, default_scans_dir
from pipeline.experiments.sweep import run_sweep
from pipeline.metrics.evaluation import object_motion, opposing_contacts
from pipeline.planning.hand_choice import candidate_to_json, choose_grasp
from pipeline.registry import load_registry
from pipeline.reports.tables import format_table
from pipeline.types import SceneSetup

#: Tilt below which a grasp counts as not tipping the object (deg).
TILT_LIMIT_DEG = 5.0


def grasp_once(params: dict[str, Any]) -> dict[str, Any]:
    """One grasp of ``params["object"]`` at ``params["yaw_deg"]``; the row the table reads."""
    registry = load_registry()
    config = load_config(
        registry,
        overrides=[
            f"trial.gripper={params['gripper']}",
            f"trial.seed={params['seed']}",
            *params["overrides"],
        ],
    )
    stages = {s: config.create(registry, s) for s in ("sensor", "segmenter", "initialiser")}
    obj = load_object(params["object"])
    world = config.create(registry, "world")
    world.load_scene(SceneSetup(obj, yaw_rad=np.radians(params["yaw_deg"]), seed=params["seed"]))
    try:
        observation = stages["sensor"].observe(world)
        try:
            cloud = stages["segmenter"].segment(observation)
        except StageFailure as exc:
            return {"refused": f"segmentation: {exc}"}
        proposal = stages["initialiser"].propose(cloud, observation)
        grippers = {name: world.gripper_spec(name) for name in world.hands}
        choice = choose_grasp(
            config, registry, cloud, proposal, grippers, observation.table_height_m
        )
        if choice.plan.status != "ok":
            return {"refused": choice.plan.reason}
        world.add_hand(choice.plan.gripper)
        outcome = world.execute_grasp(choice.plan)
        if not outcome.executed:
            return {"gripper": choice.plan.gripper, "refused": outcome.reason}
        contacts = config.create(registry, "tactile").read(world, outcome)
        shift_m, tilt_rad = object_motion(obj.mesh, outcome.object_before, outcome.object_after)
    finally:
        world.close()
    best = choice.plan.candidates[0] if choice.plan.candidates else None
    return {
        "gripper": choice.plan.gripper,
        "refused": None,
        "grasp": None if best is None else candidate_to_json(best),
        "pads": sorted(set(contacts.pads.tolist())),
        "taxels": len(contacts),
        "reapproaches": outcome.reapproaches,
        "opposing": opposing_contacts(contacts),
        "shift_mm": 1e3 * shift_m,
        "tilt_deg": float(np.degrees(tilt_rad)),
    }


def object_names(ycb: Path | None, only: str | None) -> list[str]:
    names = [info.name for info in list_objects()]
    if ycb is not None and ycb.is_dir():
        names += [str(path) for path in sorted(ycb.glob("*/textured.obj"))]
    return [n for n in names if only is None or only in n]


def label(name: str) -> str:
    return Path(name).parent.name if name.endswith(".obj") else name


def summary(rows: list[dict[str, Any]]) -> tuple[list[list[str]], int, int]:
    """Table rows per object, and how many objects (of those some hand held) met both
    targets."""
    by_object: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by_object.setdefault(row["params"]["object"], []).append(row)
    table, held, met = [], 0, 0
    for name, group in by_object.items():
        done = [r for r in group if "error" not in r and not r.get("refused")]
        hands = Counter(r["gripper"] for r in done)
        opposing = sum(r["opposing"] for r in done)
        tilts = np.array([r["tilt_deg"] for r in done])
        upright = int(np.sum(tilts < TILT_LIMIT_DEG))
        n = len(group)
        refused = Counter(
            (r.get("error") or r.get("refused") or "").split(":")[0] for r in group if r not in done
        )
        if done:
            held += 1
            met += opposing >= 0.9 * n and upright >= 0.95 * n
        table.append(
            [
                label(name),
                " ".join(f"{h} {k}" for h, k in hands.most_common()) or "-",
                f"{opposing}/{n}",
                f"{np.median(tilts):.1f}" if done else "-",
                f"{upright}/{n}",
                f"{np.median([r['shift_mm'] for r in done]):.1f}" if done else "-",
                "; ".join(f"{k} x{v}" for k, v in refused.items()) or "-",
            ]
        )
    return table, held, met


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--ycb",
        type=Path,
        default=default_scans_dir(),
        help=f"folder of YCB scans DIR/*/textured.obj (default: ${SCANS_ENV})",
    )
    parser.add_argument("--only", help="only objects whose name contains this")
    parser.add_argument("--yaws", type=int, default=20, help="random yaws per object")
    parser.add_argument("--gripper", default="auto", help="auto, pg70 or sdh")
    parser.add_argument("--seed", type=int, default=0, help="seed of the yaws")
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--workers", type=int, default=1, help="grasps run at once")
    parser.add_argument("--out", type=Path, help="keep results.jsonl here (resumable)")
    args = parser.parse_args()
    names = object_names(args.ycb, args.only)
    if not names:
        parser.error("no objects")
    rng = np.random.default_rng(args.seed)
    tasks = []
    for name in names:
        for k, yaw in enumerate(rng.uniform(-180.0, 180.0, args.yaws)):
            params = {
                "object": name,
                "yaw_deg": float(yaw),
                "seed": args.seed + k,
                "gripper": args.gripper,
                "overrides": args.overrides,
            }
            tasks.append(SweepTask(f"{label(name)}/yaw{k}", params))
    with tempfile.TemporaryDirectory(prefix="symfuse-grasps-") as scratch:
        out = args.out or Path(scratch)
        out.mkdir(parents=True, exist_ok=True)
        rows = run_sweep(tasks, grasp_once, out / "results.jsonl", workers=args.workers)
    table, held, met = summary(rows)
    header = [
        "object",
        "hand chosen",
        "opposing contacts",
        "median tilt (deg)",
        f"tilt < {TILT_LIMIT_DEG:g} deg",
        "median shift (mm)",
        "refused / not executed",
    ]
    print(format_table(header, table))
    print(
        f"\n{met}/{held} objects some hand held met both targets "
        f"(opposing >= 90 %, tilt < {TILT_LIMIT_DEG:g} deg >= 95 %)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
