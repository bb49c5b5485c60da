"""Several grasps per trial: the loop in PyBullet, `fuse` replaying it, the stop rule, the
predicted taxels and the choice of the next grasp."""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.io.formats import plan_from_json
from pipeline.planning.candidate import candidate_score
from pipeline.planning.grasp_geometry import hand_pose
from pipeline.planning.next_grasp import (
    PLANNER_FLOOR,
    SAME_PLACE_M,
    TURN_SIGMAS,
    MeasurementModel,
    NextHand,
    Uncertainty,
    choose_next_grasp,
    delivery,
    information_scores,
    new_places,
    pad_contacts,
    predicted_contacts,
    predicted_turn_rad,
    repeats,
    stop_reason,
)
from pipeline.run.trial import attempt_to_json, unfused_reason
from pipeline.sim.hands import GRIPPERS
from pipeline.types import (
    Bias,
    Contacts,
    GraspCandidate,
    GraspPlan,
    StageEstimate,
    SymmetryPlane,
)


@pytest.fixture(scope="module")
def two_grasps(tmp_path_factory):
    out = tmp_path_factory.mktemp("two-grasps")
    code = main(["trial", "--grasps", "2", "--next-grasp", "information", "--out", str(out)])
    assert code == 0
    return out


@pytest.mark.slow
def test_two_grasp_trial_records_each_grasp(two_grasps):
    document = json.loads((two_grasps / "result.json").read_text())
    grasps = document["grasps"]
    assert [g["grasp"] for g in grasps] == [1, 2]
    assert grasps[0]["chosen_by"] == {"strategy": "first"}
    assert grasps[1]["chosen_by"]["strategy"] == "information"
    assert grasps[1]["chosen_by"]["alternatives"] >= 1
    chosen_by = grasps[1]["chosen_by"]
    followed = np.abs(chosen_by["turns_deg"]) <= chosen_by["turn_limit_deg"]
    rated = np.array(chosen_by["delivery"]) * followed
    expected = np.multiply(chosen_by["scores_mm2"], rated)
    eligible = expected[rated >= PLANNER_FLOOR * rated.max()]
    assert eligible.max() > 0.0
    assert expected[chosen_by["chosen"]] == eligible.max()
    for grasp in grasps:
        assert grasp["executed"] and grasp["taxels_in_contact"] > 20
        assert grasp["pads_in_contact"] == ["left", "right"]
        assert [s["stage"] for s in grasp["stages"]] == [0, 1, 2]
        assert "deviation_m" in grasp["stages"][2]["metrics"]
        assert grasp["uncertainty"]["plane_offset_std_mm"] > 0.0
    # Fusing grasps never loses what the first taught: the second estimate is as good.
    after = [g["stages"][g["selected_stage"]]["metrics"]["deviation_m"]["median"] for g in grasps]
    assert after[1] < after[0] + 0.0005
    assert document["stop_reason"] == "grasps done: 2 of 2"
    assert document["taxels_in_contact"] == sum(g["taxels_in_contact"] for g in grasps)
    # The result's stages are the estimate after the last grasp.
    assert document["stages"][2]["plane"] == grasps[1]["stages"][2]["plane"]
    contacts = json.loads((two_grasps / "contacts.json").read_text())
    assert [len(g["taxels"]) for g in contacts["grasps"]] == [
        g["taxels_in_contact"] for g in grasps
    ]
    assert (two_grasps / "grasps.png").is_file()


@pytest.mark.slow
def test_fuse_on_a_multi_grasp_contacts_file_reproduces_the_final_estimate(two_grasps, tmp_path):
    init = json.loads((two_grasps / "result.json").read_text())["init"]
    plane = ",".join(repr(v) for v in (*init["plane"]["normal"], init["plane"]["offset"]))
    code = main(
        [
            "fuse",
            "--cloud", str(two_grasps / "cloud.ply"),
            "--contacts", str(two_grasps / "contacts.json"),
            "--config", str(two_grasps / "config.toml"),
            "--plane", plane,
            "--out", str(tmp_path / "fused"),
        ]
    )  # fmt: skip
    assert code == 0
    trial = json.loads((two_grasps / "result.json").read_text())["stages"]
    fused = json.loads((tmp_path / "fused" / "result.json").read_text())["stages"]
    assert [len({t["grasp"] for t in s["trace"]}) for s in fused[1:]] == [2, 2]
    for a, b in zip(trial, fused, strict=True):
        assert a["plane"]["normal"] == pytest.approx(b["plane"]["normal"], abs=1e-9)
        assert a["plane"]["offset"] == pytest.approx(b["plane"]["offset"], abs=1e-9)
        assert a["bias"]["translation"] == pytest.approx(b["bias"]["translation"], abs=1e-9)
        assert a["bias"]["yaw"] == pytest.approx(b["bias"]["yaw"], abs=1e-9)
        assert np.allclose(a["covariance"], b["covariance"], atol=1e-12)


