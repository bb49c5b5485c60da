"""Ctrl-C at any moment of a run, the first instants included, ends ``symfuse`` with exit
code 130, one line and nothing left behind: sent to the real console script, at times that
fall inside the imports of numpy, scipy, trimesh and the plugins, and inside the trial."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.errors import EXIT_INTERRUPTED

SYMFUSE = shutil.which("symfuse", path=str(Path(sys.executable).parent))


def cpu_seconds(pid: int) -> float:
    """The processor time process ``pid`` has used so far (s; user and system)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def interrupted_trial(tmp_path: Path, after_s: float) -> tuple[int, str]:
    """Exit code and stderr of ``symfuse trial`` sent SIGINT once it has used ``after_s`` of
    processor time: on a loaded machine Python's own start (the window before the handler,
    ``docs/cli.md``) takes many times its 40 ms of processor time in wall time."""
    process = subprocess.Popen(
        [SYMFUSE, "trial", "--out", str(tmp_path / "run")],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        # As from an interactive shell: a test run in the background inherits SIGINT ignored.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    with contextlib.suppress(FileNotFoundError, ProcessLookupError):
        while process.poll() is None and cpu_seconds(process.pid) < after_s:
            time.sleep(0.005)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=120)
    return process.returncode, err


@pytest.mark.skipif(SYMFUSE is None, reason="the symfuse console script is not installed")
@pytest.mark.parametrize(
    "after_s", [0.1, *(pytest.param(s, marks=pytest.mark.slow) for s in (0.3, 0.6, 1.0, 1.5, 3.0))]
)
def test_ctrl_c_from_the_first_instant_exits_130(tmp_path, after_s):
    code, err = interrupted_trial(tmp_path, after_s)
    assert code == EXIT_INTERRUPTED, err
    assert err == "symfuse: interrupted\n"
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_a_library_swallowed_still_ends_the_run(monkeypatch, capsys):
    """trimesh imports its optional parts under ``except BaseException``: the run goes on
    unless the command asks whether Ctrl-C came."""
    from pipeline import cli, entry

    def swallowed(args):
        with contextlib.suppress(BaseException):  # as the library does
            entry._on_interrupt(signal.SIGINT, None)
        entry.stop_if_interrupted()
        return 0

    monkeypatch.setattr(cli, "_cmd_config", swallowed)
    monkeypatch.setattr(entry, "_received", False)
    previous = signal.getsignal(signal.SIGINT)
    try:
        assert entry.main(["config"]) == EXIT_INTERRUPTED
    finally:
        signal.signal(signal.SIGINT, previous)
    assert capsys.readouterr().err == "symfuse: interrupted\n"


def test_the_console_script_imports_nothing_before_its_handler():
    """What ``pipeline.entry`` imports runs before :func:`~pipeline.entry.main` installs
    the handler: on a loaded machine ``typing`` and ``contextlib`` alone took 0.1 s there,
    and a Ctrl-C inside them ended the run with Python's traceback."""
    script = (
        "import sys; before = set(sys.modules); import pipeline.entry; "
        "print(' '.join(sorted(set(sys.modules) - before)))"
    )
    loaded = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert set(loaded.stdout.split()) <= {"__future__", "pipeline", "pipeline.entry"}
