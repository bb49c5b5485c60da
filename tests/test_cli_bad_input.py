"""Bad input met by a new user, one verb at a time: every mistake is one line
``symfuse: error: ...`` naming what is wrong, with exit code 2, and no traceback."""

from __future__ import annotations

import pytest

from pipeline.cli import main
from pipeline.errors import EXIT_BAD_INPUT


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("symfuse: error: "), err
    return lines[0]


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        (["sweep", "nope"], "sweep: argument EXPERIMENT: invalid choice: 'nope'"),
        (["trial", "--seed", "x"], "trial: argument --seed: invalid int value: 'x'"),
        (["fuse", "--cloud", "c.ply"], "fuse: the following arguments are required"),
        (["plugins", "--foo"], "unrecognized arguments: --foo"),
        ([], "the following arguments are required: VERB"),
    ],
)
def test_command_line_mistakes_are_one_line(capsys, argv, names):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == EXIT_BAD_INPUT
    _, err = capsys.readouterr()
    assert names in one_error_line(err)
