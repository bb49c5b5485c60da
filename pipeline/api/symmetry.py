"""Symmetry kernels the built-in initialisers are made of: the choice among a vertical mirror
plane, a rotation axis and a leaning mirror plane by the evidence of a view.

What is named here keeps its meaning across releases, as :mod:`pipeline.api` does.
Each name loads its module when it is first imported, so a plugin pays only for the
kernels it uses (``symfuse plugins`` imports every plugin and must stay quick).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.api._lazy import lazy_attributes

if TYPE_CHECKING:
    from pipeline.symmetry.kinds import choose_kind, vc_kind

#: Where each name comes from: (module, name there).
_SOURCES = {
    "choose_kind": ("pipeline.symmetry.kinds", "choose_kind"),
    "vc_kind": ("pipeline.symmetry.kinds", "vc_kind"),
}

__all__ = [
    "choose_kind",
    "vc_kind",
]


__getattr__ = lazy_attributes(__name__, globals(), _SOURCES)