@pytest.mark.slow
def test_a_trial_that_stops_early_says_so_with_the_grasp_it_stopped_on(
    tmp_path, monkeypatch, capsys
):
    import pipeline.run.trial

    def second_grasp_slipped(k, contacts, shift_m, tilt_rad):
        return "grasp 2 touched one side only (test); not fused" if k == 1 else ""

    monkeypatch.setattr(pipeline.run.trial, "unfused_reason", second_grasp_slipped)
    out = tmp_path / "early"
    code = main(["trial", "--grasps", "3", "--set", "trial.pictures=false", "--out", str(out)])
    assert code == 0
    document = json.loads((out / "result.json").read_text())
    # Released, and the third grasp planned unlike it.
    assert [g["grasp"] for g in document["grasps"]] == [1, 3]
    (unfused,) = document["unfused_grasps"]
    assert unfused["grasp"] == 2 and unfused["reason"].endswith("not fused")
    assert "unfused_grasp" not in document
    third, slipped = (
        plan_from_json(entry["plan"], "plan", out / "result.json")
        for entry in (document["grasps"][1], unfused)
    )
    assert not repeats(third, [slipped], GRIPPERS)
    printed = capsys.readouterr().out
    rows = printed[printed.index("grasp  chosen by") :].splitlines()
    assert rows[2].split()[:2] == ["1", "first"]
    assert rows[3].split()[0] == "2" and "not fused" in rows[3]
    assert rows[4].split()[0] == "3"
    assert rows[5] == "stopped: grasps done: 3 of 3 (1 not fused)"


