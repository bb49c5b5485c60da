"""Plugin discovery and the stage registry.

Plugins are found through the entry point group ``symfuse`` (the built-ins too) and loaded
into a pluggy plugin manager. Each plugin's :func:`~pipeline.hookspecs.symfuse_register_stages`
adds implementation classes to a :class:`StageRegistry`, which remembers where every class
came from so errors can name the plugin and its distribution.

Two pluggy behaviours are guarded against here: two entry points with one name (pluggy
would skip the second silently) and exceptions escaping a plugin unattributed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib.metadata
from collections.abc import Callable, Iterator, Mapping
from typing import Any

import pluggy

from pipeline import hookspecs
from pipeline.errors import PluginError, PluginRaised, SymfuseError
from pipeline.params import build
from pipeline.stages import CONTRACTS, STAGES, StageImplementation

ENTRY_POINT_GROUP = "symfuse"


@dataclasses.dataclass(frozen=True)
class Origin:
    """Where a plugin came from: its entry point name and the distribution declaring it."""

    plugin: str
    distribution: str
    version: str

    def __str__(self) -> str:
        return f"plugin '{self.plugin}' from distribution '{self.distribution} {self.version}'"


@dataclasses.dataclass(frozen=True)
class Registration:
    """One stage implementation class and its origin."""

    cls: type[StageImplementation]
    origin: Origin

    @property
    def stage(self) -> str:
        return self.cls.stage

    @property
    def name(self) -> str:
        return self.cls.name


class StageRegistry:
    """Stage implementations by stage and name; what ``registry.add`` in a plugin fills."""

    def __init__(self) -> None:
        self._by_stage: dict[str, dict[str, Registration]] = {stage: {} for stage in STAGES}
        self._current: Origin | None = None

    @contextlib.contextmanager
    def adding_from(self, origin: Origin) -> Iterator[StageRegistry]:
        """Attribute every ``add`` inside the block to ``origin``."""
        self._current = origin
        try:
            yield self
        finally:
            self._current = None

    def add(self, cls: type[StageImplementation]) -> None:
        """Register an implementation class (called by plugins).

        Raises:
            PluginError: ``cls`` is not a stage implementation, or its name is taken.
        """
        origin = self._current or Origin("<direct>", "<unknown>", "")
        if not (isinstance(cls, type) and issubclass(cls, StageImplementation)):
            raise PluginError(f"{origin} registered {cls!r}, which is not a stage implementation")
        stage = getattr(cls, "stage", None)
        name = getattr(cls, "name", None)
        if stage not in CONTRACTS or not issubclass(cls, CONTRACTS[stage]):
            raise PluginError(f"{origin} registered {cls.__name__} without a known stage contract")
        if not isinstance(name, str) or not name:
            raise PluginError(f"{origin} registered {cls.__name__} without a name")
        if not dataclasses.is_dataclass(cls.Params):
            raise PluginError(f"{origin}: {cls.__name__}.Params must be a dataclass")
        if name in self._by_stage[stage]:
            other = self._by_stage[stage][name].origin
            raise PluginError(f"{stage} '{name}' is registered twice: by {other} and by {origin}")
        self._by_stage[stage][name] = Registration(cls, origin)

    def names(self, stage: str) -> list[str]:
        """Sorted names of the implementations installed for ``stage``."""
        return sorted(self._by_stage[stage])

    def registrations(self) -> Iterator[Registration]:
        """Every registration, in stage order then by name."""
        for stage in STAGES:
            for name in self.names(stage):
                yield self._by_stage[stage][name]

    def get(self, stage: str, name: str) -> Registration:
        """The registration of ``name`` for ``stage``.

        Raises:
            PluginError: no such implementation; the message lists the installed ones.
        """
        if stage not in self._by_stage:
            raise PluginError(f"unknown stage '{stage}' (stages: {', '.join(STAGES)})")
        try:
            return self._by_stage[stage][name]
        except KeyError:
            available = ", ".join(self.names(stage)) or "none installed"
            raise PluginError(
                f"no {stage} named '{name}' (available: {available}; "
                "the plugin providing it may not be installed)"
            ) from None

    def create(
        self, stage: str, name: str, values: Mapping[str, Any] | None = None
    ) -> StageImplementation:
        """Instantiate an implementation with validated parameters.

        Args:
            stage: stage kind, one of :data:`pipeline.stages.STAGES`.
            name: implementation name.
            values: parameter values (TOML types); missing ones take the defaults.

        Returns:
            The instance wrapped so that exceptions escaping it name the plugin.
        """
        registration = self.get(stage, name)
        params = build(registration.cls.Params, values or {}, f"{stage}.{name}")
        instance = _attributed(registration, "__init__", registration.cls, params)
        return _AttributedStage(instance, registration)  # type: ignore[return-value]


def _attributed(registration: Registration, what: str, fn: Callable, *args, **kwargs) -> Any:
    try:
        return fn(*args, **kwargs)
    except SymfuseError:
        raise
    except Exception as exc:
        stage, name = registration.stage, registration.name
        raise PluginRaised(
            f"{stage} '{name}' ({registration.origin}) failed in {what}: {_first_line(exc)}"
        ) from exc


def _first_line(exc: BaseException) -> str:
    """``Type: first line of the message`` (error messages are one line)."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


