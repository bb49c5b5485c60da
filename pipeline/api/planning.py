"""Grasp-planning kernels the built-in planners are made of: candidates, their
geometry and predicted pad contacts; and the built-in planners themselves
(``TopParallel``, ``TopThreeFinger``), for a planner plugin that subclasses one to plan
for a hand of its own by name (``grippers``, docs/hands.md).

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.api._lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.planning.candidate import (
        Candidate,
        CandidateCloud,
        CandidateParams,
        candidate_frame,
    )
    from pipeline.planning.grasp_candidates import (
        CandidatePlanner,
        closing_angles,
        plan_from_candidates,
    )
    from pipeline.planning.grasp_geometry import (
        SDH_FINGER_ANGLES_RAD,
        SDH_PARALLEL_FINGER_ANGLES_RAD,
        back_face_is_flat,
        cylindrical_top_grasp,
        front_to_back,
        hand_pose,
        pad_band,
        parallel_top_grasp,
        rotate_z,
    )
    from pipeline.planning.hidden_volume import seen_surface
    from pipeline.planning.next_grasp import MeasurementModel
    from pipeline.planning.pad_contact import sdh_flat_part_edge_m
    from pipeline.planning.parallel_candidates import ParallelHand, parallel_candidate
    from pipeline.planning.rim import (
        find_rim,
        lean_limit_rad,
        lean_named,
        off_leaning_wall,
        rim_pinches,
        rim_sites,
        wall_lean_rad,
    )
    from pipeline.planning.sdh_candidates import (
        PINCH_SPREAD_RAD,
        SDH_SPREADS,
        TOO_NARROW,
        SdhHand,
        sdh_candidate,
        sdh_candidates,
    )
    from pipeline.planning.sdh_geometry import FingerKinematics
    from plugins.planners.top_parallel import TopParallel
    from plugins.planners.top_three_finger import TopThreeFinger

#: Where each name comes from: (module, name there).
_SOURCES = {
    "Candidate": ("pipeline.planning.candidate", "Candidate"),
    "CandidateCloud": ("pipeline.planning.candidate", "CandidateCloud"),
    "CandidateParams": ("pipeline.planning.candidate", "CandidateParams"),
    "CandidatePlanner": ("pipeline.planning.grasp_candidates", "CandidatePlanner"),
    "MeasurementModel": ("pipeline.planning.next_grasp", "MeasurementModel"),
    "PINCH_SPREAD_RAD": ("pipeline.planning.sdh_candidates", "PINCH_SPREAD_RAD"),
    "ParallelHand": ("pipeline.planning.parallel_candidates", "ParallelHand"),
    "SDH_FINGER_ANGLES_RAD": ("pipeline.planning.grasp_geometry", "SDH_FINGER_ANGLES_RAD"),
    "SDH_PARALLEL_FINGER_ANGLES_RAD": (
        "pipeline.planning.grasp_geometry",
        "SDH_PARALLEL_FINGER_ANGLES_RAD",
    ),
    "SDH_SPREADS": ("pipeline.planning.sdh_candidates", "SDH_SPREADS"),
    "SdhHand": ("pipeline.planning.sdh_candidates", "SdhHand"),
    "FingerKinematics": ("pipeline.planning.sdh_geometry", "FingerKinematics"),
    "TOO_NARROW": ("pipeline.planning.sdh_candidates", "TOO_NARROW"),
    "TopParallel": ("plugins.planners.top_parallel", "TopParallel"),
    "TopThreeFinger": ("plugins.planners.top_three_finger", "TopThreeFinger"),
    "back_face_is_flat": ("pipeline.planning.grasp_geometry", "back_face_is_flat"),
    "candidate_frame": ("pipeline.planning.candidate", "candidate_frame"),
    "closing_angles": ("pipeline.planning.grasp_candidates", "closing_angles"),
    "cylindrical_top_grasp": ("pipeline.planning.grasp_geometry", "cylindrical_top_grasp"),
    "front_to_back": ("pipeline.planning.grasp_geometry", "front_to_back"),
    "hand_pose": ("pipeline.planning.grasp_geometry", "hand_pose"),
    "pad_band": ("pipeline.planning.grasp_geometry", "pad_band"),
    "parallel_candidate": ("pipeline.planning.parallel_candidates", "parallel_candidate"),
    "parallel_top_grasp": ("pipeline.planning.grasp_geometry", "parallel_top_grasp"),
    "plan_from_candidates": ("pipeline.planning.grasp_candidates", "plan_from_candidates"),
    "find_rim": ("pipeline.planning.rim", "find_rim"),
    "lean_limit_rad": ("pipeline.planning.rim", "lean_limit_rad"),
    "lean_named": ("pipeline.planning.rim", "lean_named"),
    "off_leaning_wall": ("pipeline.planning.rim", "off_leaning_wall"),
    "rim_pinches": ("pipeline.planning.rim", "rim_pinches"),
    "rim_sites": ("pipeline.planning.rim", "rim_sites"),
    "rotate_z": ("pipeline.planning.grasp_geometry", "rotate_z"),
    "sdh_candidate": ("pipeline.planning.sdh_candidates", "sdh_candidate"),
    "sdh_candidates": ("pipeline.planning.sdh_candidates", "sdh_candidates"),
    "sdh_flat_part_edge_m": ("pipeline.planning.pad_contact", "sdh_flat_part_edge_m"),
    "seen_surface": ("pipeline.planning.hidden_volume", "seen_surface"),
    "wall_lean_rad": ("pipeline.planning.rim", "wall_lean_rad"),
}

__all__ = [
    "PINCH_SPREAD_RAD",
    "SDH_FINGER_ANGLES_RAD",
    "SDH_PARALLEL_FINGER_ANGLES_RAD",
    "SDH_SPREADS",
    "TOO_NARROW",
    "Candidate",
    "CandidateCloud",
    "CandidateParams",
    "CandidatePlanner",
    "FingerKinematics",
    "MeasurementModel",
    "ParallelHand",
    "SdhHand",
    "TopParallel",
    "TopThreeFinger",
    "back_face_is_flat",
    "candidate_frame",
    "closing_angles",
    "cylindrical_top_grasp",
    "find_rim",
    "front_to_back",
    "hand_pose",
    "lean_limit_rad",
    "lean_named",
    "off_leaning_wall",
    "pad_band",
    "parallel_candidate",
    "parallel_top_grasp",
    "plan_from_candidates",
    "rim_pinches",
    "rim_sites",
    "rotate_z",
    "sdh_candidate",
    "sdh_candidates",
    "sdh_flat_part_edge_m",
    "seen_surface",
    "wall_lean_rad",
]


__getattr__ = lazy_attributes(__name__, globals(), _SOURCES)