@pytest.mark.parametrize(
    ("threshold", "grasps"), [("20", 1), pytest.param("2.0", 2, marks=pytest.mark.slow)]
)
def test_until_std_stops_once_the_model_is_known_well_enough(tmp_path, threshold, grasps):
    """On the default CD drive each new grasp narrows the plane, and with it the hidden
    side's shape, until the threshold is met; the after-view measures where each grasp left
    the drive along its broad faces, which the jaws cannot feel, so the whole hidden side's
    std shrinks too."""
    out = tmp_path / "stop"
    code = main(
        ["trial", "--grasps", "3", "--until-std", threshold, "--set", "trial.pictures=false",
         "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    document = json.loads((out / "result.json").read_text())
    assert len(document["grasps"]) == grasps
    assert document["stop_reason"].startswith("uncertainty reached: ")
    assert f"after {grasps} grasp(s)" in document["stop_reason"]
    known = [grasp["uncertainty"] for grasp in document["grasps"]]
    for before, after in itertools.pairwise(known):
        assert after["hidden_shape_std_mm"] < before["hidden_shape_std_mm"]
        assert after["hidden_side_std_mm"] < before["hidden_side_std_mm"]


@pytest.mark.slow
def test_a_first_grasp_on_one_side_only_ends_the_trial_with_its_taxels_kept(
    tmp_path, monkeypatch, capsys
):
    import pipeline.run.trial

    # The default trial's jaws press on both faces; read as one side only, nothing is fused.
    monkeypatch.setattr(pipeline.run.trial, "opposing_contacts", lambda contacts: False)
    out = tmp_path / "one-sided"
    code = main(
        ["trial", "--set", "trial.pictures=false", "--set", "trial.retries=0", "--out", str(out)]
    )
    assert code == 3
    error = capsys.readouterr().err.strip()
    assert error.startswith("symfuse: error: grasp 1 touched one side only (the object moved ")
    # ... and says what to try next: the hand the trial did not use.
    assert error.endswith("; not fused; try --gripper sdh")
    document = json.loads((out / "result.json").read_text())
    assert document["status"] == "failed" and "stages" not in document
    assert document["unfused_grasp"]["grasp"] == 1
    kept = json.loads((out / "contacts.json").read_text())["grasps"]
    assert (
        len(kept) == 1 and len(kept[0]["taxels"]) == document["unfused_grasp"]["taxels_in_contact"]
    )


@pytest.mark.slow
def test_a_first_grasp_that_misses_is_made_again_unlike_it(tmp_path, monkeypatch):
    import pipeline.run.trial
    from pipeline.metrics.evaluation import opposing_contacts
    from pipeline.planning.hand_choice import MISSED_LINE_DEG

    # The first grasp is read as one side only; the trial looks again and grasps unlike it.
    checks = iter([False])
    monkeypatch.setattr(
        pipeline.run.trial,
        "opposing_contacts",
        lambda contacts: next(checks, None) is None and opposing_contacts(contacts),
    )
    out = tmp_path / "again"
    assert main(["trial", "--set", "trial.pictures=false", "--out", str(out)]) == 0
    document = json.loads((out / "result.json").read_text())
    (missed,) = document["missed_grasps"]
    assert missed["grasp"] == 1 and "unfused_grasp" not in document
    # The PG-70 holds the drive along its thin side only: the SDH-2 grasps it instead.
    first = np.array(missed["plan"]["closing_direction"])[:2]
    second = np.array(document["plan"]["closing_direction"])[:2]
    assert (missed["plan"]["gripper"], document["plan"]["gripper"]) == ("pg70", "sdh")
    assert abs(first @ second) > math.cos(math.radians(MISSED_LINE_DEG))
    (pg70,) = [answer for answer in document["hand"]["answers"] if answer["gripper"] == "pg70"]
    assert pg70["reason"] == (
        f"every feasible grasp closes within {MISSED_LINE_DEG:g} deg of one that missed"
    )
    assert document["grasps"][0]["taxels_in_contact"] > 0


@pytest.mark.slow
def test_a_first_grasp_not_executed_is_made_again_unlike_it(tmp_path, monkeypatch):
    from pipeline.planning.hand_choice import MISSED_LINE_DEG
    from pipeline.shipped_hands import ShippedHandsWorld

    # The first grasp is reported not executed (as when the palm lands on the object):
    # nothing touched, so the trial looks again and grasps unlike it.
    execute = ShippedHandsWorld.execute_grasp
    made = []

    def first_lands(world, plan):
        outcome = execute(world, plan)
        made.append(plan)
        if len(made) == 1:
            return replace(outcome, executed=False, reason="the palm landed on the object")
        return outcome

    monkeypatch.setattr(ShippedHandsWorld, "execute_grasp", first_lands)
    out = tmp_path / "landed"
    assert main(["trial", "--set", "trial.pictures=false", "--out", str(out)]) == 0
    document = json.loads((out / "result.json").read_text())
    (missed,) = document["missed_grasps"]
    assert missed["grasp"] == 1 and not missed["executed"]
    assert missed["reason"] == "the palm landed on the object"
    first = np.array(missed["plan"]["closing_direction"])[:2]
    second = np.array(document["plan"]["closing_direction"])[:2]
    assert missed["plan"]["gripper"] != document["plan"]["gripper"] or abs(
        first @ second
    ) < math.cos(math.radians(MISSED_LINE_DEG))
    assert document["grasp"]["executed"] and document["grasps"][0]["taxels_in_contact"] > 0


def test_a_grasp_on_one_side_only_is_not_fused():
    def contacts(*pads):
        normals = {"left": [1.0, 0.0, 0.0], "right": [-1.0, 0.0, 0.0], "top": [0.0, 0.0, -1.0]}
        return Contacts(
            np.zeros((len(pads), 3)),
            np.array([normals[p] for p in pads]).reshape(-1, 3),
            list(pads),
            np.arange(len(pads)),
        )

    both, one = contacts("left", "right", "right"), contacts("left", "left")
    assert unfused_reason(0, both, 0.004, 0.0) == ""
    assert unfused_reason(0, one, 0.04, 0.0) == (
        "grasp 1 touched one side only (the object moved 40.0 mm and tilted 0.0 deg); not fused"
    )
    assert unfused_reason(1, both, 0.004, 0.0) == ""
    assert unfused_reason(1, one, 0.0432, 0.0) == (
        "grasp 2 touched one side only (the object moved 43.2 mm and tilted 0.0 deg); not fused"
    )
    assert "touched nothing" in unfused_reason(2, contacts(), 0.0, 0.0)
    assert "one side only" in unfused_reason(1, contacts("left", "top"), 0.0, 0.0)
    # The grasp the trial stopped on is recorded as planned, chosen and executed.
    executed = {"executed": True, "object_shift_mm": 43.2}
    record = attempt_to_json(1, _plan(0.0), {"strategy": "paper"}, executed, one)
    assert record["grasp"] == 2 and record["plan"]["gripper"] == "pg70"
    assert record["object_shift_mm"] == 43.2
    assert record["taxels_in_contact"] == 2 and record["pads_in_contact"] == ["left"]
    assert "taxels_in_contact" not in attempt_to_json(1, _plan(0.0), {}, executed)


def test_stop_rule():
    # The hidden side's place (bias included) is 10 mm uncertain; its shape 1.5 mm.
    known = Uncertainty(
        plane_offset_std_m=0.0008, hidden_side_std_m=0.010, hidden_shape_std_m=0.0015
    )
    assert stop_reason(known, 1, 3, None) == ""
    assert stop_reason(known, 1, 3, 0.001) == ""  # the hidden shape is not known well enough
    assert stop_reason(known, 1, 3, 0.0015).startswith("uncertainty reached: ")
    assert stop_reason(known, 3, 3, None) == "grasps done: 3 of 3"
    assert stop_reason(known, 3, 3, 0.001) == (
        "grasps done: 3 of 3, before the uncertainty reached 1 mm: hidden shape std 1.50 mm "
        "stayed above it (plane offset std 0.80 mm)"
    )
    assert stop_reason(known, 3, 3, 0.0005).endswith(
        "reached 0.5 mm: plane offset std 0.80 mm and hidden shape std 1.50 mm stayed above it"
    )
    unknown = Uncertainty(math.inf, math.inf, math.inf)
    assert stop_reason(unknown, 2, 3, 0.05) == ""
    # Grasps released unfused count against the budget, and the summary says so.
    assert stop_reason(known, 2, 3, None, unfused=1) == ""
    assert stop_reason(known, 3, 3, 0.001, unfused=1) == (
        "grasps done: 3 of 3 (1 not fused), before the uncertainty reached 1 mm: hidden shape "
        "std 1.50 mm stayed above it (plane offset std 0.80 mm)"
    )


def _box_stage(thickness=0.04, length=0.12, height=0.08, centre=(0.5, 0.0)):
    """Stage 0 of a box seen from -x: its front face and a plane through the middle."""
    y, z = np.meshgrid(np.linspace(-length / 2, length / 2, 81), np.linspace(0.0, height, 55))
    x0 = centre[0] - thickness / 2
    points = np.column_stack([np.full(y.size, x0), centre[1] + y.ravel(), z.ravel()])
    plane = SymmetryPlane(theta_rad=0.0, offset_m=centre[0])
    completed = np.vstack([points, plane.mirror(points)])
    return StageEstimate(
        stage=0,
        plane=plane,
        bias=Bias(pivot_m=points.mean(axis=0)),
        covariance=np.diag([0.05, 0.01, 0.01, 0.002, 0.03, 0.4]) ** 2,
        points=points,
        completed=completed,
        iterations=0,
        status="initial",
        seconds=0.0,
    )


def _plan(y_m, height_m=0.04, gripper="pg70"):
    position = np.array([0.5, y_m, height_m + 0.125])
    return GraspPlan(
        gripper=gripper,
        status="ok",
        T_robot_hand=hand_pose(position, np.array([1.0, 0.0, 0.0])),
        pregrasp_height_m=0.1,
        opening_m=0.065,
        closing_direction=np.array([1.0, 0.0, 0.0]),
        predicted_contacts=np.array([[0.48, y_m, height_m]]),
    )


def test_predicted_taxels_lie_on_both_faces_of_the_model():
    stage = _box_stage()
    contacts = predicted_contacts(_plan(0.0), GRIPPERS["pg70"], stage.completed)
    left, right = contacts.pads == "left", contacts.pads == "right"
    # The PG-70's pads are 6 x 14 taxels of 3.4 mm: all of them on faces this large.
    assert left.sum() == right.sum() == 84
    assert np.allclose(contacts.positions[left, 0], 0.48, atol=1e-6)
    assert np.allclose(contacts.positions[right, 0], 0.52, atol=1e-6)
    assert np.allclose(contacts.normals[left], [1.0, 0.0, 0.0])
    assert np.allclose(contacts.normals[right], [-1.0, 0.0, 0.0])
    assert np.all(np.abs(contacts.positions[:, 2] - 0.04) < 0.025)
    # Past the end of the box only part of each pad touches.
    edge = predicted_contacts(_plan(0.06), GRIPPERS["pg70"], stage.completed)
    assert 0 < len(edge) < len(contacts)


class _Planner:
    """A planner stand-in: fixed alternatives, and the first as its own plan."""

    def __init__(self, plans):
        self.plans = tuple(plans)

    def plan(self, cloud, proposal, gripper):
        return self.plans[0]

    def alternatives(self, cloud, proposal, gripper):
        return self.plans


#: The estimator's measurement model; the object turns between grasps by the default
#: re-grasp noise's yaw (0.02 rad), and moves no other way.
MODEL = MeasurementModel(
    (0.003, 0.0017), (0.001, 0.003), 0.002, True, np.diag([0.02, 0, 0, 0, 0, 0]) ** 2
)


def _rated(plan, angle_deg, contact, tipping_ratio=0.0):
    """``plan`` as a candidate planner makes it: scored, recording its one candidate."""
    score = candidate_score((contact,), math.radians(angle_deg), tipping_ratio, 0.2)
    candidate = GraspCandidate(angle_deg, 0.04, 0.0, 0.04, (contact,), tipping_ratio, score, True)
    return replace(plan, score=score, candidates=(candidate,))


def test_delivery_is_the_planners_score_without_its_alignment():
    plan = _plan(0.0)
    # Contact over the tipping factor, whatever the closing angle.
    for angle_deg in (0.0, 30.0, 90.0, -60.0):
        assert delivery(_rated(plan, angle_deg, 0.7, 0.3)) == pytest.approx(0.7 / 1.06)
    # Along the plane the planner's score is half of it.
    assert _rated(plan, 90.0, 0.7).score == pytest.approx(0.35)
    # A plan without its candidate keeps the planner's score; an unscored one counts as 1.
    assert delivery(replace(plan, score=0.3)) == 0.3
    assert delivery(plan) == 1.0


def test_predicted_turn_is_the_angle_between_jaws_and_faces():
    stage = _box_stage()
    gripper = GRIPPERS["pg70"]
    for angle_deg in (0.0, 5.0, 15.0):
        direction = np.array(
            [math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg)), 0.0]
        )
        plan = replace(
            _plan(0.0),
            T_robot_hand=hand_pose(np.array([0.5, 0.0, 0.165]), direction),
            closing_direction=direction,
        )
        # The faces are flat and vertical: the pads meet them turned back by the closing
        # angle, and press the box into line with themselves.
        turn = predicted_turn_rad(pad_contacts(plan, gripper, stage.completed))
        assert math.degrees(turn) == pytest.approx(-angle_deg, rel=0.03)
    # A cylinder held off its axis meets the jaws turned opposite ways: it is pushed
    # across, not turned, though each side alone is turned from its pad by about 20 deg.
    angle, z = np.meshgrid(np.linspace(-np.pi, np.pi, 721), np.linspace(0.0, 0.08, 41))
    radius = 0.03
    cylinder = np.column_stack(
        [0.5 + radius * np.cos(angle.ravel()), radius * np.sin(angle.ravel()), z.ravel()]
    )
    off_axis = _plan(0.01)
    touches = pad_contacts(off_axis, gripper, cylinder)
    sides = [contact.turn_rad for _, contact in touches]
    assert len(sides) == 2 and sides[0] * sides[1] < 0.0
    assert min(map(abs, sides)) > math.radians(10.0)
    assert predicted_turn_rad(touches) == 0.0
    beside = predicted_turn_rad(pad_contacts(_plan(0.3), gripper, stage.completed))
    assert beside == 0.0  # touches nothing


