"""The quick commands import only what they use: ``symfuse --help``, ``plugins`` and
``config`` never load open3d, trimesh or matplotlib (each costs a good part of a second)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("open3d", "trimesh", "matplotlib", "plotly", "dash", "igl")


def loaded_after(code: str, modules: tuple[str, ...]) -> list[str]:
    """The ``modules`` a fresh interpreter has imported after running ``code``."""
    probe = (
        f"{code}\nimport json, sys\nprint(json.dumps([m for m in {modules!r} if m in sys.modules]))"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_importing_the_cli_loads_no_heavy_library():
    assert loaded_after("import pipeline.cli", (*HEAVY, "scipy")) == []


def test_building_the_parser_loads_no_heavy_library():
    code = "from pipeline.cli import build_parser\nbuild_parser().format_help()"
    assert loaded_after(code, (*HEAVY, "scipy")) == []


@pytest.mark.parametrize("verb", ["plugins", "config"])
def test_listing_plugins_and_config_loads_no_heavy_library(verb):
    code = (
        "import contextlib, io\nfrom pipeline.cli import main\n"
        f"with contextlib.redirect_stdout(io.StringIO()):\n    assert main([{verb!r}]) == 0"
    )
    assert loaded_after(code, (*HEAVY, "scipy")) == []


def test_the_completion_plugins_modules_load_no_scipy():
    """Perception and the simulated sensors defer scipy to the functions that use it."""
    code = (
        "import pipeline.run.completion, pipeline.perception, plugins.sensors.pybullet_kinect, "
        "plugins.initialisers.vc"
    )
    assert loaded_after(code, ("scipy", *HEAVY)) == []


def test_planning_a_sweeps_trials_loads_no_mesh_library():
    """A sweep lists its trials from the catalogue's specification: the process that
    plans them (and draws the report) never pays for trimesh, shapely or open3d."""
    code = (
        "from pipeline.experiments import EXPERIMENTS, ExperimentOptions\n"
        "assert EXPERIMENTS['table3'].tasks(ExperimentOptions())"
    )
    assert loaded_after(code, ("trimesh", "shapely", "open3d", "scipy")) == []


@pytest.mark.slow
def test_a_trial_without_pictures_loads_no_plotting_or_statistics(tmp_path):
    """A sweep's trials draw no pictures: they never pay for matplotlib or scipy.stats."""
    code = (
        "import contextlib, io\nfrom pipeline.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):"
        f"\n    assert main(['trial', '--out', {str(tmp_path / 'trial')!r}, "
        "'--set', 'trial.pictures=false']) == 0"
    )
    assert loaded_after(code, ("matplotlib", "scipy.stats", "plotly", "dash")) == []


def test_the_trial_core_imports_no_physics_engine():
    """The world is a plugin: the trial, its runner and the CLI load neither engine (the
    configured world imports its own when it loads a scene)."""
    code = "import pipeline.run.trial, pipeline.run.runner, pipeline.cli, pipeline.stages"
    assert loaded_after(code, ("pybullet", "mujoco")) == []


def test_the_grasps_picture_is_drawn_without_matplotlib(tmp_path):
    """``grasps.png`` is drawn in image space: a trial's pictures pay for no figure."""
    code = (
        "import numpy as np\nfrom pathlib import Path\n"
        "from pipeline.reports.trial_pictures import GraspMarks, grasps_picture\n"
        "rng = np.random.default_rng(0)\n"
        "box = np.array([[x, y, z] for x in (-7, 7) for y in (-2, 2) for z in (0, 1)]) / 100\n"
        "marks = [GraspMarks('a', rng.uniform(-0.05, 0.05, (10, 3)), np.repeat(['l', 'r'], 5))]\n"
        f"grasps_picture(Path({str(tmp_path / 'grasps.png')!r}), "
        "rng.uniform(-0.05, 0.05, (500, 3)), box, marks, 'title')"
    )
    assert loaded_after(code, ("matplotlib",)) == []
    assert (tmp_path / "grasps.png").stat().st_size > 0


def printed_under_the_hook(code: str) -> list[str]:
    """The words a fresh interpreter prints running ``code`` after
    :func:`pipeline.lean_imports.install`."""
    hooked = f"from pipeline import lean_imports\nlean_imports.install()\n{code}"
    done = subprocess.run(
        [sys.executable, "-c", hooked], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_the_lean_import_hook_skips_numpys_test_tools_and_scipys_docstring_notes():
    """With :mod:`pipeline.lean_imports` installed, scipy imports without numpy's
    ``f2py`` and ``testing`` and leaves its functions' docstrings as written; both numpy
    modules still import when used, and scipy's functions and capabilities table are
    there as without the hook."""
    code = (
        "import sys\nimport numpy as np, scipy.spatial, scipy.special\n"
        "from scipy._lib._array_api import xp_capabilities_table\n"
        "from scipy._lib.array_api_compat import numpy as xp\n"
        "skipped = [m for m in ('numpy.f2py', 'numpy.testing') if m not in sys.modules]\n"
        "np.testing.assert_allclose(scipy.special.logsumexp([0.0, 0.0]), np.log(2.0))\n"
        "doc = scipy.special.logsumexp.__doc__\n"
        "print(skipped == ['numpy.f2py', 'numpy.testing'], len(xp_capabilities_table) > 100,\n"
        "      'Array API Standard' in doc, doc.lstrip().startswith('Compute the log'),\n"
        "      xp.testing.assert_allclose is np.testing.assert_allclose)"
    )
    assert printed_under_the_hook(code) == ["True", "True", "False", "True", "True"]


def test_trimesh_imports_without_networkx_and_scipy_optimize_under_the_hook():
    """Under :mod:`pipeline.lean_imports`, trimesh loads neither module at its import; its
    functions that use them (a sphere fit, a vertex graph) work and get the real modules,
    as another importer does."""
    code = (
        "import sys\nimport numpy as np, trimesh\n"
        "deferred = [m for m in ('networkx', 'scipy.optimize') if m not in sys.modules]\n"
        "centre, radius, _ = trimesh.nsphere.fit_nsphere(trimesh.creation.icosphere().vertices)\n"
        "graph = trimesh.creation.box().vertex_adjacency_graph\n"
        "import networkx, scipy.optimize\n"
        "print(deferred == ['networkx', 'scipy.optimize'], abs(radius - 1.0) < 1e-9,\n"
        "      isinstance(graph, networkx.Graph), graph.number_of_nodes() == 8,\n"
        "      trimesh.bounds.optimize.minimize is scipy.optimize.minimize)"
    )
    assert printed_under_the_hook(code) == ["True"] * 5


@pytest.mark.slow
def test_a_sweeps_fork_server_imports_the_trial_under_the_hook():
    """The fork server's imports (:mod:`pipeline.experiments.trial_worker`) install the
    hook first: the trial's modules load without numpy's test tools or networkx."""
    code = "import pipeline.experiments.trial_worker"
    assert loaded_after(code, ("numpy.f2py", "numpy.testing", "networkx")) == []


@pytest.mark.slow
def test_a_default_trial_never_loads_open3d(tmp_path):
    """open3d's import is the largest of a new process (about 0.6 s): the default trial's
    clouds are written and its evaluation computed without it."""
    arguments = ["trial", "--set", "trial.pictures=false", "--out", str(tmp_path / "run")]
    code = (
        "import contextlib, io\nfrom pipeline.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert main({arguments!r}) == 0"
    )
    assert loaded_after(code, ("open3d", "igl")) == ["igl"]
