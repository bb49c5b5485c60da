"""Planner ``top-three-finger``: an SDH-2 top grasp pre-shaped to the completed cloud."""

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
    PINCH_SPREAD_RAD,
    SDH_FINGER_ANGLES_RAD,
    SDH_PARALLEL_FINGER_ANGLES_RAD,
    SDH_SPREADS,
    TOO_NARROW,
    Candidate,
    CandidateCloud,
    CandidateParams,
    CandidatePlanner,
    SdhHand,
    back_face_is_flat,
    candidate_frame,
    closing_angles,
    cylindrical_top_grasp,
    find_rim,
    front_to_back,
    lean_limit_rad,
    lean_named,
    off_leaning_wall,
    pad_band,
    plan_from_candidates,
    rim_pinches,
    rim_sites,
    rotate_z,
    sdh_candidates,
    sdh_flat_part_edge_m,
    seen_surface,
    wall_lean_rad,
)

#: Spacing of the points along an open object's fitted rim the candidates are planned with
#: (m): the cloud's own spacing at a metre.
_RIM_STEP_M = 0.002


class TopThreeFinger(CandidatePlanner):
    """Three-finger top grasp: pre-shaped and ranked on the completed cloud, or the paper's.

    With ``strategy = "candidates"`` (the default) the palm's x axis is tried every
    ``angle_step_deg`` from the proposed plane's normal (thumb on the visible side), with
    the fingers 120 deg apart (spread 60 deg) and facing the thumb (spread 0), and the
    distal pads' centre height every ``height_step_m`` between the lowest the fingertips and
    pads may go and the highest below the object's top (limits below). For each, every
    finger's proximal angle is where its distal pad, held parallel to the palm axis, meets
    the completed cloud; the palm height puts the pads at the chosen height there; the
    pre-shape is the most closed opening at which fingers, knuckles and palm descend
    ``descent_clearance_m`` clear of the cloud
    (:func:`pipeline.planning.sdh_candidates.sdh_candidates`). Candidates are ranked by
    predicted pad contact, alignment with the plane normal and tipping lever;
    ``GraspPlan.candidates`` holds the ranking.

    With ``strategy = "paper"`` (the paper's reproductions) the cloud is completed by
    mirroring it through the proposed plane; the palm descends on the vertical line through
    the completed cloud's centroid with the fingers 120 deg apart (SDH base rotation
    ``spread_deg`` = 60) and closes radially - or, with ``flat_spread`` and a flat completed
    back face at least as wide as the two fingers (:func:`back_face_is_flat`), with fingers
    1 and 2 facing the thumb (spread 0) so that their pads lie flat on the back instead of
    meeting it with their edges. The palm's x axis is the plane normal rotated about z by
    ``tactile_angle_deg``, oriented from the visible (camera) side to the back, so at
    tactile angle 0 the thumb touches the visible front and the two fingers the mirrored
    back. The distal pads cover the object's upper part (their top edge ``top_margin_m``
    below the top), the fingertips stay ``table_clearance_m`` above the table (taken
    ``cloud_base_above_table_m`` below the cloud's lowest point) and, with
    ``keep_above_cloud``, the pads' lower edge above the cloud's bottom.
    ``palm_to_pad_centre_m`` is the paper strategy's fixed palm height above the pads: the
    SDH-2's distal pad centre depth with the distal link vertical, for the proximal angles
    that touch a 60-150 mm wide object (0.20-0.22 m,
    :meth:`~pipeline.planning.sdh_geometry.FingerKinematics.distal_pad_depth_m`).
    ``predicted_contacts`` are the completed-cloud points each finger meets first (thumb,
    f1, f2). Refused when the completed cloud is wider along the closing direction than the
    hand's aperture.

    The hand's shape - finger bases, links, pads, palm - is the gripper's
    :attr:`~pipeline.types.GripperSpec.geometry`, read from its URDF
    (:meth:`pipeline.planning.sdh_candidates.SdhHand.of`), but for
    ``pad_centre_to_fingertip_m``, which places the lowest pad height: 27 mm, where the
    URDF's distal pad centre lies 26.5 mm from the fingertip (kept at the value the
    planner's heights were tuned with).
    """

    name = "top-three-finger"

    @dataclass(frozen=True)
    class Params(CandidateParams):
        tactile_angle_deg: float = param(
            0.0, "rotation of the palm x axis from the plane normal about z (deg)"
        )
        spread_deg: float = param(
            60.0,
            "SDH base rotation; 60 puts the fingers 120 deg apart",
            at_least=0.0,
            at_most=90.0,
        )
        flat_spread: bool = param(
            True, "use spread 0 (fingers facing the thumb) when the completed back is flat"
        )
        flat_radius_m: float = param(
            0.15, "a back face curved less than this radius counts as flat (m)", above=0.0
        )
        top_margin_m: float = param(
            0.015,
            "pad top edge below the object's top (m); 5 mm put the pads on lids and domed tops",
            at_least=0.0,
        )
        keep_above_cloud: bool = param(
            True,
            "raise the pads so their lower edge stays above the cloud's bottom: taxels below "
            "the segmented cloud touch surface no cloud point represents",
        )
        palm_to_pad_centre_m: float = param(
            0.21, "paper: palm origin to distal pad centre along z (m)", above=0.0
        )
        pad_centre_to_fingertip_m: float = param(
            0.027,
            "distal pad centre to fingertip along z, for the lowest pad height (m; the "
            "URDF's is 26.5 mm)",
            at_least=0.0,
        )
        contact_band_m: float = param(
            0.008,
            "depth of the first-touched surface layer, about 4 sigma of depth noise (m)",
            at_least=0.0,
        )
        pregrasp_height_m: float = param(
            0.1, "start of the descent above the grasp pose (m)", at_least=0.0
        )
        descent_clearance_m: float = param(
            0.01,
            "candidates: least gap between the descending hand and the completed cloud, "
            "whose back is only the mirror plane's guess (m)",
            at_least=0.0,
        )
        rim_sites: int = param(
            12,
            "candidates: sectors of an open object's rim a pinch across its wall is tried "
            "in, where no enveloping grasp is feasible (0: none)",
            at_least=0,
        )

    grippers = ("sdh",)

    def plan(self, cloud: PointCloud, proposal: SymmetryInit, gripper: GripperSpec) -> GraspPlan:
        p = self.params
        hand = self._check_hand(gripper)
        if p.strategy == "candidates":
            candidates = self._ranked(cloud, proposal, gripper)
            plan = plan_from_candidates(
                gripper.name, candidates, p.pregrasp_height_m, gripper.max_aperture_m
            )
            return lean_named(plan, candidates)
        points = cloud.points
        completed = np.concatenate([points, proposal.plane.mirror(points)])
        direction = front_to_back(
            points,
            rotate_z(proposal.plane.normal, np.deg2rad(p.tactile_angle_deg)),
            cloud.viewpoint_m,
        )
        band = pad_band(
            completed,
            hand.pad,
            table_height_m=float(points[:, 2].min()) - p.cloud_base_above_table_m,
            top_margin_m=p.top_margin_m,
            pad_centre_to_fingertip_m=p.pad_centre_to_fingertip_m,
            table_clearance_m=p.table_clearance_m,
            keep_above_cloud=p.keep_above_cloud,
        )
        flat = p.flat_spread and back_face_is_flat(
            completed,
            direction,
            band,
            half_span_m=hand.turning_lateral_m() + band.width_m / 2,
            band_m=p.contact_band_m,
            flat_radius_m=p.flat_radius_m,
        )
        grasp = cylindrical_top_grasp(
            completed,
            direction,
            band,
            palm_above_pad_centre_m=p.palm_to_pad_centre_m,
            contact_band_m=p.contact_band_m,
            finger_angles_rad=SDH_PARALLEL_FINGER_ANGLES_RAD if flat else SDH_FINGER_ANGLES_RAD,
            finger_offsets_m=hand.parallel_finger_offsets_m() if flat else None,
        )
        refused = grasp.width_m > gripper.max_aperture_m
        return GraspPlan(
            gripper=gripper.name,
            status="refused" if refused else "ok",
            T_robot_hand=grasp.T_robot_hand,
            pregrasp_height_m=p.pregrasp_height_m,
            opening_m=gripper.max_aperture_m,
            closing_direction=grasp.closing_direction,
            predicted_contacts=grasp.predicted_contacts,
            spread_rad=0.0 if flat else float(np.deg2rad(p.spread_deg)),
            reason=(
                f"object is {grasp.width_m * 1000:.1f} mm wide along the closing direction, "
                f"wider than the {gripper.name} aperture of "
                f"{gripper.max_aperture_m * 1000:.1f} mm"
                if refused
                else ""
            ),
        )

    def _check_hand(self, gripper: GripperSpec) -> SdhHand:
        """The hand's fingers (:meth:`SdhHand.of`).

        Raises:
            ConfigError: ``gripper`` is not a three-finger hand of the SDH-2's kind.
        """
        if gripper.fingers != 3:
            raise ConfigError(
                f"planner 'top-three-finger' needs a three-finger hand, got '{gripper.name}' "
                f"with {gripper.fingers} fingers (use planner 'top-parallel')"
            )
        return SdhHand.of(gripper, self.name)

    def _candidates(
        self,
        cloud: PointCloud,
        proposal: SymmetryInit,
        gripper: GripperSpec,
        p: Params,
    ) -> list[Candidate]:
        points = cloud.points
        hand = SdhHand.of(gripper, self.name)
        pad = hand.pad
        frame = candidate_frame(
            points,
            proposal.plane,
            pad,
            p,
            pad_centre_to_fingertip_m=p.pad_centre_to_fingertip_m,
            keep_above_cloud=p.keep_above_cloud,
            contact_edge_below_centre_m=sdh_flat_part_edge_m(pad),
            viewpoint_m=cloud.viewpoint_m,
        )
        centre = frame.completed.mean(axis=0)
        # An open object's rim stands all around its fitted circle, on the side the camera
        # did not see too: a finger descending around it must clear it there.
        rim = find_rim(points)
        completed = frame.completed
        if rim is not None:
            completed = np.concatenate([completed, rim.circle_m(_RIM_STEP_M)])
        clouds = CandidateCloud(points, completed)
        # Which way is front to back depends on the closing angle alone, not on the height.
        directions = [
            (
                angle,
                front_to_back(points, rotate_z(proposal.plane.normal, angle), cloud.viewpoint_m),
            )
            for angle in closing_angles(p.angle_step_deg)
        ]

        poses = [
            (angle, direction, height)
            for angle, direction in directions
            for height in frame.heights_m
        ]

        def candidates(spread: float, tried: list) -> list[Candidate]:
            return sdh_candidates(clouds, centre, tried, spread, hand, frame.settings)

        by_spread = {spread: candidates(spread, poses) for spread in SDH_SPREADS}
        # Where the object is too narrow across for fingers 1 and 2 facing the thumb, they
        # can pinch it from two sides instead.
        pinches = candidates(
            PINCH_SPREAD_RAD,
            [
                pose
                for pose, parallel in zip(poses, by_spread[0.0], strict=True)
                if parallel.summary.reason == TOO_NARROW
            ],
        )
        candidates = [c for group in by_spread.values() for c in group] + pinches
        sites = rim_sites(rim, p.rim_sites, cloud.viewpoint_m)
        # Where nothing was feasible on the cloud as seen, it comes again with the volume
        # under it filled (the hand choice): the wall is measured on the surface.
        surface = seen_surface(points, cloud.viewpoint_m) if sites else points
        lean = wall_lean_rad(sites, surface, hand)
        if rim is not None and lean is not None:
            # An open object's wall leaning under the rim is met by a vertical pad with its
            # edge alone, wherever the cloud's noise at the rim predicts more.
            limit = lean_limit_rad(hand.pad.pitch_m, frame.settings.touch_tolerance_m)
            candidates = off_leaning_wall(candidates, rim, lean, limit)
        if any(c.summary.feasible for c in candidates):
            return candidates
        # No hand closes around it: an open object's wall can still be pinched at the rim.
        return candidates + rim_pinches(
            sites, points, proposal.plane.normal, hand, frame.settings, surface
        )


@hookimpl
def symfuse_register_stages(registry):
    registry.add(TopThreeFinger)
