"""The ``symfuse`` console script: Ctrl-C means exit code 130 from the first instant.

Python's own handler raises KeyboardInterrupt wherever the program happens to be. Before
the command has imported numpy, scipy or a plugin, that is inside some module's import,
which then fails with an unrelated error (numpy's ``RuntimeError: Error calling
__set_name__``, a plugin's ``NameError`` on a half-imported scipy) or leaves a half-built
module that a later ``except ImportError`` swallows, or is swallowed itself (an
``except BaseException`` around an optional import). So :func:`main` installs its own
handler before anything is imported that Python's start did not load: it notes the interrupt and
raises KeyboardInterrupt as usual, and whatever error then ends the run, or none, the
command exits with 130, :data:`~pipeline.errors.EXIT_INTERRUPTED` (:func:`pipeline.cli.main`
asks :func:`interrupt_received`).

The console script also ends without the interpreter's teardown (:func:`leave`): taking
apart the modules of a trial (numpy, scipy, trimesh, open3d, PyBullet) cost a new process
about 0.3 s of processor time after its last file was written.
"""

from __future__ import annotations

# The handler is installed before anything else is imported: ``_signal`` is the C module
# under ``signal`` (which imports enum and functools first), ``os`` and ``sys`` are loaded
# by Python's start, and the rest is imported where it is used.
import _signal as signal
import os
import sys

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Sequence
    from typing import NoReturn

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

    A SIGINT the shell set to be ignored (a background job) stays ignored. Without
    ``argv`` (the console script, ``python -m pipeline.cli``: the arguments are the
    process's) the process ends here with the command's exit code (:func:`leave`); with
    ``argv`` (a caller in the same process) the code is returned.
    """
    global _received
    _received = False
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_interrupt)
    try:
        if argv is None:
            from pipeline import lean_imports

            lean_imports.install()
        from pipeline.cli import main as run

        code = run(argv)
    except BaseException:
        if not _received:
            raise
        code = report_interrupt()
    if argv is None:
        leave(code)
    return code


def leave(code: int) -> NoReturn:
    """End the process with ``code`` once the exit handlers have run and the standard
    streams are flushed, skipping the interpreter's teardown of its modules: every file a
    command writes is closed by then (``with`` blocks), so the teardown only takes apart
    what the process is about to drop anyway. A Ctrl-C from here on changes nothing: the
    command has ended."""
    import atexit
    import contextlib

    if signal.getsignal(signal.SIGINT) is _on_interrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        # A closed pipe or stream: nothing more can be said.
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(code)


def report_interrupt() -> int:
    """Say the command was interrupted and return its exit code, 130. In the console
    script a second Ctrl-C is ignored from here on: the command is ending as asked."""
    from pipeline.errors import EXIT_INTERRUPTED

    if signal.getsignal(signal.SIGINT) is _on_interrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    print("symfuse: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED
