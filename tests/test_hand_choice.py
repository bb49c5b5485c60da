"""``trial.gripper = "auto"``: the hand is chosen by the planners' best feasible grasps, the
grasp holds tall and narrow objects from opposing sides without tipping them, and an object
no hand can hold is refused in one line."""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from pipeline.cli import main
from pipeline.config import load_config
from pipeline.errors import ConfigError
from pipeline.metrics.evaluation import object_motion, opposing_contacts
from pipeline.planning.hand_choice import check_planner_is_read, choose_grasp
from pipeline.registry import load_registry
from pipeline.sim.hands import GRIPPERS
from pipeline.stages import GraspPlanner
from pipeline.testing import estimation_problem, registry_with
from pipeline.types import Bias, GraspPlan, SymmetryInit
from plugins.worlds.pybullet_world import Pybullet


@pytest.fixture(scope="module")
def registry():
    return load_registry()


def _cylinder(name: str, diameter: float, height: float, mass: float) -> SimpleNamespace:
    mesh = trimesh.creation.cylinder(radius=diameter / 2, height=height, sections=48)
    mesh.apply_translation((0.0, 0.0, height / 2))
    return SimpleNamespace(name=name, mesh=mesh, mass_kg=mass, friction=0.6)


def _auto_grasp(registry, obj, yaw_deg: float, seed: int = 0, hand: str = "auto"):
    """Sense, choose the hand (``trial.gripper = hand``), grasp, read the taxels."""
    overrides = [f"trial.gripper={hand}", f"trial.seed={seed}"]
    config = load_config(registry, overrides=overrides)
    stages = {s: config.create(registry, s) for s in ("sensor", "segmenter", "initialiser")}
    with Pybullet.create(obj, None, yaw=np.radians(yaw_deg), seed=seed) as world:
        observation = stages["sensor"].observe(world)
        cloud = stages["segmenter"].segment(observation)
        proposal = stages["initialiser"].propose(cloud, observation)
        choice = choose_grasp(
            config, registry, cloud, proposal, GRIPPERS, observation.table_height_m
        )
        assert choice.plan.status == "ok", choice.plan.reason
        world.add_hand(choice.plan.gripper)
        outcome = world.execute_grasp(choice.plan)
        assert outcome.executed, outcome.reason
        contacts = config.create(registry, "tactile").read(world, outcome)
    shift, tilt = object_motion(obj.mesh, outcome.object_before, outcome.object_after)
    return choice, contacts, shift, np.degrees(tilt)


@pytest.mark.parametrize("yaw_deg", [0.0, 70.0])
@pytest.mark.slow
def test_a_tall_bottle_is_held_from_opposing_sides_without_tipping(registry, yaw_deg):
    """250 mm tall, 70 mm across, 0.4 kg: wider than the PG-70 opens, so the SDH-2 grasps
    it, low enough and guarded so that it does not tip."""
    bottle = _cylinder("bottle", 0.07, 0.25, 0.4)
    choice, contacts, shift, tilt = _auto_grasp(registry, bottle, yaw_deg)
    assert choice.plan.gripper == "sdh"
    assert "pg70" in choice.reason  # why not the other hand
    assert opposing_contacts(contacts)
    assert tilt < 5.0 and shift < 0.01


def test_a_narrow_cylinder_is_held_from_opposing_sides(registry):
    """40 mm across: the PG-70 fits it."""
    narrow = _cylinder("narrow", 0.04, 0.1, 0.2)
    choice, contacts, shift, tilt = _auto_grasp(registry, narrow, 30.0)
    assert choice.plan.gripper == "pg70"
    assert opposing_contacts(contacts)
    assert tilt < 5.0 and shift < 0.01


def test_a_narrow_cylinder_is_held_by_the_sdh_pre_shaped_to_it(registry):
    narrow = _cylinder("narrow", 0.04, 0.1, 0.2)
    choice, contacts, _, tilt = _auto_grasp(registry, narrow, 17.0, seed=1, hand="sdh")
    assert choice.plan.gripper == "sdh"
    assert opposing_contacts(contacts)
    assert tilt < 5.0


def _box(name: str, extents: tuple[float, float, float], mass: float) -> SimpleNamespace:
    mesh = trimesh.creation.box(extents)
    mesh.apply_translation((0.0, 0.0, extents[2] / 2))
    return SimpleNamespace(name=name, mesh=mesh, mass_kg=mass, friction=0.6)


@pytest.mark.parametrize("thickness_m", [0.006, 0.015])
def test_the_pg70_touches_both_sides_of_a_thin_plate(registry, thickness_m):
    """Both pads touch: the back jaw, closing at most half the aperture, reaches the back
    of a plate thinner than its reach from the visible front."""
    box = _box("plate", (thickness_m, 0.06, 0.1), 0.2)
    choice, contacts, shift, tilt = _auto_grasp(registry, box, 0.0, hand="pg70")
    assert choice.plan.gripper == "pg70"
    assert set(contacts.pads) == {"left", "right"}
    assert opposing_contacts(contacts)
    assert tilt < 5.0 and shift < 0.01


