"""Fixtures shared by the command-line tests."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.io.formats import contacts_to_json, write_cloud, write_json
from pipeline.synthetic import make_case


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
