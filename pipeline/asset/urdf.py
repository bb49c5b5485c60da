"""A URDF of one rigid body: a visual mesh, convex collision parts, the inertia of a solid."""

from __future__ import annotations

from xml.etree import ElementTree

from pipeline.asset.mass import MassProperties


def urdf_text(name: str, mass: MassProperties, visual: str, collision: str) -> str:
    """The URDF of a single link named ``base_link`` in robot ``name``.

    Args:
        mass: the body's mass properties in the link frame (the frame of its meshes).
        visual: the visual mesh's file name, relative to the URDF.
        collision: the collision mesh's file name: an OBJ whose objects are convex parts
            (PyBullet makes each its own convex shape of one compound).
    """
    robot = ElementTree.Element("robot", name=name)
    link = ElementTree.SubElement(robot, "link", name="base_link")
    for kind, filename in (("visual", visual), ("collision", collision)):
        element = ElementTree.SubElement(link, kind)
        ElementTree.SubElement(element, "origin", xyz="0 0 0", rpy="0 0 0")
        geometry = ElementTree.SubElement(element, "geometry")
        ElementTree.SubElement(geometry, "mesh", filename=filename, scale="1 1 1")
    inertial = ElementTree.SubElement(link, "inertial")
    ElementTree.SubElement(
        inertial, "origin", xyz=" ".join(f"{v:.9g}" for v in mass.centre_of_mass_m), rpy="0 0 0"
    )
    ElementTree.SubElement(inertial, "mass", value=f"{mass.mass_kg:.9g}")
    tensor = mass.inertia_kg_m2
    ElementTree.SubElement(
        inertial,
        "inertia",
        **{
            f"i{'xyz'[a]}{'xyz'[b]}": f"{tensor[a, b]:.9g}"
            for a, b in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
        },
    )
    ElementTree.indent(robot)
    return ElementTree.tostring(robot, encoding="unicode") + "\n"