def test_the_pg70_grasps_a_box_too_wide_for_the_back_jaws_margin(registry):
    """54 mm across leaves 11 mm of the 65 mm aperture, less than the clearances and the
    back margin ask for: the jaws split it and touch both sides."""
    box = _box("box", (0.054, 0.09, 0.08), 0.2)
    choice, contacts, shift, tilt = _auto_grasp(registry, box, 0.0, hand="pg70")
    assert choice.plan.gripper == "pg70"
    assert set(contacts.pads) == {"left", "right"}
    assert tilt < 5.0 and shift < 0.01


def test_an_object_no_hand_can_hold_is_refused_in_one_line(tmp_path, capsys):
    mesh = trimesh.creation.box((0.26, 0.26, 0.08))
    mesh.apply_translation((0.0, 0.0, 0.04))
    mesh.export(tmp_path / "crate.obj")
    out = tmp_path / "out"
    code = main(["trial", "--mesh", str(tmp_path / "crate.obj"), "--gripper", "auto",
                 "--set", "trial.pictures=false", "--out", str(out)])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 3
    assert len(err.strip().splitlines()) == 1
    assert err.startswith("symfuse: error: no hand can grasp the object, ")
    # The measured size (a 260 mm square seen once, 80 mm tall) and each hand's limit.
    width_mm = int(err.split("no hand can grasp the object, ")[1].split(" mm wide")[0])
    height_mm = int(err.split("narrowest and ")[1].split(" mm tall")[0])
    assert 240 <= width_mm <= 275 and 70 <= height_mm <= 85
    # Each hand's own reason first, its opening after it.
    assert re.search(r": pg70: .+ \(pg70 opens 65 mm\); sdh: .+ \(sdh opens 220 mm\)$", err)
    document = json.loads((out / "result.json").read_text())
    assert document["status"] == "failed"
    assert {a["gripper"] for a in document["hand"]["answers"]} == {"pg70", "sdh"}


@pytest.mark.parametrize("yaw_deg", [0.0, 80.0])
def test_the_sdh_holds_a_jar_too_narrow_for_fingers_facing_the_thumb(registry, yaw_deg):
    """68 mm across, 97 mm tall: narrower than fingers 1 and 2 facing the thumb need for
    both their pads (86 mm). The planner may turn them to face each other and pinch it, with
    the thumb, which nothing opposes then, resting at the surface without pushing; all three
    pads touch and the jar stays put."""
    jar = _cylinder("jar", 0.068, 0.097, 0.4)
    _, contacts, shift, tilt = _auto_grasp(registry, jar, yaw_deg, hand="sdh")
    assert {"f1_distal", "f2_distal", "thumb_distal"} <= set(contacts.pads)
    assert opposing_contacts(contacts)
    assert tilt < 5.0 and shift < 0.005


class _AaaPinch(GraspPlanner):
    """A planner for the PG-70 whose name sorts before the built-in ones, scored low."""

    name = "aaa-pinch"
    grippers = ("pg70",)

    def plan(self, cloud, proposal, gripper):
        return GraspPlan(gripper.name, "ok", np.eye(4), 0.1, 0.06, np.array([1.0, 0, 0]),
                         score=0.01)  # fmt: skip


def _choice(registry, *overrides):
    problem, plane = estimation_problem()
    config = load_config(registry, overrides=list(overrides))
    proposal = SymmetryInit(plane, Bias())
    return choose_grasp(config, registry, problem.cloud, proposal, GRIPPERS, 0.0)


def test_a_named_hand_is_planned_by_planner_use_whatever_else_is_installed():
    registry = registry_with(_AaaPinch)
    assert _choice(registry, "trial.gripper=pg70").answer.planner == "top-parallel"
    chosen = _choice(registry, "trial.gripper=pg70", "planner.use=aaa-pinch").answer
    assert (chosen.planner, chosen.plan.score) == ("aaa-pinch", 0.01)


def test_a_named_hand_planner_use_does_not_plan_for_goes_to_the_best_planner_that_does():
    registry = registry_with(_AaaPinch)
    choice = _choice(registry, "trial.gripper=sdh")  # planner.use stays top-parallel
    assert (choice.answer.gripper, choice.answer.planner) == ("sdh", "top-three-finger")
    assert [a.gripper for a in choice.answers] == ["sdh"]


def test_a_chosen_planner_that_would_not_plan_is_refused_in_one_line():
    registry = registry_with(_AaaPinch)
    for overrides, message in [
        (["planner.use=aaa-pinch"], "is not read with trial.gripper = 'auto'"),
        (["planner.use=aaa-pinch", "trial.gripper=sdh"], "does not plan for the hand 'sdh'"),
    ]:
        config = load_config(registry, overrides=overrides)
        with pytest.raises(ConfigError, match=message):
            check_planner_is_read(config, registry, {"planner.use": "--set"})
    check_planner_is_read(load_config(registry, overrides=["trial.gripper=sdh"]), registry, {})
    config = load_config(registry, overrides=["planner.use=aaa-pinch", "trial.gripper=pg70"])
    check_planner_is_read(config, registry, {"planner.use": "--set"})
