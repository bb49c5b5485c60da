"""TOML configuration: defaults, ``--config FILE``, ``--set key=value``, validation.

Layout of a config file::

    [trial]                      # settings of `symfuse trial` (see TrialSettings)
    object = "cd_drive"

    [segmenter]                  # one section per stage (pipeline.stages.STAGES)
    use = "table-cluster"        # the implementation, by name: swap a stage here

    [segmenter.table-cluster]    # parameters of one implementation (its Params)
    min_height_m = 0.02

Files and overrides are deep-merged over the shipped ``default.toml``. Every key is checked:
an unknown section, key or implementation name, or a value of the wrong type, is a
:class:`~pipeline.errors.ConfigError` naming the dotted key. Parameters of implementations
that are not selected are validated too, so a typo never waits for the day it is used.

A config knows what the user set and where (:attr:`Config.changed`): the checks that read
"did the user choose this" (:meth:`Config.check_trial`) and the notes on settings a command
does not read ask it rather than comparing with the defaults again.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib.resources
import tomllib
from collections.abc import Collection, Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, get_args, get_type_hints

import tomli_w

from pipeline.catalogue.rest import parse_rest
from pipeline.errors import ConfigError
from pipeline.params import build, param, to_toml
from pipeline.registry import StageRegistry
from pipeline.stages import STAGES, StageImplementation


@dataclasses.dataclass(frozen=True)
class TrialSettings:
    """The ``[trial]`` section: the simulated scene of ``symfuse trial``."""

    object: str = param(
        "cd_drive", "catalogue name, or path of an OBJ/STL/PLY mesh or a URDF (metres)"
    )
    gripper: str = param(
        "auto",
        "hand, one the world offers (pybullet, mujoco: pg70, the Schunk PG-70, or sdh, the "
        "SDH-2), or auto: the hand whose planner finds the best feasible grasp on this object",
    )
    seed: int = param(0, "seed of every random choice in the trial", at_least=0)
    # The table is 2 m x 2 m about the robot origin: an object placed beyond it falls.
    x_m: float = param(
        0.0, "object position on the table, robot frame x (m)", above=-1.0, below=1.0
    )
    y_m: float = param(
        0.0, "object position on the table, robot frame y (m)", above=-1.0, below=1.0
    )
    yaw_deg: float = param(0.0, "object rotation about the table normal (deg)")
    rest: str = param(
        "upright",
        "how the object lies on the table: upright (the mesh's own frame), K (its K-th most "
        "likely stable pose, 0 the most likely) or random (one drawn with the trial's seed "
        "by the poses' probabilities)",
    )
    pictures: bool = param(True, "write the PNG pictures (sweeps of many trials may skip them)")
    units: Literal["m", "mm"] = param(
        "m", "length unit of a mesh file given as object (a URDF states its own scale)"
    )
    grasps: int = param(
        1,
        "grasps per trial: after each the hand releases and withdraws, the estimator fuses "
        "every grasp so far and the next grasp is planned on its model",
        at_least=1,
    )
    next_grasp: Literal["paper", "random", "information"] = param(
        "information",
        "how grasps after the first are chosen among the planner's feasible ones: paper "
        "(the planner's own best), random (seeded), information (largest expected reduction "
        "of the hidden side's uncertainty)",
    )
    until_std_mm: float = param(
        0.0,
        "stop grasping once the plane offset's and the hidden shape's posterior stds are "
        "both at most this (mm); 0: make all the grasps",
        at_least=0.0,
    )
    after_view: bool = param(
        True,
        "look again while the hand holds the object and fuse that view as a measurement of "
        "how the grasp moved it (docs/after-view.md); false: the paper's pipeline",
    )
    retries: int = param(
        2,
        "after a first grasp whose pads do not touch opposing sides, or that the hand could "
        "not execute (nothing to fuse): "
        "release, look again and grasp unlike every grasp that missed, up to this many times",
        at_least=0,
    )
    symmetry: tuple[float, ...] = param(
        (),
        "the true mirror plane of a mesh file given as object, [NX, NY, D]: the points with "
        "NX x + NY y = D in the file's own frame and units, so the plane errors are scored; "
        "empty: none",
    )


@dataclasses.dataclass(frozen=True)
class ModelSettings:
    """The ``[model]`` section: the solid the model files describe (:mod:`pipeline.asset`)."""

    # Denser than any solid element (osmium, 22.6 t/m^3) is a typo.
    density_kg_m3: float = param(
        500.0,
        "uniform density of the model's solid (kg/m^3), for its mass and inertia",
        above=0.0,
        at_most=25_000.0,
    )
    mass_kg: float = param(
        0.0,
        "the model's mass (kg), which sets the density instead; 0: density x volume",
        at_least=0.0,
        at_most=1_000.0,
    )


#: How the grasps after a trial's first may be chosen (:mod:`pipeline.planning.next_grasp`).
NEXT_GRASP_STRATEGIES: tuple[str, ...] = get_args(get_type_hints(TrialSettings)["next_grasp"])

#: Sections that are not stages, and the dataclass each one is validated against.
SETTINGS_SECTIONS: dict[str, type] = {"trial": TrialSettings, "model": ModelSettings}


def default_config_text() -> str:
    """The shipped default config file's text."""
    return importlib.resources.files("pipeline").joinpath("default.toml").read_text()


