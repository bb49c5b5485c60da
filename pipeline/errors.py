"""The error types symfuse raises on purpose.

Every failure a user can cause (a bad file, a bad config key, a missing or broken plugin)
raises one of these with a one-line message that names the file, key or plugin at fault.
The CLI prints ``symfuse: error: <message>`` and exits with :attr:`SymfuseError.exit_code`;
anything else reaching the CLI is a bug in symfuse and keeps its traceback.
"""

from __future__ import annotations


class SymfuseError(Exception):
    """Base of all deliberate symfuse errors; the message is a single line."""

    exit_code: int = 2


class ConfigError(SymfuseError):
    """A config file, a ``--set`` override or a plugin parameter is wrong."""


class InputError(SymfuseError):
    """An input file (cloud, contacts, mesh, URDF) is missing, unreadable or invalid."""


class PluginError(SymfuseError):
    """A plugin could not be found, loaded or registered, or raised while running."""


class MissingExtraError(SymfuseError):
    """An optional feature's dependencies are not installed; the message names the extra."""


class StageFailure(SymfuseError):
    """A stage ran correctly but could not produce a usable result (e.g. empty segmentation).

    The message says which stage and why; runs that fail this way still write what they
    have so far.
    """

    exit_code = 3
