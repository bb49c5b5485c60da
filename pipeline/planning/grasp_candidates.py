"""Ranked top-grasp candidates: closing directions and heights enumerated on the completed
cloud, infeasible ones rejected, the rest scored (what a candidate is, when it is feasible
and how it is scored: :mod:`pipeline.planning.candidate`).

Parallel-jaw candidates are built by
:func:`~pipeline.planning.parallel_candidates.parallel_candidate`, SDH-2 candidates by
:func:`~pipeline.planning.sdh_candidates.sdh_candidate`; both return a
:class:`~pipeline.planning.candidate.Candidate`. This module holds what a planner does
with them: the closing angles to try, the ranked candidates as plans, and the planner
base class (:class:`CandidatePlanner`).
"""

from __future__ import annotations

import re
from abc import abstractmethod
from collections import defaultdict
from dataclasses import replace

import numpy as np

from pipeline.planning.candidate import Candidate, CandidateParams
from pipeline.stages import GraspPlanner
from pipeline.types import GraspPlan, GripperSpec, PointCloud, SymmetryInit


def closing_angles(step_deg: float) -> np.ndarray:
    """Closing angles from the plane normal (rad): 0, then outward either side in
    ``step_deg`` steps, up to 90 deg (a closing line and its reverse are one grasp)."""
    side = np.arange(step_deg, 90.0 + 1e-9, step_deg)
    angles = [0.0, *(a for pair in zip(side, -side, strict=True) for a in pair)]
    if side.size and abs(side[-1] - 90.0) < 1e-9:
        angles.pop()  # -90 deg is the same line as +90 deg
    return np.radians(angles)


#: A number in a reason's text (not part of a name such as ``f1``).
_NUMBER = re.compile(r"(?<![A-Za-z_\d.])\d+(?:\.\d+)?")


def common_reason(reasons: list[str]) -> tuple[str, int]:
    """The most common kind of reason and how many share it.

    Reasons of one kind differ only in their numbers ("82 mm wide ..." and "114 mm wide
    ..."), so they are counted together, and each number that differs among them is
    given as its range ("82-114 mm wide ..."). Ties go to the kind met first.
    """
    kinds: dict[str, list[str]] = defaultdict(list)
    for reason in reasons:
        kinds[_NUMBER.sub("#", reason)].append(reason)
    kind, members = max(kinds.items(), key=lambda item: len(item[1]))
    columns = zip(*(_NUMBER.findall(reason) for reason in members), strict=True)
    spans = []
    for column in columns:
        low, high = min(column, key=float), max(column, key=float)
        spans.append(low if float(low) == float(high) else f"{low}-{high}")
    pieces = kind.split("#")
    text = "".join(piece + span for piece, span in zip(pieces, spans, strict=False))
    return text + pieces[-1], len(members)


def plan_from_candidates(
    gripper: str, candidates: list[Candidate], pregrasp_height_m: float, aperture_m: float
) -> GraspPlan:
    """The best feasible candidate as a plan, with every candidate ranked; refused (with
    the most common reason) when none is feasible."""
    ranked = sorted(candidates, key=lambda c: (not c.summary.feasible, -c.summary.score))
    summaries = tuple(c.summary for c in ranked)
    best = ranked[0]
    if not best.summary.feasible:
        reason, count = common_reason([c.summary.reason for c in ranked])
        return GraspPlan(
            gripper=gripper,
            status="refused",
            T_robot_hand=best.T_robot_hand,
            pregrasp_height_m=pregrasp_height_m,
            opening_m=aperture_m,
            closing_direction=best.T_robot_hand[:3, 0].copy(),
            reason=f"none of {len(ranked)} grasps is feasible ({count} of them: {reason})",
            score=0.0,
            candidates=summaries,
        )
    return GraspPlan(
        gripper=gripper,
        status="ok",
        T_robot_hand=best.T_robot_hand,
        pregrasp_height_m=pregrasp_height_m,
        opening_m=best.opening_m,
        closing_direction=best.T_robot_hand[:3, 0].copy(),
        predicted_contacts=best.predicted_contacts,
        spread_rad=best.spread_rad,
        score=best.summary.score,
        candidates=summaries,
    )


def feasible_plans(
    gripper: str, candidates: list[Candidate], pregrasp_height_m: float, aperture_m: float
) -> tuple[GraspPlan, ...]:
    """Every feasible candidate as a plan of its own, best first (the choices of a next
    grasp, :mod:`pipeline.planning.next_grasp`)."""
    feasible = sorted((c for c in candidates if c.summary.feasible), key=lambda c: -c.summary.score)
    return tuple(
        plan_from_candidates(gripper, [c], pregrasp_height_m, aperture_m) for c in feasible
    )


class CandidatePlanner(GraspPlanner):
    """A planner that ranks candidates: its feasible ones are the alternatives a next grasp
    is chosen among, whatever its ``strategy``. A subclass provides ``_check_hand`` (raise
    :class:`~pipeline.errors.ConfigError` for a hand it cannot plan for) and
    ``_candidates`` (every candidate it considers on the cloud with the given parameters);
    both plan from :meth:`_ranked`."""

    @abstractmethod
    def _check_hand(self, gripper: GripperSpec) -> None: ...

    @abstractmethod
    def _candidates(
        self,
        cloud: PointCloud,
        proposal: SymmetryInit,
        gripper: GripperSpec,
        params: CandidateParams,
    ) -> list[Candidate]: ...

    def _ranked(
        self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec
    ) -> list[Candidate]:
        """The candidates with the fingertips ``table_clearance_m`` above the table; when
        none of them is feasible, those with the fingertips ``low_table_clearance_m`` above
        it instead. The clearance keeps a fingertip off a table that is not quite where the
        cloud says, and costs nothing on an object taller than the pads; on a low object it
        leaves the pads' lowest taxels above the object's sides, and the lower reach is the
        only grasp there is (docs/method.md §5).

        The lower reach measures from the table the segmenter measured
        (:attr:`PointCloud.table_height_m`) when the cloud carries it: the cloud's lowest
        point lies the segmenter's cut above it (three sigmas of the table's depth noise,
        2-5 mm), and on a lying cylinder 20 mm across those millimetres put the pads'
        lowest taxel row above the widest line or on it."""
        p = self.params
        candidates = self._candidates(cloud, proposal, gripper, p)
        if p.low_table_clearance_m >= p.table_clearance_m or any(
            c.summary.feasible for c in candidates
        ):
            return candidates
        low = replace(p, table_clearance_m=p.low_table_clearance_m)
        if cloud.table_height_m is not None:
            base_m = float(cloud.points[:, 2].min()) - cloud.table_height_m
            low = replace(low, cloud_base_above_table_m=max(base_m, 0.0))
        return self._candidates(cloud, proposal, gripper, low)

    def alternatives(
        self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec
    ) -> tuple[GraspPlan, ...]:
        self._check_hand(gripper)
        return feasible_plans(
            gripper.name,
            self._ranked(cloud, proposal, gripper),
            self.params.pregrasp_height_m,
            gripper.max_aperture_m,
        )