def _deep_merge(base: dict[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    merged = copy.deepcopy(base)
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), dict):
            merged[key] = _deep_merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file, turning every failure into a one-line :class:`ConfigError`."""
    try:
        return tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError(f"config file '{path}' does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"config file '{path}' cannot be read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file '{path}' is not valid TOML: {exc}") from None


def parse_override(text: str) -> dict[str, Any]:
    """Turn ``section.key=value`` into a nested dict.

    The value is read as a TOML value (``20``, ``0.5``, ``true``, ``[1, 2]``, ``"text"``);
    anything that is not valid TOML is taken as a plain string, so ``estimator.use=icp``
    works without quotes.
    """
    key, sep, raw = text.partition("=")
    parts = key.strip().split(".")
    if not sep or not all(p.strip() for p in parts) or len(parts) < 2:
        raise ConfigError(f"--set '{text}': expected section.key=value")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    nested: dict[str, Any] = {parts[-1].strip(): value}
    for part in reversed(parts[:-1]):
        nested = {part.strip(): nested}
    return nested


@dataclasses.dataclass(frozen=True)
class Config:
    """A validated, fully resolved configuration.

    Attributes:
        settings: the non-stage sections, validated (e.g. ``settings["trial"]``).
        choices: stage -> selected implementation name.
        params: stage -> implementation name -> validated ``Params`` instance, for the
            selected implementation and every implementation the files mention.
        changed: what the user set, as dotted key -> where (a config file's path, a
            ``--set``, the command's option that stands for the key, or ``settings``):
            every key a ``--set`` or an option names, even to its default value (``--set
            planner.use=top-parallel`` is a choice), and every key whose value differs from
            the shipped defaults (a whole resolved ``config.toml`` given to ``--config`` sets
            only what it changes). A parameter of an implementation the shipped defaults do
            not mention is set where its stage's ``use`` is.
        shipped: the shipped defaults, resolved (:meth:`to_dict`'s form).
    """

    settings: Mapping[str, Any]
    choices: Mapping[str, str]
    params: Mapping[str, Mapping[str, Any]]
    # Where the values came from is not part of what they are: two configs of equal
    # values are equal, however they were given.
    changed: Mapping[str, str] = dataclasses.field(default_factory=dict, compare=False)
    shipped: Mapping[str, Any] = dataclasses.field(default_factory=dict, repr=False, compare=False)

    @property
    def trial(self) -> TrialSettings:
        return self.settings["trial"]

    @property
    def model(self) -> ModelSettings:
        return self.settings["model"]

    def stage_params(self, stage: str) -> Any:
        """The ``Params`` of the implementation selected for ``stage``."""
        return self.params[stage][self.choices[stage]]

    def create(self, registry: StageRegistry, stage: str) -> Any:
        """Instantiate the selected implementation of ``stage`` with its parameters."""
        name = self.choices[stage]
        return registry.create(stage, name, to_toml(self.stage_params(stage)))

    def to_dict(self) -> dict[str, Any]:
        """Everything, defaults included, as TOML-ready nested dicts (re-loadable)."""
        out: dict[str, Any] = {name: to_toml(value) for name, value in self.settings.items()}
        for stage in STAGES:
            section: dict[str, Any] = {"use": self.choices[stage]}
            for impl, params in sorted(self.params[stage].items()):
                section[impl] = to_toml(params)
            out[stage] = section
        return out

    def to_toml(self) -> str:
        return tomli_w.dumps(self.to_dict())

    def changed_sections(self, sources: Collection[str] | None = None) -> list[str]:
        """The sections with a key the user set (only those set in ``sources``, when
        given: config files' paths, say), in config order."""
        sections = {
            key.split(".")[0]
            for key, where in self.changed.items()
            if sources is None or where in sources
        }
        return [section for section in self.to_dict() if section in sections]

    def differing(self) -> dict[str, Any]:
        """The values that differ from the shipped defaults, as a sparse nested dict that,
        merged over them (``load_config(settings=...)``), gives this config back."""
        return changed_settings(self.to_dict(), self.shipped)

    def check_stages(self, registry: StageRegistry, stages: Iterable[str] = STAGES) -> None:
        """Check the parameters of the implementations selected for ``stages`` as they go
        together (:meth:`~pipeline.stages.StageImplementation.check_params`), without
        building them; an implementation with its own ``__init__``, which may check more,
        is built and dropped.

        Raises:
            ConfigError: naming the key at fault.
        """
        for stage in stages:
            cls = registry.get(stage, self.choices[stage]).cls
            if cls.__init__ is not StageImplementation.__init__:
                self.create(registry, stage)
            else:
                cls.check_params(self.stage_params(stage))

    def check_trial(self, registry: StageRegistry) -> None:
        """The checks across keys a trial makes before it runs: a ``planner.use`` the user
        chose that would not plan (:func:`pipeline.planning.hand_choice.check_planner_is_read`), and
        the next-grasp strategy or the stop rule set for a trial of one grasp (neither
        would act).

        Raises:
            ConfigError: naming the key (and the option that stands for it) at fault.
        """
        from pipeline.planning.hand_choice import check_planner_is_read

        check_planner_is_read(self, registry, self.changed)
        if self.trial.grasps > 1:
            return
        for key, option in (("next_grasp", "--next-grasp"), ("until_std_mm", "--until-std")):
            if f"trial.{key}" in self.changed:
                raise ConfigError(
                    f"{option} (trial.{key}) applies to a trial of several grasps; give "
                    "--grasps N with N > 1"
                )

    def write(self, path: Path) -> Path:
        """Write the resolved config as TOML; ``--config`` on it reproduces the run."""
        path = Path(path)
        path.write_text(
            "# Resolved symfuse configuration: pass it with --config to repeat this run.\n"
            + self.to_toml()
        )
        return path


def _validate(raw: Mapping[str, Any], registry: StageRegistry) -> Config:
    known_sections = [*SETTINGS_SECTIONS, *STAGES]
    for section in raw:
        if section not in known_sections:
            raise ConfigError(
                f"unknown config section '{section}' (known: {', '.join(known_sections)})"
            )
    settings = {}
    for section, settings_cls in SETTINGS_SECTIONS.items():
        values = raw.get(section, {})
        if not isinstance(values, Mapping):
            raise ConfigError(f"config key '{section}' must be a table")
        settings[section] = build(settings_cls, values, section)

    choices: dict[str, str] = {}
    params: dict[str, dict[str, Any]] = {}
    for stage in STAGES:
        section = raw.get(stage, {})
        if not isinstance(section, Mapping):
            raise ConfigError(f"config key '{stage}' must be a table")
        use = section.get("use")
        if not isinstance(use, str):
            raise ConfigError(f"config key '{stage}.use' must name a {stage} implementation")
        params[stage] = {}
        for key, value in section.items():
            if key == "use":
                continue
            if not isinstance(value, Mapping):
                raise ConfigError(
                    f"unknown config key '{stage}.{key}' ({stage} takes 'use' and one table "
                    "of parameters per implementation)"
                )
            registration = _registration(registry, stage, key, f"{stage}.{key}")
            params[stage][key] = build(registration.cls.Params, value, f"{stage}.{key}")
        registration = _registration(registry, stage, use, f"{stage}.use")
        choices[stage] = use
        params[stage].setdefault(use, registration.cls.Params())
    _check_gripper(settings["trial"].gripper, choices["world"], registry)
    parse_rest(settings["trial"].rest)
    return Config(settings=settings, choices=choices, params=params)


def _check_gripper(gripper: str, world: str, registry: StageRegistry) -> None:
    """``trial.gripper`` must be ``auto`` or a hand of the selected world; when it is not,
    the message names the installed worlds that offer that hand."""
    hands = registry.get("world", world).cls.hands
    if gripper == "auto" or gripper in hands:
        return
    offering = [
        name for name in registry.names("world") if gripper in registry.get("world", name).cls.hands
    ]
    if not offering:
        hint = "no installed world offers it (symfuse plugins lists the worlds)"
    elif len(offering) == 1:
        hint = f"world {offering[0]} offers it: --set world.use={offering[0]}"
    else:
        hint = f"worlds {', '.join(offering)} offer it: --set world.use={offering[0]}"
    raise ConfigError(
        f"config key 'trial.gripper': {gripper!r} is not a hand of world '{world}' "
        f"(auto, {', '.join(hands)}); {hint}"
    )


def changed_settings(config: Mapping[str, Any], base: Mapping[str, Any]) -> dict[str, Any]:
    """The values of the nested dict ``config`` that ``base`` lacks or holds otherwise
    (both as :meth:`Config.to_dict` gives them): a sparse dict that, merged over ``base``,
    gives ``config`` back."""
    changed: dict[str, Any] = {}
    for key, value in config.items():
        if isinstance(value, Mapping) and isinstance(base.get(key), Mapping):
            inner = changed_settings(value, base[key])
            if inner:
                changed[key] = inner
        elif key not in base or base[key] != value:
            changed[key] = copy.deepcopy(value)
    return changed


def dotted_value(config: Mapping[str, Any], key: str) -> Any:
    """The value at ``section.key`` (dotted) in a nested config dict; None when absent."""
    value: Any = config
    for part in key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return None
        value = value[part]
    return value


def _registration(registry: StageRegistry, stage: str, name: str, key: str):
    names = registry.names(stage)
    if name not in names:
        available = ", ".join(names) or "none installed"
        raise ConfigError(f"config key '{key}': no {stage} named '{name}' (available: {available})")
    return registry.get(stage, name)


def leaf_keys(nested: Mapping[str, Any], prefix: str = "") -> list[str]:
    """The dotted keys of the values (not tables) of a nested config dict, in order."""
    keys: list[str] = []
    for key, value in nested.items():
        dotted = f"{prefix}{key}"
        keys += leaf_keys(value, f"{dotted}.") if isinstance(value, Mapping) else [dotted]
    return keys


def _implied_by(key: str, where: Mapping[str, str]) -> str:
    """Where a parameter the user did not name took a value other than the shipped one
    (an implementation the defaults do not mention, brought in whole): where another key
    of its table was set, else where its stage's ``use`` was."""
    table = key.rpartition(".")[0]
    named = (source for other, source in where.items() if other.startswith(f"{table}."))
    return next(named, where.get(f"{key.split('.')[0]}.use", ""))


def load_config(
    registry: StageRegistry,
    files: Iterable[Path] = (),
    overrides: Iterable[str] = (),
    settings: Mapping[str, Any] | None = None,
    options: Iterable[tuple[str, str]] = (),
    command_defaults: tuple[str, Mapping[str, Any]] | None = None,
) -> Config:
    """Merge the defaults, a command's own defaults (``command_defaults``: the command, as
    :attr:`Config.changed` names it, and a nested dict), ``files`` (in order), ``settings``
    (a nested dict, e.g. what :meth:`Config.differing` returned), ``--set`` ``overrides``
    and the ``options`` of a command (``(override, option)`` pairs, the option's name for
    :attr:`Config.changed`); validate.

    Raises:
        ConfigError: naming the file or dotted key at fault.
    """
    shipped = tomllib.loads(default_config_text())
    raw, named, where = shipped, [], {}
    layers = [(command_defaults[1], command_defaults[0])] if command_defaults else []
    layers += [(read_toml(path), str(path)) for path in files]
    layers.append((settings or {}, "settings"))
    for text in overrides:
        layers.append((parse_override(text), "--set"))
    for text, option in options:
        layers.append((parse_override(text), option))
    for layer, source in layers:
        raw = _deep_merge(raw, layer)
        keys = leaf_keys(layer)
        where.update(dict.fromkeys(keys, source))
        if source.startswith("--"):
            named += keys
    config = _validate(raw, registry)
    defaults = _validate(shipped, registry).to_dict()
    changed = {key: where[key] for key in named}
    for key in leaf_keys(changed_settings(config.to_dict(), defaults)):
        changed.setdefault(key, where.get(key) or _implied_by(key, where))
    return dataclasses.replace(config, changed=changed, shipped=defaults)
