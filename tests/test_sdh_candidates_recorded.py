"""The SDH-2 planner's candidates on synthetic views against a record of the planner as it
was before its candidates were evaluated together (``tests/data/sdh_candidates.json``):
every candidate's closing angle, height, spread, feasibility, reason and score, and the
chosen plan's palm pose and opening, equal bit for bit.

Run as a script (``python tests/test_sdh_candidates_recorded.py``) it writes the record
from the code it runs with: a deliberate change to the planner's results records anew.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from test_planners import SDH, _true_plane, _view

from pipeline.synthetic import box_object, cylinder_object
from plugins.planners.top_three_finger import TopThreeFinger

RECORD = Path(__file__).parent / "data/sdh_candidates.json"
#: Name -> (object, yaw in rad): a box turned off the camera's axis, and a can.
CASES = {
    "box_turned": (box_object(0.06, 0.11, 0.12), 0.5),
    "cylinder": (cylinder_object(0.035, 0.12), 0.0),
}


def _planned(case: str) -> dict:
    obj, yaw = CASES[case]
    plan = TopThreeFinger(TopThreeFinger.Params()).plan(_view(obj, yaw), _true_plane(yaw), SDH)
    return {
        "candidates": [
            [c.closing_angle_deg, c.height_m, c.spread_deg, c.feasible, c.reason, c.score]
            for c in plan.candidates
        ],
        "T_robot_hand": plan.T_robot_hand.tolist(),
        "opening_m": plan.opening_m,
        "spread_rad": plan.spread_rad,
        "contacts": len(plan.predicted_contacts),
    }


@pytest.mark.parametrize(
    "case", [pytest.param("box_turned"), pytest.param("cylinder", marks=pytest.mark.slow)]
)
def test_the_sdh_planner_finds_the_recorded_candidates(case):
    recorded = json.loads(RECORD.read_text())[case]
    planned = _planned(case)
    assert len(planned["candidates"]) == len(recorded["candidates"])
    for k, (found, expected) in enumerate(
        zip(planned["candidates"], recorded["candidates"], strict=True)
    ):
        assert found == expected, f"candidate {k}"
    assert planned == recorded


def _record() -> str:
    """The record as JSON, a candidate to a line."""
    cases = []
    for case in CASES:
        planned = _planned(case)
        rows = ",\n".join(json.dumps(row) for row in planned.pop("candidates"))
        rest = json.dumps(planned)[1:-1]
        cases.append(f'"{case}": {{{rest},\n"candidates": [\n{rows}\n]}}')
    return "{\n" + ",\n".join(cases) + "\n}\n"


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).parent))
    RECORD.write_text(_record())