def test_information_leaves_out_grasps_that_turn_the_object_beyond_q():
    stage = _box_stage()
    gripper = GRIPPERS["pg70"]
    square = _plan(-0.03)
    direction = np.array([math.cos(math.radians(10.0)), math.sin(math.radians(10.0)), 0.0])
    turned = replace(
        _plan(0.03),
        T_robot_hand=hand_pose(np.array([0.5, 0.03, 0.165]), direction),
        closing_direction=direction,
    )
    yaw_std = math.radians(1.0)
    model = replace(MODEL, regrasp_noise=np.diag([yaw_std, 0.005, 0.005, 0.0005, 0, 0]) ** 2)
    choices = {}
    for label, plans in (("both", [turned, square]), ("turned only", [turned])):
        choices[label] = choose_next_grasp(
            "information",
            [NextHand(_Planner(plans), gripper)],
            stage,
            model,
            np.random.default_rng(0),
        )
    both = choices["both"]
    assert abs(both.turns_rad[0]) > TURN_SIGMAS * yaw_std >= abs(both.turns_rad[1])
    assert both.scores[0] > 0.0 and both.chosen == 1
    assert both.to_json()["turn_limit_deg"] == pytest.approx(TURN_SIGMAS)
    # Where every grasp would turn it too far, the planner's best is taken.
    assert choices["turned only"].chosen == 0


