"""The ``symfuse`` console script: Ctrl-C means exit code 130 from the first instant.

Python's own handler raises KeyboardInterrupt wherever the program happens to be. Before
the command has imported numpy, scipy or a plugin, that is inside some module's import,
which then fails with an unrelated error (numpy's ``RuntimeError: Error calling
__set_name__``, a plugin's ``NameError`` on a half-imported scipy) or leaves a half-built
module that a later ``except ImportError`` swallows, or is swallowed itself (an
``except BaseException`` around an optional import). So :func:`main` installs its own
handler before importing anything but the standard library: it notes the interrupt and
raises KeyboardInterrupt as usual, and whatever error then ends the run, or none, the
command exits with 130, :data:`~pipeline.errors.EXIT_INTERRUPTED` (:func:`pipeline.cli.main`
asks :func:`interrupt_received`).
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence

from pipeline.errors import EXIT_INTERRUPTED

_received = False


def interrupt_received() -> bool:
    """Whether Ctrl-C reached the running ``symfuse`` command."""
    return _received


def stop_if_interrupted() -> None:
    """Raise KeyboardInterrupt if Ctrl-C came and was swallowed: a library that imports
    its optional parts under ``except BaseException`` (trimesh does) takes it for a missing
    part and goes on. The run verbs call this between phases.
    """
    if _received:
        raise KeyboardInterrupt


def _on_interrupt(signum, frame) -> None:
    global _received
    _received = True
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line (:func:`pipeline.cli.main`) with the interrupt noted.

    A SIGINT the shell set to be ignored (a background job) stays ignored.
    """
    global _received
    _received = False
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_interrupt)
    try:
        from pipeline.cli import main as run

        return run(argv)
    except BaseException:
        if not _received:
            raise
        return report_interrupt()


def report_interrupt() -> int:
    """Say the command was interrupted and return its exit code, 130. In the console
    script a second Ctrl-C is ignored from here on: the command is ending as asked."""
    if signal.getsignal(signal.SIGINT) is _on_interrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    print("symfuse: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED
