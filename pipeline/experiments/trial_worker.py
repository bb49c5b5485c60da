"""What a sweep's worker loads before its first full trial, loaded once per sweep.

The local executor (:mod:`pipeline.experiments.sweep`) of an experiment whose tasks are
full simulated trials imports this module in a fork server, once, and starts each worker
as a fork of it: the workers begin with the trial's modules, the plugins, the simulator
and open3d loaded (about two seconds of processor time a worker would otherwise spend
before its first trial). A module a trial needs and this one does not load is imported by
the worker as usual: the list is for speed, never for correctness.
"""

from __future__ import annotations

import pipeline.estimation.iekf
import pipeline.experiments.paper_trial
import pipeline.run.trial
import pipeline.sim.grasping
import pipeline.sim.hand_models
import pipeline.sim.world  # noqa: F401  (the imports are this module's purpose)
from pipeline.experiments.common import plugin_registry
from pipeline.io.open3d_loader import open3d

plugin_registry()
open3d()
