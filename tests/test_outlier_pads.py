"""A pad that touched what the mirror image cannot complete is left out of a re-fusion
(pipeline.estimation.outlier_pads), on the synthetic cylinder with real fusions."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from pipeline.estimation.consistency import ConsistencySettings
from pipeline.estimation.outlier_pads import outlier_pad
from pipeline.experiments.synthetic_study import make_estimator
from pipeline.metrics import diameter_error
from pipeline.run.runner import run_estimator
from pipeline.synthetic import Cylinder, make_case

#: How far the hidden pad's taxels stand off the cylinder, as on a handle (m).
HANDLE_M = 0.015


def _with_handle(seed: int, gripper: str = "three_finger"):
    """The pads on the cylinder (three by default), the one furthest from the camera
    moved ``HANDLE_M`` outward along its normal: it pressed on a part behind the object
    that the camera did not see. Returns the case, its problem with the moved contacts and
    the moved pad."""
    case = make_case(np.random.default_rng(seed), gripper=gripper)
    contacts, pads = case.contacts, np.asarray(case.contacts.pads)
    camera = case.T_robot_camera[:3, 3]
    hidden = max(
        np.unique(pads),
        key=lambda pad: np.linalg.norm(contacts.positions[pads == pad].mean(axis=0) - camera),
    )
    positions = contacts.positions.copy()
    on_handle = pads == hidden
    positions[on_handle] -= HANDLE_M * contacts.normals[on_handle]
    moved = dataclasses.replace(contacts, positions=positions)
    return case, dataclasses.replace(case.problem, grasps=(moved,)), str(hidden)


def test_a_pad_on_a_hidden_handle_is_left_out_and_the_others_fused():
    case, problem, hidden = _with_handle(seed=0)
    result = run_estimator(make_estimator("iekf", {}), problem)
    initial, last = result.stage(0), result.final
    # Stage 0 is right, but the handle's taxels contradict it.
    assert abs(diameter_error(initial.completed, case.cylinder.diameter_m)) < 0.004
    assert not initial.consistency.consistent
    # The plain fusion could not explain the handle either and was flagged.
    assert last.hypothesis is not None and last.hypothesis.name == f"without {hidden}"
    assert last.hypothesis.replaced
    # Fused without that pad, the model is right, and it says the handle is unexplained.
    assert abs(diameter_error(last.completed, case.cylinder.diameter_m)) < 0.004
    assert last.status == "inconsistent" and "taxels" in last.consistency.reason
    assert last.consistency.passes_free_space


def test_no_pad_is_singled_out_when_every_pad_contradicts_stage_0():
    """The three pads of a cylinder 1.4 times as large: leaving any one out still leaves
    taxels Stage 0 cannot explain."""
    case = make_case(np.random.default_rng(3), gripper="three_finger")
    big = make_case(
        np.random.default_rng(3),
        gripper="three_finger",
        cylinder=dataclasses.replace(Cylinder(), radius_m=1.4 * Cylinder().radius_m),
    )
    result = run_estimator(
        make_estimator("iekf", {}), dataclasses.replace(case.problem, grasps=(big.contacts,))
    )
    assert all(stage.hypothesis is None for stage in result.stages)
    assert result.final.status == "inconsistent"


def test_only_a_grasp_of_three_pads_or_more_with_a_contradicted_stage_0_qualifies():
    from pipeline.estimation.map_params import fusion_problem
    from pipeline.estimation.problem import estimate_result

    settings = ConsistencySettings()
    params = make_estimator("iekf", {}).params
    window = (params.window_along_normal_m, params.window_across_normal_m)
    for gripper, handle, singled_out in (
        ("three_finger", True, True),
        ("three_finger", False, False),
        ("parallel", True, False),
    ):
        case, problem, _ = _with_handle(0, gripper)
        if not handle:
            problem = case.problem
        fusion = fusion_problem(problem, params, "iekf", window, params.facing_filter)
        initial = estimate_result(fusion, (), 0.0, problem.view, settings).stages[0]
        found = outlier_pad(fusion, initial, settings, cKDTree(fusion.points_m))
        assert (found is not None) == singled_out, (gripper, handle, found)
