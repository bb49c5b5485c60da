"""Visuo-tactile state estimation: geometry, correspondences, the structured IEKF, its dense
reference and the ICP baseline (METHOD.md sections 1-4). Pure array code, no I/O."""

from .dense import DenseCovariance
from .iekf import FusionProblem, GraspContacts, IekfSettings, StageOutcome, fuse
from .structured import StructuredCovariance

__all__ = [
    "DenseCovariance",
    "FusionProblem",
    "GraspContacts",
    "IekfSettings",
    "StageOutcome",
    "StructuredCovariance",
    "fuse",
]