def test_information_feels_along_the_plane_where_the_place_is_unknown():
    """After a grasp across a short box the plane and the place across it are known, where
    along the plane the box sits is not: jaws closing along the plane teach that, and are
    chosen although the planner's alignment factor rates them half."""
    box = _box_stage(length=0.05)
    # The camera at an angle sees the front half of both end faces too.
    x, z = np.meshgrid(np.linspace(0.48, 0.5, 7), np.linspace(0.0, 0.08, 25))
    ends = [np.column_stack([x.ravel(), np.full(x.size, y), z.ravel()]) for y in (-0.025, 0.025)]
    points = np.vstack([box.points, *ends])
    stage = replace(
        box,
        points=points,
        completed=np.vstack([points, box.plane.mirror(points)]),
        bias=Bias(pivot_m=points.mean(axis=0)),
        covariance=np.diag([0.01, 0.001, 0.01, 0.001, 0.001, 0.01]) ** 2,
    )
    across = _rated(_plan(0.0), 0.0, 0.6)
    position = np.array([0.5, 0.0, 0.04 + 0.125])
    along = replace(
        _plan(0.0),
        T_robot_hand=hand_pose(position, np.array([0.0, 1.0, 0.0])),
        closing_direction=np.array([0.0, 1.0, 0.0]),
        predicted_contacts=np.array([[0.5, -0.025, 0.04]]),
    )
    along = _rated(along, 90.0, 0.5)
    gripper = GRIPPERS["pg70"]
    contacts = predicted_contacts(along, gripper, stage.completed)
    assert len(contacts) and np.allclose(np.abs(contacts.normals[:, 1]), 1.0)
    assert along.score < PLANNER_FLOOR * across.score <= delivery(along)
    choice = choose_next_grasp(
        "information",
        [NextHand(_Planner([across, along]), gripper)],
        stage,
        MODEL,
        np.random.default_rng(0),
    )
    assert choice.scores[1] > choice.scores[0] > 0.0
    assert choice.chosen == 1
    assert choice.to_json()["delivery"] == pytest.approx([0.6, 0.5])


def test_strategies_choose_among_the_alternatives():
    stage = _box_stage()
    far = _plan(0.0)
    # A grasp beside the box touches nothing: it teaches nothing.
    plans = [_plan(0.3), far, _plan(0.04)]
    planner = _Planner(plans)
    gripper = GRIPPERS["pg70"]
    paper = choose_next_grasp(
        "paper", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(0)
    )
    assert paper.plan is plans[0] and paper.alternatives == ()
    informed = choose_next_grasp(
        "information", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(0)
    )
    assert informed.scores[0] == 0.0
    assert informed.chosen == int(np.argmax(informed.scores)) != 0
    # The planner's score weighs the gain: a grasp it rates poorly (a pad meeting an
    # edge, a push that may tip the object) is taken only for a gain as much larger.
    best = informed.chosen
    other = 3 - best  # the other grasp that touches the box
    ratio = informed.scores[other] / informed.scores[best]
    for factor, expected in ((0.9, other), (1.1, best)):
        weighed = list(plans)
        weighed[best] = replace(plans[best], score=factor * ratio)
        weighed[other] = replace(plans[other], score=1.0)
        choice = choose_next_grasp(
            "information",
            [NextHand(_Planner(weighed), gripper)],
            stage,
            MODEL,
            np.random.default_rng(0),
        )
        assert choice.scores == informed.scores and choice.chosen == expected
        assert choice.to_json()["planner_scores"][other] == 1.0
    draws = [
        choose_next_grasp(
            "random", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(s)
        ).chosen
        for s in range(20)
    ]
    assert set(draws) == {0, 1, 2}
    again = [
        choose_next_grasp(
            "random", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(s)
        ).chosen
        for s in range(20)
    ]
    assert draws == again


def test_new_places_keeps_the_taxels_away_from_the_touched_surface():
    x = np.array([0.0, 0.004, 0.006, 0.02])
    contacts = Contacts(
        np.column_stack([x, np.zeros(4), np.zeros(4)]),
        np.tile([1.0, 0.0, 0.0], (4, 1)),
        ["left", "left", "right", "right"],
        np.arange(4),
    )
    touched = np.array([[0.0, 0.003, 0.0], [0.5, 0.5, 0.5]])
    # Distances 3.0, 5.0, 6.7 and 20.2 mm; the same place is within 5 mm.
    assert SAME_PLACE_M == 0.005
    fresh = new_places(contacts, touched)
    assert fresh.positions[:, 0].tolist() == [0.006, 0.02]
    assert fresh.pads.tolist() == ["right", "right"] and fresh.taxel_indices.tolist() == [2, 3]
    assert new_places(contacts, np.zeros((0, 3))) is contacts


def test_a_grasp_where_an_earlier_one_pressed_teaches_only_its_new_taxels():
    stage = _box_stage()
    gripper = GRIPPERS["pg70"]
    again, beside, apart = _plan(0.0), _plan(0.012), _plan(-0.03)
    plans = (again, beside, apart)
    alone = information_scores(stage, plans, {"pg70": gripper}, MODEL)
    after = information_scores(stage, plans, {"pg70": gripper}, MODEL, earlier=(again,))
    assert min(alone) > 0.0
    # The same grasp again reads only surface it read: nothing new.
    assert after[0] == 0.0
    # One that overlaps it counts the columns past it; one clear of it loses nothing.
    assert 0.0 < after[1] < alone[1]
    apart_taxels = predicted_contacts(apart, gripper, stage.completed)
    fresh = new_places(apart_taxels, predicted_contacts(again, gripper, stage.completed).positions)
    assert len(fresh) == len(apart_taxels)
    assert after[2] == pytest.approx(alone[2], rel=1e-9)
    # So the choice leaves the repeat, which the planner rates best, for new surface.
    planner = _Planner(
        [replace(again, score=1.0), replace(beside, score=0.5), replace(apart, score=0.5)]
    )
    first = choose_next_grasp(
        "information", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(0)
    )
    assert first.chosen == 0
    second = choose_next_grasp(
        "information",
        [NextHand(planner, gripper)],
        stage,
        MODEL,
        np.random.default_rng(0),
        earlier=(again,),
    )
    assert second.chosen in (1, 2) and second.scores[0] == 0.0


