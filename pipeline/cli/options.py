"""The options of the verbs that stand for config keys, in one table.

``symfuse trial --gripper pg70`` is ``--set trial.gripper=pg70`` said shorter: each such
option is one row of :data:`KEY_OPTIONS`, naming the verb, the option (its argparse
``dest``), the config key and how the option's value is written as the key's TOML value.
:func:`option_overrides` turns a parsed command line into those settings, each with the
option it came from, so the config knows who set what (:attr:`pipeline.config.Config.changed`)
and a ``--set`` of a key an option also sets is refused (:func:`pipeline.cli.check_overrides`).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


def _quoted(value: Any) -> str:
    """A path or name as a TOML string, whatever it holds."""
    return json.dumps(str(value))


def _array(value: Any) -> str:
    return str(list(value))


@dataclass(frozen=True)
class KeyOption:
    """A verb's option that sets one config key.

    Attributes:
        verb: the verb that has the option.
        dest: the option's argparse ``dest`` (None: the key is set whenever the verb runs,
            to ``constant``).
        key: the dotted config key it sets.
        text: the option's value as a TOML value (read as a plain string when it is not
            valid TOML, as ``--set`` reads it).
        constant: the value of a key the verb always sets.
    """

    verb: str
    dest: str | None
    key: str
    text: Callable[[Any], str] = str
    constant: str = ""

    @property
    def flag(self) -> str:
        """How the option is named to the user (``--next-grasp``; the verb for a key it
        always sets)."""
        if self.dest is None:
            return f"symfuse {self.verb}"
        return "SCAN" if self.dest == "scan" else "--" + self.dest.replace("_", "-")


#: Every option that stands for a config key, by verb, in the order they apply.
KEY_OPTIONS: tuple[KeyOption, ...] = (
    KeyOption("trial", "object", "trial.object", _quoted),
    KeyOption("trial", "mesh", "trial.object", _quoted),
    KeyOption("trial", "gripper", "trial.gripper"),
    KeyOption("trial", "init", "initialiser.use"),
    KeyOption("trial", "seed", "trial.seed"),
    KeyOption("trial", "yaw", "trial.yaw_deg"),
    KeyOption("trial", "rest", "trial.rest", _quoted),
    KeyOption("trial", "grasps", "trial.grasps"),
    KeyOption("trial", "next_grasp", "trial.next_grasp"),
    KeyOption("trial", "until_std", "trial.until_std_mm"),
    KeyOption("trial", "symmetry", "trial.symmetry", _array),
    KeyOption("trial", "units", "trial.units"),
    KeyOption("fuse", "init", "initialiser.use"),
    KeyOption("complete", None, "sensor.use", _quoted, constant="recorded"),
    KeyOption("complete", "scan", "sensor.recorded.path", _quoted),
    KeyOption("complete", "init", "initialiser.use", _quoted),
    KeyOption("complete", "camera", "sensor.recorded.camera", _quoted),
    KeyOption("complete", "topic", "sensor.recorded.topic", _quoted),
    KeyOption("sweep", "estimator", "estimator.use"),
    KeyOption("sweep", "rest", "trial.rest", _quoted),
)


def option_overrides(args: argparse.Namespace) -> list[tuple[str, str]]:
    """The settings the options given to ``args.verb`` stand for, as ``(override, option)``
    pairs for :func:`pipeline.config.load_config` (an option not given sets nothing)."""
    settings = []
    for option in KEY_OPTIONS:
        if option.verb != args.verb:
            continue
        value = option.constant if option.dest is None else getattr(args, option.dest)
        if value is None or value == "":
            continue
        settings.append((f"{option.key}={option.text(value)}", option.flag))
    return settings
