"""The error types symfuse raises on purpose, and the exit codes of the command line.

Every failure a user can cause (a bad file, a bad config key, a missing plugin) raises one
of these with a one-line message that names the file, key or plugin at fault. The CLI
prints ``symfuse: error: <message>`` and exits with :attr:`SymfuseError.exit_code`;
anything else reaching the CLI is a bug in symfuse and keeps its traceback.

Exit codes (the command line reference, ``docs/cli.md``, states them too):

==== ================================================================================
0    the run finished and its estimate is usable
2    bad input or config: nothing was run, nothing is left behind
3    the estimate failed or is inconsistent (:data:`FAILED_STATUSES`), or a stage could
     not produce a result; what the run wrote, ``result.json`` included, is kept
4    a plugin raised an unexpected exception; the message names the stage, the plugin
     and its distribution
130  interrupted (Ctrl-C)
==== ================================================================================
"""

from __future__ import annotations

EXIT_OK = 0
"""Exit code: the run finished."""
EXIT_BAD_INPUT = 2
"""Exit code: bad input or configuration; nothing ran."""
EXIT_ESTIMATE_FAILED = 3
"""Exit code: the estimate failed or is inconsistent, or a stage produced no result; the
results are written."""
EXIT_PLUGIN_RAISED = 4
"""Exit code: a plugin raised an unexpected exception."""
EXIT_INTERRUPTED = 130

#: Final estimate statuses that make a run exit with :data:`EXIT_ESTIMATE_FAILED`.
FAILED_STATUSES = frozenset({"no_correspondence", "diverged", "inconsistent"})
#: Statuses of a stage whose estimator gave up and returned its prior unchanged.
FELL_BACK_STATUSES = frozenset({"no_correspondence", "diverged"})


def estimate_failed(status: str) -> bool:
    """Whether a final estimate ``status`` counts as failed (exit code 3)."""
    return status in FAILED_STATUSES


class SymfuseError(Exception):
    """Base of all deliberate symfuse errors; the message is a single line."""

    exit_code: int = EXIT_BAD_INPUT


class ConfigError(SymfuseError):
    """A config file, a ``--set`` override or a plugin parameter is wrong."""


class InputError(SymfuseError):
    """An input file (cloud, contacts, mesh, URDF) is missing, unreadable or invalid."""


class PluginError(SymfuseError):
    """A plugin could not be found, or is installed wrongly (a name taken twice, an unknown
    hook), or was used where it cannot work."""


class PluginRaised(PluginError):
    """A plugin's own code raised an unexpected exception (on import, while registering or
    inside a stage method); the message names the stage, the plugin and its distribution."""

    exit_code = EXIT_PLUGIN_RAISED


class MissingExtraError(SymfuseError):
    """An optional feature's dependencies are not installed; the message names the extra."""


class StageFailure(SymfuseError):
    """A stage ran correctly but could not produce a usable result (e.g. empty segmentation).

    The message says which stage and why; runs that fail this way still write what they
    have so far.
    """

    exit_code = EXIT_ESTIMATE_FAILED
