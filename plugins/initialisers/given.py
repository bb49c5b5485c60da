"""Initialiser ``given``: a symmetry plane stated in the configuration."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.api import (
    Bias,
    ConfigError,
    DepthObservation,
    PointCloud,
    SymmetryInit,
    SymmetryInitialiser,
    SymmetryPlane,
    hookimpl,
    param,
)


class GivenPlane(SymmetryInitialiser):
    """A fixed plane ``{p : normal_xy . (x, y) = offset_m}`` from the configuration.

    For experiments that control the initial error (the paper's figures 8 to 10) and for
    replaying a known plane. The normal need not be unit length: it is normalised and the
    offset scaled with it, so the stated set of points is kept. The bias is zero, pivoting
    about the cloud's centroid.
    """

    name = "given"

    @dataclass(frozen=True)
    class Params:
        normal_xy: tuple[float, ...] = param(
            (1.0, 0.0), "horizontal plane normal (nx, ny), robot frame; any non-zero length"
        )
        offset_m: float = param(0.0, "plane offset: nx x + ny y = offset_m (m, robot frame)")

        def __post_init__(self) -> None:
            values = np.asarray(self.normal_xy, dtype=float)
            if values.shape != (2,) or not np.all(np.isfinite(values)):
                raise ConfigError(
                    "config key 'initialiser.given.normal_xy': expected two finite numbers "
                    f"[nx, ny], got {list(self.normal_xy)}"
                )
            if np.hypot(*values) == 0.0:
                raise ConfigError("config key 'initialiser.given.normal_xy': must not be [0, 0]")
            if not np.isfinite(self.offset_m):
                raise ConfigError("config key 'initialiser.given.offset_m': must be finite")

    def propose(self, cloud: PointCloud, observation: DepthObservation | None) -> SymmetryInit:
        plane = SymmetryPlane.from_normal(np.asarray(self.params.normal_xy), self.params.offset_m)
        return SymmetryInit(plane=plane, bias=Bias(pivot_m=cloud.points.mean(axis=0)))


@hookimpl
def symfuse_register_stages(registry):
    registry.add(GivenPlane)
