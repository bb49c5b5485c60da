"""The hook a symfuse plugin implements.

A plugin is a module (or object) exposed under the entry point group ``symfuse``. It
implements :func:`symfuse_register_stages` and adds its stage implementation classes to the
registry it is handed. The built-in stages in ``plugins/`` are registered exactly this way.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from pipeline.registry import StageRegistry

PROJECT = "symfuse"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)
"""Decorates a plugin module's ``symfuse_register_stages`` hook implementation."""


@hookspec
def symfuse_register_stages(registry: StageRegistry) -> None:
    """Add stage implementations to the registry.

    Args:
        registry: call ``registry.add(cls)`` once per implementation class; ``cls`` derives
            from one of the contracts in :mod:`pipeline.stages` and sets ``name``.

    Called once per plugin when the plugin manager starts. Raising here is reported as an
    error naming the plugin and its distribution.
    """
