"""Estimation kernels the built-in estimators are made of: the fusion problem,
its settings, the IEKF and ICP solvers, and building a result.

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.api._lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.estimation.after_view_term import AfterViewSettings
    from pipeline.estimation.icp import IcpSettings, icp_fuse
    from pipeline.estimation.iekf import IekfSettings, fuse
    from pipeline.estimation.map_params import (
        MapParams,
        consistency_settings,
        fusion_problem,
        regrasp_noise,
    )
    from pipeline.estimation.problem import (
        checked_points,
        diagonal_covariance,
        estimate_result,
        initial_state,
    )
    from pipeline.estimation.problem import stage_estimate as stage_estimate_from_state
    from pipeline.estimation.registration import RegistrationSettings

#: Where each name comes from: (module, name there).
_SOURCES = {
    "AfterViewSettings": ("pipeline.estimation.after_view_term", "AfterViewSettings"),
    "IcpSettings": ("pipeline.estimation.icp", "IcpSettings"),
    "IekfSettings": ("pipeline.estimation.iekf", "IekfSettings"),
    "MapParams": ("pipeline.estimation.map_params", "MapParams"),
    "RegistrationSettings": ("pipeline.estimation.registration", "RegistrationSettings"),
    "checked_points": ("pipeline.estimation.problem", "checked_points"),
    "consistency_settings": ("pipeline.estimation.map_params", "consistency_settings"),
    "diagonal_covariance": ("pipeline.estimation.problem", "diagonal_covariance"),
    "estimate_result": ("pipeline.estimation.problem", "estimate_result"),
    "fuse": ("pipeline.estimation.iekf", "fuse"),
    "fusion_problem": ("pipeline.estimation.map_params", "fusion_problem"),
    "icp_fuse": ("pipeline.estimation.icp", "icp_fuse"),
    "initial_state": ("pipeline.estimation.problem", "initial_state"),
    "regrasp_noise": ("pipeline.estimation.map_params", "regrasp_noise"),
    "stage_estimate_from_state": ("pipeline.estimation.problem", "stage_estimate"),
}

__all__ = [
    "AfterViewSettings",
    "IcpSettings",
    "IekfSettings",
    "MapParams",
    "RegistrationSettings",
    "checked_points",
    "consistency_settings",
    "diagonal_covariance",
    "estimate_result",
    "fuse",
    "fusion_problem",
    "icp_fuse",
    "initial_state",
    "regrasp_noise",
    "stage_estimate_from_state",
]


__getattr__ = lazy_attributes(__name__, globals(), _SOURCES)