def test_information_chooses_among_the_grasps_the_planner_rates_near_its_best():
    stage = _box_stage()
    gripper = GRIPPERS["pg70"]
    again, beside, apart = _plan(0.0), _plan(0.012), _plan(-0.03)
    # After a grasp at the middle, one overlapping it teaches a little and one clear of it
    # a lot; rated under half the planner's best, the one clear of it is out of the choice.
    assert PLANNER_FLOOR == 0.5
    for rating, chosen in ((0.49, 0), (1.0, 1)):
        planner = _Planner([replace(beside, score=1.0), replace(apart, score=rating)])
        choice = choose_next_grasp(
            "information", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(0),
            earlier=(again,),
        )  # fmt: skip
        assert 0.0 < choice.scores[0] < choice.scores[1]
        assert choice.chosen == chosen


def test_information_takes_the_best_delivered_when_no_grasp_teaches():
    # Without a covariance nothing ranks the gains: the best delivered grasp is taken,
    # wherever the planner lists it.
    stage = replace(_box_stage(), covariance=np.full((6, 6), np.inf))
    ratings = ((0.0, 0.3), (0.02, 0.9), (-0.02, 0.6))
    plans = [replace(_plan(y), score=rating) for y, rating in ratings]
    for order in itertools.permutations(range(3)):
        planner = _Planner([plans[k] for k in order])
        choice = choose_next_grasp(
            "information", [NextHand(planner, GRIPPERS["pg70"])], stage, MODEL,
            np.random.default_rng(0),
        )  # fmt: skip
        assert choice.scores == (0.0, 0.0, 0.0)
        assert order[choice.chosen] == 1


def test_a_grasp_already_made_is_made_again_only_when_nothing_else_teaches():
    stage = _box_stage()
    gripper = GRIPPERS["pg70"]
    made = _plan(0.0)
    # Found again on the moved object: 3 mm aside, jaws swapped, 5 deg turned.
    turned = np.array([-math.cos(math.radians(5.0)), -math.sin(math.radians(5.0)), 0.0])
    again = replace(
        _plan(0.003),
        T_robot_hand=hand_pose(np.array([0.5, 0.003, 0.165]), turned),
        closing_direction=turned,
    )
    grippers = {"pg70": gripper}
    assert repeats(again, [made], grippers)
    again = replace(_plan(0.003), score=1.0)
    assert not repeats(_plan(0.0, height_m=0.03), [made], grippers)  # 10 mm lower
    assert not repeats(_plan(-0.03), [made], grippers)
    # The hand 8 mm further along the closing direction and 3.5 mm aside (the README's
    # spray bottle's second grasp): the pads close on the same places, the same grasp.
    along = replace(
        _plan(0.0035),
        T_robot_hand=hand_pose(np.array([0.508, 0.0035, 0.165]), made.closing_direction),
    )
    assert repeats(along, [made], grippers)
    assert not repeats(replace(along, T_robot_hand=hand_pose(
        np.array([0.508, 0.006, 0.165]), made.closing_direction)), [made], grippers)  # fmt: skip
    # The repeat, which the planner rates best, loses to any new grasp that teaches,
    # however the planner rates it (the floor compares the new grasps among themselves) ...
    planner = _Planner([again, replace(_plan(-0.03), score=0.2)])
    choice = choose_next_grasp(
        "information", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(0),
        earlier=(made,),
    )  # fmt: skip
    assert choice.chosen == 1 and choice.to_json()["repeats"] == [True, False]
    # ... and is made again when no other grasp teaches anything.
    planner = _Planner([again, replace(made, score=0.2)])
    choice = choose_next_grasp(
        "information", [NextHand(planner, gripper)], stage, MODEL, np.random.default_rng(0),
        earlier=(made,),
    )  # fmt: skip
    assert choice.chosen == 0 and choice.scores[1] == 0.0


def test_the_floor_stays_set_by_the_best_delivered_grasp_a_repeat_included():
    stage = _box_stage()
    gripper = GRIPPERS["pg70"]
    made = _plan(0.0)
    again = replace(_plan(0.003), score=1.0)  # the grasp made, found again: rated best
    beside, apart = _plan(0.006), _plan(-0.03)  # overlapping it: teaches less; clear: more

    def choose(apart_rating):
        plans = [again, replace(beside, score=0.55), replace(apart, score=apart_rating)]
        return choose_next_grasp(
            "information", [NextHand(_Planner(plans), gripper)], stage, MODEL,
            np.random.default_rng(0), earlier=(made,),
        )  # fmt: skip

    # Delivered at 0.45, under half the repeat's 1.0, the grasp clear of it stays out though
    # its gain times its delivery is the larger (and half the best new grasp's 0.55 would
    # let it in).
    choice = choose(0.45)
    assert choice.scores[2] * 0.45 > choice.scores[1] * 0.55 > 0.0
    assert choice.repeated == (True, False, False)
    assert choice.chosen == 1
    # Above the floor it is chosen; with no new grasp above it, the new ones are compared
    # among themselves and the repeat is still not made again.
    assert choose(0.55).chosen == 2
    alone = [again, replace(apart, score=0.3)]
    choice = choose_next_grasp(
        "information", [NextHand(_Planner(alone), gripper)], stage, MODEL,
        np.random.default_rng(0), earlier=(made,),
    )  # fmt: skip
    assert choice.chosen == 1


