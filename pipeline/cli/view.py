"""``symfuse view`` and the ``--rerun`` option of the run verbs: a Rerun recording of a run.

Both build the recording from the run folder's files (:mod:`pipeline.viz.recording`), so
``symfuse trial --rerun`` and ``symfuse view`` on the same folder give the same recording.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from pipeline.errors import ConfigError


def add_rerun_option(parser: argparse.ArgumentParser) -> None:
    """``--rerun`` for a verb that writes a run folder."""
    parser.add_argument(
        "--rerun",
        action="store_true",
        help="also write recording.rrd, a Rerun recording of the run (needs symfuse[viz])",
    )


def check_rerun(args: argparse.Namespace) -> None:
    """Fail before running anything when ``--rerun`` is asked for without the viz extra."""
    if getattr(args, "rerun", False):
        from pipeline.viz.recording import rerun_module

        rerun_module()


def record_if_asked(args: argparse.Namespace, run_dir: Path) -> None:
    """After a run wrote ``run_dir``: write its recording when ``--rerun`` was given."""
    if getattr(args, "rerun", False):
        from pipeline.viz.recording import write_recording

        print(f"wrote {write_recording(run_dir)} (open it with: rerun {run_dir}/recording.rrd)")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``view`` verb to the CLI's subparsers and return its parser."""
    parser = subparsers.add_parser(
        "view",
        help="open a finished run in the Rerun viewer (needs symfuse[viz])",
        description=(
            "Build a Rerun recording (RUN_DIR/recording.rrd) from a finished run's files - "
            "camera, cloud, completed models per stage, symmetry planes, hand, taxels, true "
            "mesh and the IEKF iterations on a timeline - without re-running it, and open it "
            "in the viewer when a display is available."
        ),
    )
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a trial/fuse output folder")
    parser.add_argument(
        "--out", type=Path, metavar="FILE", help="write the recording here instead (.rrd)"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing recording (--out, or RUN_DIR/recording.rrd)",
    )
    parser.add_argument(
        "--no-open", action="store_true", help="only write the recording, do not open the viewer"
    )
    return parser


def has_display() -> bool:
    """Whether a viewer window can open: always on macOS and Windows, on Linux and other
    Unixes when an X11 or Wayland display is set."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def check_recording_target(path: Path, *, overwrite: bool) -> None:
    """Refuse a recording target (``--out``, or the run folder's ``recording.rrd``) that is
    not a ``.rrd`` file in an existing folder we can write, or that exists (another file,
    perhaps one of the run's own, or the recording of an earlier ``--rerun``) without
    ``overwrite``.

    Raises:
        ConfigError: naming the target and what is wrong with it.
    """
    if path.suffix.lower() != ".rrd":
        raise ConfigError(f"--out {path}: a Rerun recording is a .rrd file")
    if path.is_dir():
        raise ConfigError(f"--out {path}: is a folder; give a .rrd file")
    if path.exists() and not overwrite:
        raise ConfigError(
            f"{path}: exists; pass --overwrite to replace it, give another --out, or open "
            f"it with: rerun {path}"
        )
    if not path.parent.is_dir():
        raise ConfigError(f"--out {path}: the folder {path.parent} does not exist")
    try:  # a read-only folder, found before the recorder fails in its own words
        tempfile.TemporaryFile(dir=path.parent).close()
    except OSError as exc:
        raise ConfigError(
            f"{path}: cannot write in {path.parent} ({exc.strerror or exc}); give an --out "
            "in a folder you can write"
        ) from None


def run(args: argparse.Namespace) -> int:
    from pipeline.viz.recording import RECORDING_NAME, write_recording

    target = args.out if args.out is not None else Path(args.run_dir) / RECORDING_NAME
    if args.out is not None or Path(args.run_dir).is_dir():
        check_recording_target(target, overwrite=args.overwrite)
    path = write_recording(args.run_dir, target)
    print(f"wrote {path}")
    if args.no_open or not has_display():
        print(f"open it with: rerun {path}")
        return 0
    # The viewer outlives this command, in its own session.
    subprocess.Popen(
        [sys.executable, "-m", "rerun", str(path)],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    print("opened the Rerun viewer")
    return 0
