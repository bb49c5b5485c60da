"""Planner ``top-parallel``: a parallel-jaw top grasp (the PG-70's), ranked among candidates or
the paper's rule."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.api import (
    ConfigError,
    GraspPlan,
    GripperSpec,
    PointCloud,
    SymmetryInit,
    hookimpl,
    param,
)
from pipeline.api.planning import (
    Candidate,
    CandidateCloud,
    CandidateParams,
    CandidatePlanner,
    ParallelHand,
    candidate_frame,
    closing_angles,
    front_to_back,
    hand_pose,
    pad_band,
    parallel_candidate,
    parallel_top_grasp,
    plan_from_candidates,
    rotate_z,
)


class TopParallel(CandidatePlanner):
    """Parallel-jaw top grasp: the best of many closing directions and heights, or the paper's.

    With ``strategy = "candidates"`` (the default) the closing direction is tried every
    ``angle_step_deg`` from the proposed plane's normal and the pad height every
    ``height_step_m`` from the lowest the fingertips and pads may go to the highest below
    the object's top (the limits below); each candidate is kept when both jaws and the
    housing descend clear of the cloud, and ranked by its predicted pad contact on both
    sides, its alignment with the plane normal and its tipping lever
    (:mod:`pipeline.planning.candidate`). ``GraspPlan.candidates`` holds the
    ranking. The housing must pass ``descent_clearance_m`` above the object.

    With ``strategy = "paper"`` (the paper's reproductions) the closing direction is the
    proposed plane's normal rotated about z by ``tactile_angle_deg``; the hand's x axis
    points from the front jaw (the PG-70's ``"left"`` pad, camera side) to the back jaw. The
    closing line passes through the cloud's centroid projected onto the proposed plane (the
    centroid of the cloud completed by that plane; docs/method.md §5); the front pad's
    surface stands ``jaw_clearance_m`` in front of where it would first touch the visible
    surface on that line (within the pad's width and height range; a curved face at its
    fitted extreme, :func:`pipeline.planning.grasp_geometry.pad_touch`). Pads cover the
    object's upper part (top edge ``top_margin_m`` below the cloud's top) but the fingertips
    stay ``table_clearance_m`` above the table, which is taken to lie
    ``cloud_base_above_table_m`` below the cloud's lowest point (the segmentation's height
    cut), and the pads' lower edge stays above the cloud's bottom (``pad_above_cloud``; on
    short objects the pads reach above the top instead of touching unseen surface).
    The hand's shape - where the pads sit below the palm, how far the fingers reach below
    them and stay behind their surfaces, the jaws' width, the housing - is the gripper's
    :attr:`~pipeline.types.GripperSpec.geometry`, read from its URDF (docs/hands.md); any
    parallel gripper with one is planned for.
    ``predicted_contacts`` are the visible points the front pad meets first, moved onto the
    pad's plane at that touch. The plan is refused when the object's
    width along the closing direction (visible cloud and its mirror image, between the pads'
    paths) plus the jaw clearance exceeds the gripper's aperture.
    """

    name = "top-parallel"

    @dataclass(frozen=True)
    class Params(CandidateParams):
        tactile_angle_deg: float = param(
            0.0, "rotation of the closing direction from the plane normal about z (deg)"
        )
        jaw_clearance_m: float = param(
            0.01, "front pad distance before the visible surface (m)", at_least=0.0
        )
        pad_above_cloud: bool = param(
            True, "keep the pads' lower edge above the cloud's bottom (short objects)"
        )
        contact_band_m: float = param(
            0.008,
            "depth of the first-touched surface layer, about 4 sigma of depth noise (m)",
            at_least=0.0,
        )
        flat_radius_m: float = param(
            0.15,
            "a visible face curved less than this radius counts as flat: the pad touches it "
            "on the closing line, a more curved one at its extreme (m)",
            above=0.0,
        )
        touch_depth_m: float = param(
            0.001,
            "visible surface within this depth of the pad's first touch is touched (m)",
            at_least=0.0,
        )
        pregrasp_height_m: float = param(
            0.1, "start of the descent above the grasp pose (m)", at_least=0.0
        )
        back_margin_m: float = param(
            0.01,
            "candidates: extra room for the back jaw behind the mirrored back, a guess (m)",
            at_least=0.0,
        )

    grippers = ("pg70",)

    def plan(self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec) -> GraspPlan:
        p = self.params
        hand = self._check_hand(gripper)
        if p.strategy == "candidates":
            return plan_from_candidates(
                gripper.name,
                self._ranked(cloud, proposal, gripper),
                p.pregrasp_height_m,
                gripper.max_aperture_m,
            )
        points = cloud.points
        plane = proposal.plane
        normal = plane.normal
        centroid = points.mean(axis=0)
        centre = centroid - (centroid @ normal - plane.offset_m) * normal
        direction = front_to_back(
            points, rotate_z(normal, np.deg2rad(p.tactile_angle_deg)), cloud.viewpoint_m
        )
        band = pad_band(
            points,
            gripper.pads[0],
            table_height_m=float(points[:, 2].min()) - p.cloud_base_above_table_m,
            top_margin_m=p.top_margin_m,
            pad_centre_to_fingertip_m=hand.pad_centre_to_fingertip_m,
            table_clearance_m=p.table_clearance_m,
            keep_above_cloud=p.pad_above_cloud,
        )
        opening = gripper.max_aperture_m
        grasp = parallel_top_grasp(
            points,
            plane.mirror(points),
            centre,
            direction,
            band,
            opening_m=opening,
            jaw_clearance_m=p.jaw_clearance_m,
            palm_above_pad_centre_m=hand.palm_to_pad_centre_m,
            contact_band_m=p.contact_band_m,
            flat_radius_m=p.flat_radius_m,
            touch_depth_m=p.touch_depth_m,
        )
        if grasp is None:
            return GraspPlan(
                gripper=gripper.name,
                status="refused",
                T_robot_hand=hand_pose(centre, direction),
                pregrasp_height_m=p.pregrasp_height_m,
                opening_m=opening,
                closing_direction=direction,
                reason="no visible point lies between the pads' paths at the grasp height",
            )
        refused = grasp.width_m + p.jaw_clearance_m > opening
        return GraspPlan(
            gripper=gripper.name,
            status="refused" if refused else "ok",
            T_robot_hand=grasp.T_robot_hand,
            pregrasp_height_m=p.pregrasp_height_m,
            opening_m=opening,
            closing_direction=grasp.closing_direction,
            predicted_contacts=grasp.predicted_contacts,
            reason=(
                f"object is {grasp.width_m * 1000:.1f} mm wide along the closing direction; "
                f"with the {p.jaw_clearance_m * 1000:.0f} mm jaw clearance it exceeds the "
                f"{gripper.name} aperture of {opening * 1000:.1f} mm"
                if refused
                else ""
            ),
        )

    def _check_hand(self, gripper: GripperSpec) -> ParallelHand:
        """The jaws' geometry (:meth:`ParallelHand.of`).

        Raises:
            ConfigError: ``gripper`` is not a two-finger parallel gripper with a URDF.
        """
        if gripper.fingers != 2:
            raise ConfigError(
                f"planner 'top-parallel' needs a two-finger gripper, got '{gripper.name}' with "
                f"{gripper.fingers} fingers (use planner 'top-three-finger')"
            )
        return ParallelHand.of(gripper, self.name)

    def _candidates(
        self,
        cloud: PointCloud,
        proposal: SymmetryInit,
        gripper: GripperSpec,
        p: Params,
    ) -> list[Candidate]:
        points = cloud.points
        hand = ParallelHand.of(gripper, self.name)
        pad = hand.pad
        frame = candidate_frame(
            points,
            proposal.plane,
            pad,
            p,
            pad_centre_to_fingertip_m=hand.pad_centre_to_fingertip_m,
            keep_above_cloud=p.pad_above_cloud,
            contact_edge_below_centre_m=pad.rows * pad.pitch_m / 2,
            viewpoint_m=cloud.viewpoint_m,
        )
        centre = frame.completed.mean(axis=0)
        clouds = CandidateCloud(points, frame.completed)
        # Which way is front to back depends on the closing angle alone, not on the height.
        directions = [
            (
                angle,
                front_to_back(points, rotate_z(proposal.plane.normal, angle), cloud.viewpoint_m),
            )
            for angle in closing_angles(p.angle_step_deg)
        ]
        candidates = [
            parallel_candidate(
                clouds,
                centre,
                direction,
                angle,
                height,
                hand,
                frame.settings,
                jaw_clearance_m=p.jaw_clearance_m,
                back_margin_m=p.back_margin_m,
            )
            for angle, direction in directions
            for height in frame.heights_m
        ]
        return candidates


@hookimpl
def symfuse_register_stages(registry):
    registry.add(TopParallel)
