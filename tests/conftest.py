"""Fixtures shared by the command-line tests, and one BLAS thread for every test.

The tests run on a single-threaded BLAS, as a trial runs its stages
(:func:`pipeline.run.runner.one_blas_thread`): their matrices are small, and on a loaded
machine a second BLAS thread spends several times the work waiting for the first (an IEKF
test took 12 s of processor time with two threads, 4 s with one). The environment variable
reaches the commands the tests start as new processes; the limit below, this process's
BLAS should it be loaded already.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # after the BLAS thread count
import pytest
from threadpoolctl import threadpool_limits

from pipeline.cli import main
from pipeline.io.formats import contacts_to_json, write_cloud, write_json
from pipeline.synthetic import make_case

#: Kept for the whole session (a limit not used as a context manager stays in force).
_ONE_BLAS_THREAD = threadpool_limits(limits=1, user_api="blas")


@pytest.fixture(scope="session")
def recording(tmp_path_factory):
    """A synthetic cylinder (r = 40 mm) seen from one side, grasped by two pads, with a
    15 deg / 10 mm wrong initial plane; files as a robot would record them. Returns the
    folder, the case and the initial plane as ``NX,NY,D`` text."""
    folder = tmp_path_factory.mktemp("recording")
    case = make_case(np.random.default_rng(3), theta_error_rad=np.radians(15.0), r_error_m=0.010)
    write_cloud(folder / "cloud.ply", case.cloud.points)
    np.save(folder / "cloud.npy", case.cloud.points)
    write_json(folder / "contacts.json", contacts_to_json([case.contacts]))
    plane = case.init_plane
    return folder, case, ",".join(repr(float(v)) for v in (*plane.normal[:2], plane.offset_m))


@pytest.fixture
def run(capsys):
    """``run(*argv)`` -> (exit code, stdout, stderr) of ``symfuse argv``."""

    def run(*argv):
        code = main([str(a) for a in argv])
        out, err = capsys.readouterr()
        return code, out, err

    return run