def test_no_strategy_chooses_a_grasp_that_was_not_fused_again():
    stage = _box_stage()
    gripper = GRIPPERS["pg70"]
    slipped = _plan(0.0)
    # The planner finds it again on the moved object (3 mm aside) and rates it best.
    plans = [replace(_plan(0.003), score=1.0), replace(_plan(0.04), score=0.3)]
    hands = [NextHand(_Planner(plans), gripper)]
    for strategy in ("paper", "random", "information"):
        for seed in range(5):
            choice = choose_next_grasp(
                strategy, hands, stage, MODEL, np.random.default_rng(seed), unfused=(slipped,)
            )
            assert choice.plan is plans[1]
    # When every grasp repeats one not fused, none is chosen.
    alone = [NextHand(_Planner(plans[:1]), gripper)]
    choice = choose_next_grasp(
        "information", alone, stage, MODEL, np.random.default_rng(0), unfused=(slipped,)
    )
    assert choice.plan.status == "refused" and "not fused" in choice.plan.reason


def test_a_grasp_not_fused_is_drawn_where_it_was_planned(monkeypatch):
    import pipeline.reports.trial_pictures
    from pipeline.run.trial import draw_grasps

    drawn = {}
    monkeypatch.setattr(
        pipeline.reports.trial_pictures,
        "grasps_picture",
        lambda *args, **kwargs: drawn.update(marks=args[3]),
    )
    first = {
        "selected_stage": 2,
        "stages": [{}, {}, {"metrics": {"deviation_m": {"median": 0.0014}}}],
        "chosen_by": {"strategy": "first"},
        "gripper": "pg70",
    }
    unfused = {
        "grasp": 2,
        "chosen_by": {"strategy": "random"},
        "gripper": "pg70",
        "executed": True,
        "pads_in_contact": [],
        "plan": {"predicted_contacts": [[0.48, 0.0, 0.04], [0.52, 0.0, 0.04]]},
    }
    contacts = predicted_contacts(_plan(0.0), GRIPPERS["pg70"], _box_stage().completed)
    draw_grasps(
        Path("grasps.png"),
        "box",
        SimpleNamespace(selected=SimpleNamespace(completed=np.zeros((1, 3)))),
        SimpleNamespace(vertices=np.zeros((1, 3))),
        SimpleNamespace(contacts=(contacts,)),
        {"grasps": [first], "unfused_grasps": [unfused]},
    )
    marks = drawn["marks"]
    assert [m.fused for m in marks] == [True, False]
    assert marks[1].label == "random (pg70), touched nothing: not fused (planned contacts)"
    assert marks[1].taxels_m.shape == (2, 3)


