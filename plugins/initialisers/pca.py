"""Initialiser ``pca``: the naive baseline plane through the centroid along the major axis."""

from __future__ import annotations

from pipeline.api import (
    Bias,
    DepthObservation,
    PointCloud,
    SymmetryInit,
    SymmetryInitialiser,
    hookimpl,
)
from pipeline.api.perception import pca_plane


class PcaInitialiser(SymmetryInitialiser):
    """Naive baseline: plane containing the major PCA axis and z, through the centroid.

    The offset puts the plane through the centroid of the *visible* cloud. A single view
    sees the front of an object, so this centroid (and the plane) lies in front of the true
    centre by up to half the object's thickness: the baseline deliberately makes no
    correction, which is what the other initialisers are compared against. Contacts are
    ignored (``refine`` keeps the proposal).
    """

    name = "pca"

    def propose(self, cloud: PointCloud, observation: DepthObservation | None) -> SymmetryInit:
        return SymmetryInit(
            plane=pca_plane(cloud.points), bias=Bias(pivot_m=cloud.points.mean(axis=0))
        )


@hookimpl
def symfuse_register_stages(registry):
    registry.add(PcaInitialiser)
