"""Benchmark the per-taxel tactile model and grasp execution in PyBullet (DIRECT mode).

Run: ``python bench/tactile.py [--reads N]``. A PG-70 grasps a 42 mm box (two 6 x 14 pads,
168 taxels) and an SDH-2 grasps an 80 mm cylinder (six pads, 486 taxels); the tactile model
then reads the contacts ``N`` times. Target: at least 1000 reads/s (under 1 ms per read)
for the two 6 x 14 pads, and a grasp well under 1 s of wall time.
"""

from __future__ import annotations

import argparse
import os
import time
from types import SimpleNamespace

import numpy as np
import pybullet as pb
from summary import record

from pipeline.sim.grasping import execute_grasp
from pipeline.sim.hands import Hand
from pipeline.types import GraspPlan
from plugins.tactile.pybullet_taxels import PybulletTaxels


def _world(gripper: str) -> tuple[SimpleNamespace, GraspPlan]:
    client = pb.connect(pb.DIRECT)
    pb.setGravity(0, 0, -9.81, physicsClientId=client)
    plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
    pb.createMultiBody(0, plane, physicsClientId=client)
    if gripper == "pg70":
        shape = pb.createCollisionShape(
            pb.GEOM_BOX, halfExtents=[0.021, 0.04, 0.06], physicsClientId=client
        )
        palm_z, opening, spread = 0.225, 0.065, 0.0
    else:
        shape = pb.createCollisionShape(
            pb.GEOM_CYLINDER, radius=0.04, height=0.12, physicsClientId=client
        )
        palm_z, opening, spread = 0.30, 0.12, np.deg2rad(60.0)
    object_id = pb.createMultiBody(
        0.2, shape, basePosition=[0.5, 0.1, 0.06], physicsClientId=client
    )
    hand = Hand.load(client, gripper)
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [0.5, 0.1, palm_z]
    plan = GraspPlan(gripper, "ok", T, 0.06, opening, np.array([1.0, 0, 0]), spread_rad=spread)
    world = SimpleNamespace(
        client=client,
        hand=hand,
        object_id=object_id,
        taxels=lambda behind_m, beyond_m: hand.taxel_state(object_id, behind_m, beyond_m),
        rng=np.random.default_rng(0),
    )
    return world, plan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reads", type=int, default=2000, help="tactile reads to time")
    args = parser.parse_args()
    model = PybulletTaxels()
    rows = []
    for gripper in ("pg70", "sdh"):
        world, plan = _world(gripper)
        start = time.perf_counter()
        outcome = execute_grasp(world.client, world.hand, plan, world.object_id)
        grasp_s = time.perf_counter() - start
        contacts = model.read(world, outcome)
        times = np.empty(args.reads)
        cpu_start = time.process_time()
        for i in range(args.reads):
            start = time.perf_counter()
            model.read(world, outcome)
            times[i] = time.perf_counter() - start
        cpu_s = (time.process_time() - cpu_start) / args.reads
        taxels = len(world.hand.taxel_frames().positions)
        rows.append((gripper, taxels, len(contacts), times, cpu_s, grasp_s, outcome.executed))
        pb.disconnect(world.client)

    load = os.getloadavg()[0]
    print(f"tactile reads ({args.reads} per hand) and grasp wall time, load average {load:.1f} on")
    print(f"{os.cpu_count()} cores; target: >= 1000 reads/s for the PG-70's two 6x14 pads, grasp")
    print("well under 1 s. reads/s from the mean wall time; cpu us = process CPU time per read.")
    header = (
        f"{'hand':<6} {'taxels':>6} {'contact':>7} {'mean us':>8} {'median us':>9} "
        f"{'cpu us':>7} {'reads/s':>8} {'target':>8} {'grasp s':>8} {'executed':>8}"
    )
    print(header)
    print("-" * len(header))
    for gripper, taxels, touching, times, cpu_s, grasp_s, executed in rows:
        target = ">= 1000" if gripper == "pg70" else "-"
        if gripper == "pg70":
            record("tactile reads per second, PG-70", 1.0 / times.mean(), "/s", 1000, at_most=False)
        print(
            f"{gripper:<6} {taxels:>6} {touching:>7} {times.mean() * 1e6:>8.0f} "
            f"{np.median(times) * 1e6:>9.0f} {cpu_s * 1e6:>7.0f} {1.0 / times.mean():>8.0f} "
            f"{target:>8} "
            f"{grasp_s:>8.3f} {executed!s:>8}"
        )


if __name__ == "__main__":
    main()