class _AttributedStage:
    """Proxy around a stage instance whose method calls re-raise foreign exceptions as
    :class:`PluginRaised` naming the stage, implementation, plugin and distribution."""

    def __init__(self, instance: StageImplementation, registration: Registration) -> None:
        self._instance = instance
        self._registration = registration

    def __getattr__(self, attribute: str) -> Any:
        value = getattr(self._instance, attribute)
        if not callable(value) or attribute.startswith("_"):
            return value

        @functools.wraps(value)
        def call(*args: Any, **kwargs: Any) -> Any:
            return _attributed(self._registration, attribute, value, *args, **kwargs)

        return call

    def __repr__(self) -> str:
        return f"<{self._registration.stage} '{self._registration.name}'>"


class PluginManager:
    """Typed façade over pluggy: load plugins, then build the registry from them."""

    def __init__(self) -> None:
        self._pm = pluggy.PluginManager(hookspecs.PROJECT)
        self._pm.add_hookspecs(hookspecs)
        self._origins: dict[str, Origin] = {}

    def register(self, plugin: object, origin: Origin) -> None:
        """Register a plugin object (module or instance) under ``origin.plugin``."""
        if origin.plugin in self._origins:
            raise PluginError(
                f"plugin name '{origin.plugin}' is declared twice: by distribution "
                f"'{self._origins[origin.plugin].distribution}' and by '{origin.distribution}'"
            )
        try:
            self._pm.register(plugin, name=origin.plugin)
        except pluggy.PluginValidationError as exc:
            raise PluginError(f"{origin} is not a valid symfuse plugin: {exc}") from exc
        self._origins[origin.plugin] = origin

    def load_entry_points(self, group: str = ENTRY_POINT_GROUP) -> None:
        """Load every entry point of ``group``; a failing import is reported by name."""
        # ``dist.metadata`` parses the METADATA file anew: read it once per distribution.
        declared: dict[int, tuple[str, str]] = {}

        def declared_by(entry_point: importlib.metadata.EntryPoint) -> tuple[str, str]:
            dist = entry_point.dist
            if dist is None:
                return ("<unknown>", "")
            if id(dist) not in declared:
                metadata = dist.metadata
                declared[id(dist)] = (metadata["Name"], metadata["Version"])
            return declared[id(dist)]

        found = [(declared_by(ep), ep) for ep in importlib.metadata.entry_points(group=group)]
        found.sort(key=lambda item: (item[0][0], item[1].name))
        for (distribution, version), entry_point in found:
            origin = Origin(plugin=entry_point.name, distribution=distribution, version=version)
            try:
                plugin = entry_point.load()
            except Exception as exc:
                raise PluginRaised(
                    f"cannot load {origin} ({entry_point.value}): {_first_line(exc)}"
                ) from exc
            self.register(plugin, origin)
        self.check_hooks()

    def check_hooks(self) -> None:
        """Fail on any registered function marked as a hook that symfuse does not define."""
        try:
            self._pm.check_pending()
        except pluggy.PluginValidationError as exc:
            raise PluginError(f"a symfuse plugin implements an unknown hook: {exc}") from exc

    def build_registry(self) -> StageRegistry:
        """Ask every plugin to register its stages; attribute any failure to it."""
        registry = StageRegistry()
        for impl in self._pm.hook.symfuse_register_stages.get_hookimpls():
            origin = self._origins[impl.plugin_name]
            arguments = {"registry": registry}
            with registry.adding_from(origin):
                try:
                    impl.function(**{k: arguments[k] for k in impl.argnames})
                except SymfuseError:
                    raise
                except Exception as exc:
                    raise PluginRaised(
                        f"{origin} failed in symfuse_register_stages: {_first_line(exc)}"
                    ) from exc
        return registry


def load_registry() -> StageRegistry:
    """Discover the installed plugins and return the filled registry."""
    manager = PluginManager()
    manager.load_entry_points()
    return manager.build_registry()