def test_the_next_grasp_is_chosen_among_every_hand_and_scored_with_its_own_pads():
    stage = _box_stage()
    big = GRIPPERS["pg70"]
    # A second parallel hand whose pads have half the rows: it reads less of the faces.
    pads = tuple(replace(pad, rows=pad.rows // 2) for pad in big.pads)
    small = replace(big, name="short-pads", pads=pads)
    here, apart = _plan(0.0), _plan(-0.03, gripper="short-pads")
    hands = [
        NextHand(_Planner([replace(here, score=0.6)]), big),
        NextHand(_Planner([replace(apart, score=0.8)]), small),
    ]
    grippers = {"pg70": big, "short-pads": small}
    rng = np.random.default_rng(0)
    # paper: the best-scored plan of any hand, as for the first grasp.
    assert choose_next_grasp("paper", hands, stage, MODEL, rng).plan.gripper == "short-pads"
    informed = choose_next_grasp("information", hands, stage, MODEL, rng)
    assert [p.gripper for p in informed.alternatives] == ["pg70", "short-pads"]
    assert informed.to_json()["grippers"] == ["pg70", "short-pads"]
    # Each alternative is scored with its own hand's taxels.
    assert informed.scores == pytest.approx(
        information_scores(stage, informed.alternatives, grippers, MODEL), rel=1e-12
    )
    same_place = replace(apart, gripper="pg70")
    alone = information_scores(stage, (apart, same_place), grippers, MODEL)
    assert 0.0 < alone[0] < alone[1]
    # An earlier grasp by one hand makes its place old for every hand: the short pads
    # there read nothing the PG-70's did not.
    after = information_scores(stage, (apart,), grippers, MODEL, earlier=(same_place,))
    assert after == [0.0]
    draws = {
        choose_next_grasp("random", hands, stage, MODEL, np.random.default_rng(s)).plan.gripper
        for s in range(20)
    }
    assert draws == {"pg70", "short-pads"}


def test_later_grasps_change_hands_only_in_a_world_that_can_after_an_auto_choice():
    from pipeline.config import load_config
    from pipeline.planning.hand_choice import HandChoice, PlannerAnswer, Planners
    from pipeline.registry import load_registry
    from pipeline.run.trial import next_hands
    from pipeline.testing import PARALLEL_HAND, AnalyticWorld
    from plugins.worlds.pybullet_world import Pybullet

    registry = load_registry()
    config = load_config(registry)
    answers = (
        PlannerAnswer("pg70", "top-parallel", _plan(0.0)),
        PlannerAnswer("sdh", "top-three-finger", _plan(0.0, gripper="sdh")),
    )
    planners = Planners(config, registry)
    auto = next_hands(Pybullet(), planners, HandChoice(answers[1], "", answers))
    # The first grasp's hand first, each hand with the planner that answered for it.
    assert list(auto) == ["sdh", "pg70"]
    assert [hand.planner.name for hand in auto.values()] == ["top-three-finger", "top-parallel"]
    assert auto["pg70"].gripper is GRIPPERS["pg70"]
    named = HandChoice(answers[0], "trial.gripper = 'pg70'", answers[:1])
    assert list(next_hands(Pybullet(), planners, named)) == ["pg70"]
    parallel = PlannerAnswer(PARALLEL_HAND, "top-parallel", _plan(0.0, gripper=PARALLEL_HAND))
    fixed = next_hands(AnalyticWorld(), planners, HandChoice(parallel, "", (parallel, answers[1])))
    assert list(fixed) == [PARALLEL_HAND]


@pytest.fixture(scope="module")
def spray_head_three_times(tmp_path_factory):
    """The spray bottle seen from 20 deg, three grasps: the PG-70 holds it at its head,
    where a second grasp of the PG-70 reads much the same surface again; the SDH-2 reaches
    the body. Fusing them takes the camera's view: the joint fusion is set aside for the
    earlier shape (§11)."""
    out = tmp_path_factory.mktemp("spray") / "trial"
    code = main(
        ["trial", "--object", "spray_bottle", "--init", "vc", "--yaw", "20", "--grasps", "3",
         "--set", "trial.pictures=false", "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    return out


@pytest.mark.slow
def test_a_trial_changes_hands_when_another_reaches_new_surface(spray_head_three_times):
    grasps = json.loads((spray_head_three_times / "result.json").read_text())["grasps"]
    hands = [g["gripper"] for g in grasps]
    assert hands[0] == "pg70" and "sdh" in hands[1:]
    changed = grasps[hands.index("sdh")]
    assert set(changed["chosen_by"]["grippers"]) == {"pg70", "sdh"}
    assert changed["planner"] == "top-three-finger"
    assert changed["executed"] and changed["taxels_in_contact"] > 20
    assert set(changed["pads_in_contact"]) <= {"f1_distal", "f2_distal", "thumb_distal"}
    contacts = json.loads((spray_head_three_times / "contacts.json").read_text())["grasps"]
    assert [g["plan"]["gripper"] for g in contacts] == hands


@pytest.mark.slow
def test_fuse_with_the_depth_image_reproduces_an_estimate_that_needed_the_camera(
    spray_head_three_times, tmp_path
):
    document = json.loads((spray_head_three_times / "result.json").read_text())
    trial = document["stages"]
    assert any(stage.get("hypothesis") for stage in trial)
    init = document["init"]
    plane = ",".join(repr(v) for v in (*init["plane"]["normal"], init["plane"]["offset"]))
    common = [
        "fuse",
        "--cloud", str(spray_head_three_times / "cloud.ply"),
        "--contacts", str(spray_head_three_times / "contacts.json"),
        "--config", str(spray_head_three_times / "config.toml"),
        "--plane", plane,
    ]  # fmt: skip
    depth = str(spray_head_three_times / "depth.npy")
    assert main([*common, "--depth", depth, "--out", str(tmp_path / "seen")]) == 0
    seen = json.loads((tmp_path / "seen" / "result.json").read_text())
    assert seen["inputs"]["depth"] == depth
    assert seen["selected_stage"] == document["selected_stage"]
    for a, b in zip(trial, seen["stages"], strict=True):
        assert a["status"] == b["status"] and a.get("hypothesis") == b.get("hypothesis")
        assert a["plane"]["normal"] == pytest.approx(b["plane"]["normal"], abs=1e-9)
        assert a["plane"]["offset"] == pytest.approx(b["plane"]["offset"], abs=1e-9)
        assert a["bias"]["translation"] == pytest.approx(b["bias"]["translation"], abs=1e-9)
        assert np.allclose(a["covariance"], b["covariance"], atol=1e-12)
    # Without the image only the taxels are checked, and the fused model stands.
    assert main([*common, "--out", str(tmp_path / "blind")]) == 0
    blind = json.loads((tmp_path / "blind" / "result.json").read_text())["stages"]
    assert all(stage["consistency"]["checks"] == ["taxels"] for stage in blind)
    assert not any(stage.get("hypothesis") for stage in blind)


@pytest.mark.parametrize(
    ("asked", "hint"),
    [(("pg70",), "; try --gripper sdh"), (("pg70", "sdh"), "; try another --yaw")],
)
def test_a_refused_grasp_says_what_to_try_next(asked, hint):
    """The catalogue's box, 65 mm thick, refused by the PG-70 (aperture 65 mm) named by
    --gripper: the SDH-2 holds it. With every hand asked, another pose is what is left."""
    from pipeline.errors import StageFailure
    from pipeline.planning.hand_choice import HandChoice, PlannerAnswer
    from pipeline.run.trial import _take_choice

    refused = replace(_plan(0.0), status="refused", reason="none of 180 grasps is feasible")
    answers = tuple(PlannerAnswer(hand, f"planner-{hand}", refused) for hand in asked)
    choice = HandChoice(answers[0], "", answers)
    trial = SimpleNamespace(
        world=SimpleNamespace(hands=("pg70", "sdh")), record=SimpleNamespace(choice=lambda c: None)
    )
    with pytest.raises(StageFailure) as failure:
        _take_choice(trial, choice, [])
    assert str(failure.value) == (
        f"grasp planner 'planner-pg70' refused: none of 180 grasps is feasible{hint}"
    )
