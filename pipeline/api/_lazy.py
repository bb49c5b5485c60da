"""Names a module offers but loads on first use (PEP 562): the theme modules of
:mod:`pipeline.api` re-export kernels this way, so that importing one costs nothing until a
name is taken from it."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from importlib import import_module
from typing import Any


def lazy_attributes(
    module_name: str, namespace: dict[str, Any], sources: Mapping[str, tuple[str, str]]
) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``module_name`` whose names come from ``sources`` (name
    -> (module, name there)): each is imported on first access and kept in ``namespace``
    (the module's globals), so it is looked up once."""

    def __getattr__(name: str) -> Any:
        try:
            module, original = sources[name]
        except KeyError:
            raise AttributeError(f"module {module_name!r} has no attribute {name!r}") from None
        value = getattr(import_module(module), original)
        namespace[name] = value
        return value

    return __getattr__
