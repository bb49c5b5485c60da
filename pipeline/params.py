"""Typed plugin parameters: declaration, validation and conversion to and from TOML values.

A stage implementation declares its parameters as a frozen dataclass named ``Params``::

    @dataclass(frozen=True)
    class Params:
        min_height_m: float = param(0.02, "drop points closer than this to the table (m)")
        method: Literal["dbscan", "euclidean"] = param("dbscan", "clustering algorithm")

Supported field types: ``bool``, ``int``, ``float``, ``str``, ``Literal[...]`` of str/int,
and ``tuple[float, ...]`` / ``tuple[int, ...]`` / ``tuple[str, ...]``. An ``int`` is accepted
where a ``float`` is declared; nothing else is converted silently; a ``float`` is finite
(TOML's ``nan`` and ``inf`` are refused). Numbers may declare a bound, ``param(0.001,
"...", above=0.0)`` or ``at_least=1``, and an upper bound, strict ``below=1.0`` or inclusive
``at_most=1.0``, which :func:`build` enforces with an error naming the dotted key.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import typing
from collections.abc import Mapping
from typing import Any, Literal, get_args, get_origin

from pipeline.errors import ConfigError


def param(
    default: Any,
    doc: str,
    *,
    above: float | None = None,
    at_least: float | None = None,
    below: float | None = None,
    at_most: float | None = None,
) -> Any:
    """Declare a parameter with its default, a one-line description (with units) and,
    for numbers, an optional strict (``above``) or inclusive (``at_least``) lower bound and
    a strict (``below``) or inclusive (``at_most``) upper bound."""
    return dataclasses.field(
        default=default,
        metadata={
            "doc": doc,
            "above": above,
            "at_least": at_least,
            "below": below,
            "at_most": at_most,
        },
    )


@dataclasses.dataclass(frozen=True)
class NoParams:
    """Parameters of an implementation that has none."""


@dataclasses.dataclass(frozen=True)
class ParamInfo:
    """One declared parameter, as ``symfuse plugins --params`` and the docs show it."""

    name: str
    type_name: str
    default: Any
    doc: str


def _field_types(params_cls: type) -> dict[str, Any]:
    return typing.get_type_hints(params_cls)


def _bound(field: dataclasses.Field) -> str:
    text = ""
    if field.metadata.get("above") is not None:
        text = f" > {field.metadata['above']:g}"
    elif field.metadata.get("at_least") is not None:
        text = f" >= {field.metadata['at_least']:g}"
    if field.metadata.get("below") is not None:
        text += f"{',' if text else ''} < {field.metadata['below']:g}"
    elif field.metadata.get("at_most") is not None:
        text += f"{',' if text else ''} <= {field.metadata['at_most']:g}"
    return text


def _check_bound(field: dataclasses.Field, value: Any, key: str) -> None:
    above, at_least = field.metadata.get("above"), field.metadata.get("at_least")
    if above is not None and not value > above:
        raise ConfigError(f"config key '{key}': must be > {above:g}, got {value!r}")
    if at_least is not None and not value >= at_least:
        raise ConfigError(f"config key '{key}': must be >= {at_least:g}, got {value!r}")
    below = field.metadata.get("below")
    if below is not None and not value < below:
        raise ConfigError(f"config key '{key}': must be < {below:g}, got {value!r}")
    at_most = field.metadata.get("at_most")
    if at_most is not None and not value <= at_most:
        raise ConfigError(f"config key '{key}': must be <= {at_most:g}, got {value!r}")


def _type_name(annotation: Any) -> str:
    if get_origin(annotation) is Literal:
        return " | ".join(repr(a) for a in get_args(annotation))
    if get_origin(annotation) is tuple:
        return f"list of {get_args(annotation)[0].__name__}"
    return getattr(annotation, "__name__", str(annotation))


def describe(params_cls: type, values: Any = None) -> list[ParamInfo]:
    """List the declared parameters of a ``Params`` dataclass.

    Args:
        values: a ``Params`` instance whose values to show as the defaults (e.g. the
            shipped config's); None shows the declared defaults.
    """
    hints = _field_types(params_cls)
    return [
        ParamInfo(
            f.name,
            _type_name(hints[f.name]) + _bound(f),
            f.default if values is None else getattr(values, f.name),
            f.metadata.get("doc", ""),
        )
        for f in dataclasses.fields(params_cls)
    ]


def defaults(params_cls: type) -> dict[str, Any]:
    """The defaults of a ``Params`` dataclass as TOML-ready values."""
    return to_toml(params_cls())


def to_toml(params: Any) -> dict[str, Any]:
    """A ``Params`` instance as a dict of TOML-ready values (tuples become lists)."""
    return {
        f.name: list(value) if isinstance(value := getattr(params, f.name), tuple) else value
        for f in dataclasses.fields(params)
    }


def _convert(value: Any, annotation: Any, key: str) -> Any:
    origin = get_origin(annotation)
    if origin is Literal:
        choices = get_args(annotation)
        if value not in choices:
            allowed = ", ".join(repr(c) for c in choices)
            raise ConfigError(f"config key '{key}': {value!r} is not one of {allowed}")
        return value
    if origin is tuple:
        item_type = get_args(annotation)[0]
        if not isinstance(value, list | tuple):
            raise ConfigError(f"config key '{key}': expected a list, got {type(value).__name__}")
        return tuple(_convert(item, item_type, f"{key}[{i}]") for i, item in enumerate(value))
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"config key '{key}': expected float, got {type(value).__name__}")
        if not math.isfinite(value):  # TOML's nan and inf: no setting means either
            raise ConfigError(f"config key '{key}': expected a finite number, got {value!r}")
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config key '{key}': expected int, got {type(value).__name__}")
        return value
    if annotation in (bool, str):
        if not isinstance(value, annotation):
            raise ConfigError(
                f"config key '{key}': expected {annotation.__name__}, got {type(value).__name__}"
            )
        return value
    raise TypeError(f"unsupported parameter type {annotation!r} for '{key}'")


def build(params_cls: type, values: Mapping[str, Any], section: str) -> Any:
    """Validate ``values`` against ``params_cls`` and build an instance.

    Args:
        params_cls: the implementation's ``Params`` dataclass.
        values: TOML values for (a subset of) its fields; missing ones take the default.
        section: dotted config section the values came from, used in error messages.

    Raises:
        ConfigError: an unknown key, a value of the wrong type or out of its declared
            bound; the message names the full dotted key.
    """
    hints = _field_types(params_cls)
    known = [f.name for f in dataclasses.fields(params_cls)]
    for key in values:
        if key not in hints:
            listing = ", ".join(known) if known else "none"
            close = difflib.get_close_matches(key, known, n=1)
            guess = f"did you mean '{close[0]}'? " if close else ""
            raise ConfigError(
                f"unknown config key '{section}.{key}' ({guess}known keys: {listing})"
            )
    converted = {k: _convert(v, hints[k], f"{section}.{k}") for k, v in values.items()}
    params = params_cls(**converted)
    check_bounds(params, section)
    return params


def check_bounds(params: Any, section: str) -> None:
    """Raise :class:`ConfigError` for any field of ``params`` outside its declared bound."""
    for field in dataclasses.fields(params):
        _check_bound(field, getattr(params, field.name), f"{section}.{field.name}")


def check_ordered(params: Any, section: str, low: str, high: str, why: str = "") -> None:
    """Raise :class:`ConfigError` unless ``params.low < params.high``: two parameters that
    only make sense in that order (a range's ends, a part inside another). ``section`` is
    the implementation's config section; ``why`` (optional) ends the message."""
    low_value, high_value = getattr(params, low), getattr(params, high)
    if not low_value < high_value:
        reason = f": {why}" if why else ""
        raise ConfigError(
            f"config key '{section}.{low}' ({low_value}) must be < {high} ({high_value}){reason}"
        )


def project(target_cls: type, params: Any) -> Any:
    """An instance of the dataclass ``target_cls`` built from the same-named fields of
    ``params``: how a plugin hands the kernel's own settings type the subset it needs."""
    return target_cls(**{f.name: getattr(params, f.name) for f in dataclasses.fields(target_cls)})
