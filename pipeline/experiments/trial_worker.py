"""What a sweep's worker loads before its first full trial, loaded once per sweep.

The local executor (:mod:`pipeline.experiments.sweep`) of an experiment whose tasks are
full simulated trials imports this module in a fork server, once, and starts each worker
as a fork of it: the workers begin with the trial's modules, the plugins, the simulator,
libigl (the evaluation's distances) and open3d (real scenes' segmentation and clouds)
loaded (about two seconds of processor time a worker would otherwise spend before its
first trial). A module a trial needs and this one does not load is imported by
the worker as usual: the list is for speed, never for correctness.
"""

from __future__ import annotations

import importlib

from pipeline import lean_imports

#: The trial's modules the server imports (after :func:`pipeline.lean_imports.install`,
#: as the ``symfuse`` command does, so that scipy loads without the work it skips).
TRIAL_MODULES = (
    "pipeline.estimation.iekf",
    "pipeline.experiments.paper_trial",
    "pipeline.run.trial",
    "pipeline.sim.grasping",
    "pipeline.sim.hand_models",
    "pipeline.sim.world",
)

lean_imports.install()
for _module in TRIAL_MODULES:
    importlib.import_module(_module)

from pipeline.experiments.common import plugin_registry  # noqa: E402  (after the hook)
from pipeline.io.open3d_loader import open3d  # noqa: E402

plugin_registry()
importlib.import_module("igl")
open3d()
