"""symfuse-wide-gripper: a third hand for symfuse, the "wide" two-jaw gripper (110 mm
opening, 30 x 30 mm pads), offered by a PyBullet world and planned for by name.

Everything comes from ``pipeline.api``: the PyBullet world reads the hand from its URDF
(shipped inside this package), and the built-in ``top-parallel`` planner places any
two-jaw hand by the geometry read from it, so naming the hand is all a planner needs.
"""

# --8<-- [start:plugin]
from pathlib import Path
from typing import ClassVar

from pipeline.api import hookimpl
from pipeline.api.planning import TopParallel
from pipeline.api.sim import Pybullet

#: The hand's URDF, found wherever the package is installed (a world takes a relative
#: path from the working directory, so give it the absolute one).
URDF = str(Path(__file__).parent / "wide.urdf")


class WidePybullet(Pybullet):
    """The pybullet world with the wide gripper, next to the PG-70 and the SDH-2."""

    name = "pybullet-wide"
    extra_hands: ClassVar[dict[str, str]] = {"wide": URDF}


class WideParallel(TopParallel):
    """top-parallel for the wide gripper: with ``--gripper wide`` (or ``auto``) it plans."""

    name = "wide-parallel"
    grippers = ("wide",)


@hookimpl
def symfuse_register_stages(registry):
    registry.add(WidePybullet)
    registry.add(WideParallel)


# --8<-- [end:plugin]
