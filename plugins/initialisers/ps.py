"""Initialiser ``ps``: PCA orientation, offset and bias from a parallel grasp."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from pipeline.api import (
    Bias,
    Contacts,
    DepthObservation,
    GraspPlan,
    PointCloud,
    SymmetryInit,
    SymmetryInitialiser,
    SymmetryPlane,
    hookimpl,
    param,
)
from pipeline.api.perception import contact_bias, jaw_centre_offset, pca_plane


class PsInitialiser(SymmetryInitialiser):
    """PS (vision + proprioception): PCA plane, moved to the centre between the jaws.

    ``propose``: the PCA plane (normal = minor axis of the table-projected cloud) through the
    cloud's centroid, enough to plan a grasp closing along it. ``refine`` (docs/method.md
    §5): the bias translation is the front surface's motion along the front pad's normal
    (detected front contacts minus ``plan.predicted_contacts``; zero without a plan); the
    offset puts the plane through the centre between the two pads' contact centroids, taken
    back into the camera view's frame by the bias (``m_r = n . (centre - b_T)``). With fewer
    than two pads in contact the centre is the planned palm position; without a plan too,
    the proposed offset is kept. Orientation and bias yaw are not changed.
    """

    name = "ps"

    @dataclass(frozen=True)
    class Params:
        bias: Literal["normal", "full", "none"] = param(
            "normal",
            "initial bias translation: 'normal' = front contact motion along the pad normal, "
            "'full' = whole contact centroid difference, 'none' = zero",
        )

    def propose(self, cloud: PointCloud, observation: DepthObservation | None) -> SymmetryInit:
        return SymmetryInit(
            plane=pca_plane(cloud.points), bias=Bias(pivot_m=cloud.points.mean(axis=0))
        )

    def refine(
        self,
        proposal: SymmetryInit,
        cloud: PointCloud,
        plan: GraspPlan | None,
        contacts: Contacts,
    ) -> SymmetryInit:
        normal = proposal.plane.normal
        translation = (
            contact_bias(contacts, plan.predicted_contacts, self.params.bias)
            if plan is not None
            else np.zeros(3)
        )
        centre = jaw_centre_offset(normal, contacts)
        if centre is None and plan is not None:
            centre = float(plan.T_robot_hand[:3, 3] @ normal)
        offset = proposal.plane.offset_m if centre is None else centre - float(translation @ normal)
        return replace(
            proposal,
            plane=SymmetryPlane(proposal.plane.theta_rad, offset),
            bias=Bias(yaw_rad=0.0, translation_m=translation, pivot_m=proposal.bias.pivot_m),
        )


@hookimpl
def symfuse_register_stages(registry):
    registry.add(PsInitialiser)
