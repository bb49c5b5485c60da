"""Import-time work of scipy and trimesh that symfuse's own processes skip.

Two things scipy (1.15 and later) does when it is imported cost a new ``symfuse trial``
process about a third of its scipy import time and change nothing a command computes:

* Every function scipy marks with its array-API decorator (``xp_capabilities``, a few
  hundred of them across ``scipy.spatial``, ``special``, ``optimize``, ``ndimage``...)
  has its docstring parsed and written again at import, to append a table of the array
  libraries it supports. :func:`install` makes that decorator keep the docstring as it
  is: the function, and scipy's table of capabilities, are untouched.
* scipy's array-API namespace for numpy copies every public name of numpy, and asking
  numpy for its lazily loaded ``f2py`` and ``testing`` submodules imports them (with
  ``unittest`` and numpy's Fortran wrapper generator). While that namespace is built,
  those two names are stand-ins that import the real module on first use of one of their
  attributes; afterwards numpy gives the real modules as before.

trimesh imports networkx (whose import also scans every installed distribution for its
backends) and ``scipy.optimize`` at its own import, for graph and fitting functions a
default trial never calls (networkx alone is about 0.17 s of processor time). While trimesh
imports, those two are stand-ins too: trimesh's ``nx.<name>`` and ``optimize.<name>``
reach the real modules (imported then) whenever trimesh uses them, and a name trimesh
takes from them at import (``from scipy.optimize import leastsq``) is a callable that
imports the real module on first call. Any other importer gets the real modules.

Each acts when the module concerned is first imported, through an import hook
(:func:`install`): a process that imports no scipy or trimesh pays nothing. The
``symfuse`` console script and a sweep's fork server install it; a program that imports
``pipeline`` as a library keeps scipy and trimesh as they import themselves.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import sys
from types import ModuleType

#: scipy's module holding the array-API decorator and the docstring class it uses.
ARRAY_API_MODULE = "scipy._lib._array_api"
#: scipy's array-API namespace for numpy, which copies numpy's public names.
NUMPY_NAMESPACE_MODULE = "scipy._lib.array_api_compat.numpy"
#: numpy's lazily loaded submodules that namespace would import for nothing.
DEFERRED_NUMPY_SUBMODULES = ("f2py", "testing")
#: The modules trimesh's import gets as stand-ins (:class:`_DeferredModule`).
TRIMESH_DEFERRED = ("networkx", "scipy.optimize")


class _KeptDocstring:
    """Stands in for scipy's ``FunctionDoc`` in :data:`ARRAY_API_MODULE`: the decorator
    appends its note to a section list nobody reads and gets back the docstring as it
    was (after the signature line it strips)."""

    def __init__(self, function: object) -> None:
        self._doc = getattr(function, "__doc__", None) or ""

    def __getitem__(self, section: str) -> list[str]:
        return []

    def __str__(self) -> str:
        return "\n" + self._doc


class _DeferredSubmodule(ModuleType):
    """A module imported on first use of one of its attributes."""

    def __getattr__(self, name: str) -> object:
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(importlib.import_module(self.__name__), name)


class _DeferredName:
    """``module.name``, a callable that imports ``module`` on first call (what a stand-in
    module gives ``from module import name`` while it is in ``sys.modules``)."""

    def __init__(self, module: str, name: str) -> None:
        self._module, self._name = module, name

    def __call__(self, *args, **kwargs):
        return getattr(importlib.import_module(self._module), self._name)(*args, **kwargs)

    def __repr__(self) -> str:
        return f"<{self._module}.{self._name}, imported on first call>"


class _DeferredModule(_DeferredSubmodule):
    """The stand-in trimesh imports, in ``sys.modules`` only while trimesh imports. Then a
    trimesh module asking for a name gets a :class:`_DeferredName`; any other module, the
    real attribute (the real module replacing the stand-in in ``sys.modules``). Afterwards
    every attribute is the real module's."""

    def __getattr__(self, name: str) -> object:
        if name.startswith("__"):
            raise AttributeError(name)
        if sys.modules.get(self.__name__) is self:
            asking = sys._getframe(1).f_globals.get("__name__", "")
            if asking == "trimesh" or asking.startswith("trimesh."):
                return _DeferredName(self.__name__, name)
            del sys.modules[self.__name__]
        return super().__getattr__(name)


def _keep_docstrings(module: ModuleType) -> None:
    module.FunctionDoc = _KeptDocstring


class _TrimmingLoader(importlib.machinery.SourceFileLoader):
    """scipy's own source loader, with this module's change around executing it."""

    def exec_module(self, module: ModuleType) -> None:
        if module.__name__ == NUMPY_NAMESPACE_MODULE:
            _exec_without_numpy_tools(module, super().exec_module)
            return
        if module.__name__ == "trimesh":
            _exec_with_deferred_modules(module, super().exec_module)
            return
        super().exec_module(module)
        _keep_docstrings(module)


def _exec_without_numpy_tools(module: ModuleType, execute) -> None:
    numpy = importlib.import_module("numpy")
    stood_in = [
        name
        for name in DEFERRED_NUMPY_SUBMODULES
        if f"numpy.{name}" not in sys.modules and name not in vars(numpy)
    ]
    for name in stood_in:
        setattr(numpy, name, _DeferredSubmodule(f"numpy.{name}"))
    try:
        execute(module)
    finally:
        for name in stood_in:
            if isinstance(vars(numpy).get(name), _DeferredSubmodule):
                delattr(numpy, name)


def _exec_with_deferred_modules(module: ModuleType, execute) -> None:
    stand_ins = {
        name: _DeferredModule(name) for name in TRIMESH_DEFERRED if name not in sys.modules
    }
    sys.modules.update(stand_ins)
    try:
        execute(module)
    finally:
        for name, stand_in in stand_ins.items():
            if sys.modules.get(name) is stand_in:
                del sys.modules[name]


class _Finder:
    """A meta path finder (its base class, ``importlib.abc``, would cost a quick command
    more than this module saves it) giving the two scipy modules and trimesh
    :class:`_TrimmingLoader`; every other import, and those three if they are not plain
    source files, is left to the other finders."""

    def find_spec(self, fullname, path, target=None):
        if fullname not in (ARRAY_API_MODULE, NUMPY_NAMESPACE_MODULE, "trimesh"):
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        loader = getattr(spec, "loader", None)
        if type(loader) is not importlib.machinery.SourceFileLoader:
            return None
        spec.loader = _TrimmingLoader(loader.name, loader.path)
        return spec


def install() -> None:
    """Put the import hook first on ``sys.meta_path`` (once; a scipy already imported is
    left as it is)."""
    if not any(isinstance(finder, _Finder) for finder in sys.meta_path):
        sys.meta_path.insert(0, _Finder())
