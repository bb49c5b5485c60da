"""The table of options that stand for config keys (pipeline.cli.options) matches the
parsers and the config, and what the options set is labelled with the option."""

from __future__ import annotations

import pytest

from pipeline.cli import build_parser
from pipeline.cli.options import KEY_OPTIONS, option_overrides
from pipeline.config import leaf_keys, load_config
from pipeline.registry import load_registry


def _subparsers():
    parser = build_parser()
    (verbs,) = [a for a in parser._actions if a.dest == "verb"]
    return verbs.choices


@pytest.mark.parametrize("option", KEY_OPTIONS, ids=lambda o: f"{o.verb}-{o.dest}")
def test_every_row_names_an_option_of_its_verb(option):
    if option.dest is None:
        assert option.constant
        return
    dests = {action.dest for action in _subparsers()[option.verb]._actions}
    assert option.dest in dests


def test_every_key_of_the_table_is_a_config_key():
    registry = load_registry()
    known = set(leaf_keys(load_config(registry, overrides=["sensor.use=recorded"]).to_dict()))
    assert {option.key for option in KEY_OPTIONS} <= known


def test_the_options_given_become_overrides_labelled_with_the_option():
    args = build_parser().parse_args(
        ["trial", "--gripper", "sdh", "--seed", "0", "--yaw", "15", "--symmetry=1,0,-0.5"]
    )
    assert option_overrides(args) == [
        ("trial.gripper=sdh", "--gripper"),
        ("trial.seed=0", "--seed"),
        ("trial.yaw_deg=15.0", "--yaw"),
        ("trial.symmetry=[1.0, 0.0, -0.5]", "--symmetry"),
    ]
    config = load_config(load_registry(), options=option_overrides(args))
    assert config.changed["trial.seed"] == "--seed"  # at its default value: still a choice
    assert config.trial.symmetry == (1.0, 0.0, -0.5) and config.trial.yaw_deg == 15.0
    scan = build_parser().parse_args(["complete", "scan.pcd", "--out", "x"])
    assert [option for _, option in option_overrides(scan)] == ["symfuse complete", "SCAN"]
