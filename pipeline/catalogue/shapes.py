"""Procedural meshes of the catalogue's object kinds, built with trimesh and shapely.

Generator kinds and their ``dimensions_m`` keys (all metres):

* ``box``: ``thickness`` (x), ``length`` (y), ``height`` (z).
* ``cylinder``: ``diameter``, ``height``.
* ``jar``: body of revolution: ``body_diameter`` and ``body_height``, a conical shoulder of
  ``shoulder_height`` up to ``neck_diameter``, then a lid of ``lid_diameter``, ``lid_height``.
* ``mug``: open cup of outer ``diameter``, ``height``, side ``wall`` and ``base`` thickness,
  with a D-shaped handle on +x (``handle_span`` out of the wall, ``handle_height`` tall,
  bar ``handle_thickness`` by ``handle_width``, centred at ``handle_center_height``).
* ``loaf``: ``width`` (x) by ``length`` (y); vertical sides up to ``side_height``, then a
  half-elliptic dome up to ``height``.
* ``car``: toy car along x (bonnet at +x): ``length``, ``width`` (over the wheels),
  ``height``, ``body_width``, ``cabin_width``, ``beltline_height``, ``ground_clearance``,
  ``wheel_diameter``, ``wheel_width``, ``wheelbase``.
* ``spray_bottle``: elliptical body (``body_depth`` along x, ``body_width`` along y,
  ``body_height``, top section scaled by ``body_taper``), a ``shoulder_height`` transition to a
  round neck (``neck_diameter``, ``neck_height``), and a trigger head (``head_back`` behind and
  ``head_front`` in front of the axis, ``head_height``, ``head_width``; a narrower nozzle
  ``nozzle_length`` by ``nozzle_height`` at the front; a lever ``trigger_thickness`` thick,
  hanging ``trigger_length`` below the head, ``trigger_gap`` in front of the neck).

Meshes made of several parts (mug, car, spray bottle) are united with trimesh's ``manifold``
boolean engine (the ``manifold3d`` package).

Every generator takes the ``dimensions_m`` of a catalogue entry and returns a watertight mesh
in metres, z up, not yet placed on the table (:func:`pipeline.catalogue.objects.place_on_table`).
trimesh and shapely are imported by the generators that use them: listing the catalogue (a
sweep planning its trials) needs the kinds, not the libraries.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import shapely.geometry
    import trimesh

#: Polygon segments of a full circle in generated round shapes.
CIRCLE_SECTIONS = 128


def _union(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    import trimesh

    try:
        import manifold3d  # noqa: F401  (trimesh's boolean engine; checked for a clear error)
    except ImportError as exc:
        raise ImportError(
            "catalogue objects made of several parts need the manifold3d package "
            "(pip install manifold3d)"
        ) from exc
    return trimesh.boolean.union(parts, engine="manifold")


def _revolve(profile_rz: list[tuple[float, float]]) -> trimesh.Trimesh:
    """Solid of revolution about z of a closed profile ``(radius, z)`` that starts and ends on
    the axis; consecutive duplicate points are dropped."""
    import trimesh

    points = [profile_rz[0]]
    for point in profile_rz[1:]:
        if point != points[-1]:
            points.append(point)
    return trimesh.creation.revolve(np.array(points), sections=CIRCLE_SECTIONS)


def _extrude_xz(polygon_xz: shapely.geometry.Polygon, width_y: float) -> trimesh.Trimesh:
    """Prism of a polygon drawn in the (x, z) plane, extruded symmetrically along y."""
    import trimesh

    prism = trimesh.creation.extrude_polygon(polygon_xz, width_y)
    # Rotate +90 deg about x: polygon (x, y) -> (x, z), extrusion +z -> -y.
    prism.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2.0, [1, 0, 0]))
    prism.apply_translation([0.0, width_y / 2.0, 0.0])
    return prism


def _loft_ellipses(sections_zab: list[tuple[float, float, float]]) -> trimesh.Trimesh:
    """Closed loft through horizontal ellipses ``(z, semi_axis_x, semi_axis_y)``, bottom to
    top, capped at both ends."""
    import trimesh

    n = CIRCLE_SECTIONS
    angles = 2.0 * np.pi * np.arange(n) / n
    rings = [
        np.column_stack([a * np.cos(angles), b * np.sin(angles), np.full(n, z)])
        for z, a, b in sections_zab
    ]
    bottom_centre = [0.0, 0.0, sections_zab[0][0]]
    top_centre = [0.0, 0.0, sections_zab[-1][0]]
    vertices = np.vstack([*rings, bottom_centre, top_centre])
    k = np.arange(n)
    k_next = (k + 1) % n
    faces = []
    for ring in range(len(rings) - 1):
        low, high = ring * n, (ring + 1) * n
        faces.append(np.column_stack([low + k, low + k_next, high + k_next]))
        faces.append(np.column_stack([low + k, high + k_next, high + k]))
    bottom, top = len(rings) * n, len(rings) * n + 1
    last = (len(rings) - 1) * n
    faces.append(np.column_stack([np.full(n, bottom), k_next, k]))
    faces.append(np.column_stack([np.full(n, top), last + k, last + k_next]))
    return trimesh.Trimesh(vertices=vertices, faces=np.vstack(faces))


def _box_xz(x0: float, x1: float, z0: float, z1: float) -> shapely.geometry.Polygon:
    import shapely.geometry

    return shapely.geometry.box(x0, z0, x1, z1)


def _ellipse_xz(centre_x: float, centre_z: float, semi_x: float, semi_z: float):
    import shapely.affinity
    import shapely.geometry

    circle = shapely.geometry.Point(centre_x, centre_z).buffer(1.0, quad_segs=32)
    return shapely.affinity.scale(circle, semi_x, semi_z, origin=(centre_x, centre_z))


# ---------------------------------------------------------------- generators (one per kind)


def _box(d: Mapping[str, float]) -> trimesh.Trimesh:
    import trimesh

    return trimesh.creation.box(extents=[d["thickness"], d["length"], d["height"]])


def _cylinder(d: Mapping[str, float]) -> trimesh.Trimesh:
    import trimesh

    return trimesh.creation.cylinder(
        radius=d["diameter"] / 2.0, height=d["height"], sections=CIRCLE_SECTIONS
    )


def _jar(d: Mapping[str, float]) -> trimesh.Trimesh:
    body_r, neck_r, lid_r = d["body_diameter"] / 2, d["neck_diameter"] / 2, d["lid_diameter"] / 2
    shoulder_z = d["body_height"]
    neck_z = shoulder_z + d["shoulder_height"]
    top_z = neck_z + d["lid_height"]
    profile = [
        (0.0, 0.0),
        (body_r, 0.0),
        (body_r, shoulder_z),
        (neck_r, neck_z),
        (lid_r, neck_z),
        (lid_r, top_z),
        (0.0, top_z),
    ]
    return _revolve(profile)


def _mug(d: Mapping[str, float]) -> trimesh.Trimesh:
    outer_r, height = d["diameter"] / 2.0, d["height"]
    inner_r = outer_r - d["wall"]
    cup = _revolve(
        [(0.0, 0.0), (outer_r, 0.0), (outer_r, height), (inner_r, height), (inner_r, d["base"]),
         (0.0, d["base"])]
    )  # fmt: skip
    # D-shaped handle: a half elliptic ring centred on the outer wall, rooted mid-wall.
    centre_z, half_height = d["handle_center_height"], d["handle_height"] / 2.0
    outer = _ellipse_xz(outer_r, centre_z, d["handle_span"], half_height)
    inner = _ellipse_xz(
        outer_r,
        centre_z,
        d["handle_span"] - d["handle_thickness"],
        half_height - d["handle_thickness"],
    )
    root_x = outer_r - d["wall"] / 2.0
    keep = _box_xz(
        root_x, outer_r + d["handle_span"], centre_z - half_height, centre_z + half_height
    )
    handle = _extrude_xz(outer.difference(inner).intersection(keep), d["handle_width"])
    return _union([cup, handle])


def _loaf(d: Mapping[str, float]) -> trimesh.Trimesh:
    import shapely.geometry

    half_w, side_h, dome_h = d["width"] / 2.0, d["side_height"], d["height"] - d["side_height"]
    dome = [(half_w * np.cos(a), side_h + dome_h * np.sin(a)) for a in np.linspace(0.0, np.pi, 33)]
    outline = shapely.geometry.Polygon([(-half_w, 0.0), (half_w, 0.0), *dome])
    return _extrude_xz(outline, d["length"])


def _car(d: Mapping[str, float]) -> trimesh.Trimesh:
    import shapely.geometry
    import trimesh

    half_l, clearance, belt = d["length"] / 2.0, d["ground_clearance"], d["beltline_height"]
    bevel = 0.25 * (belt - clearance)
    lower = shapely.geometry.Polygon(
        [(-half_l, clearance), (half_l, clearance), (half_l, belt - 1.6 * bevel),
         (half_l - 2.0 * bevel, belt), (-half_l + bevel, belt), (-half_l, belt - bevel)]
    )  # fmt: skip
    length, roof = d["length"], d["height"]
    overlap = 0.1 * (belt - clearance)  # cabin sinks into the body so the union is one solid
    cabin = shapely.geometry.Polygon(
        [(-0.30 * length, belt - overlap), (0.22 * length, belt - overlap),
         (0.06 * length, roof), (-0.20 * length, roof)]
    )  # fmt: skip
    parts = [_extrude_xz(lower, d["body_width"]), _extrude_xz(cabin, d["cabin_width"])]
    wheel_r, wheel_w = d["wheel_diameter"] / 2.0, d["wheel_width"]
    axle_y = d["width"] / 2.0 - wheel_w / 2.0
    to_y_axis = trimesh.transformations.rotation_matrix(np.pi / 2.0, [1, 0, 0])
    for x in (-d["wheelbase"] / 2.0, d["wheelbase"] / 2.0):
        for y in (-axle_y, axle_y):
            wheel = trimesh.creation.cylinder(wheel_r, wheel_w, sections=CIRCLE_SECTIONS // 2)
            wheel.apply_transform(to_y_axis)
            wheel.apply_translation([x, y, wheel_r])
            parts.append(wheel)
    return _union(parts)


def _spray_bottle(d: Mapping[str, float]) -> trimesh.Trimesh:
    import shapely.ops

    body_a, body_b, taper = d["body_depth"] / 2.0, d["body_width"] / 2.0, d["body_taper"]
    neck_r = d["neck_diameter"] / 2.0
    body_top = d["body_height"]
    shoulder_top = body_top + d["shoulder_height"]
    head_bottom = shoulder_top + d["neck_height"]
    head_top = head_bottom + d["head_height"]
    chamfer = 0.05 * min(body_a, body_b)
    sections = [(0.0, body_a - chamfer, body_b - chamfer), (chamfer, body_a, body_b)]
    sections.append((body_top, taper * body_a, taper * body_b))
    for t in np.linspace(0.0, 1.0, 9)[1:]:
        blend = (1.0 - np.cos(np.pi * t)) / 2.0  # smooth start and end of the shoulder
        z = body_top + t * d["shoulder_height"]
        a = taper * body_a + blend * (neck_r - taper * body_a)
        b = taper * body_b + blend * (neck_r - taper * body_b)
        sections.append((z, a, b))
    # the neck runs a little into the head so the union is one solid
    sections.append((head_bottom + 0.25 * d["head_height"], neck_r, neck_r))
    bottle = _loft_ellipses(sections)

    nozzle_x = d["head_front"] - d["nozzle_length"]
    lever_x = neck_r + d["trigger_gap"]
    head_outline = shapely.ops.unary_union(
        [
            _box_xz(-d["head_back"], nozzle_x, head_bottom, head_top),
            _box_xz(nozzle_x - 1e-3, d["head_front"], head_top - d["nozzle_height"], head_top),
            _box_xz(
                lever_x,
                lever_x + d["trigger_thickness"],
                head_bottom - d["trigger_length"],
                head_bottom + 1e-3,
            ),
        ]
    )
    head = _extrude_xz(head_outline, d["head_width"])
    return _union([bottle, head])


#: kind -> generator: dimensions (m) to a watertight mesh, not yet placed on the table.
GENERATORS: dict[str, Callable[[Mapping[str, float]], trimesh.Trimesh]] = {
    "box": _box,
    "cylinder": _cylinder,
    "jar": _jar,
    "mug": _mug,
    "loaf": _loaf,
    "car": _car,
    "spray_bottle": _spray_bottle,
}
