"""Symmetry beyond the paper's vertical plane: mirror planes of any orientation and rotation
axes (:class:`pipeline.types.Symmetry`).

* :mod:`.search` - the symmetries of a mesh, found by search (the ground truth of scans);
* :mod:`.truth_file` - ``symmetry.json``, the true symmetries stored beside a mesh file;
* :mod:`.scoring` - an estimated plane or axis against the true ones (angle, offset);
* :mod:`.axis_fit` - a vertical rotation axis from one view (circle fits of slices);
* :mod:`.kinds` - each kind's completion of a view and the choice of kind by evidence.
"""
