"""TOML config: defaults, files, --set overrides, validation messages, round trip."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from typing import ClassVar, Literal

import pytest

from pipeline.config import load_config, parse_override
from pipeline.errors import ConfigError
from pipeline.params import param
from pipeline.registry import load_registry
from pipeline.stages import STAGES
from pipeline.testing import registry_with


@pytest.fixture(scope="module")
def registry():
    return load_registry()


def write(tmp_path, text, name="run.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_defaults_select_one_installed_implementation_per_stage(registry):
    config = load_config(registry)
    for stage in STAGES:
        assert config.choices[stage] in registry.names(stage)
    assert config.trial.object == "cd_drive"


def test_file_then_overrides_in_order(registry, tmp_path):
    path = write(tmp_path, '[trial]\nseed = 5\nobject = "salt_cylinder"\n')
    config = load_config(registry, [path], ["trial.seed=7", "trial.yaw_deg=30"])
    assert config.trial.seed == 7
    assert config.trial.object == "salt_cylinder"
    assert config.trial.yaw_deg == 30.0


def test_swapping_a_stage_is_one_line(registry):
    other = next(n for n in registry.names("estimator") if n != "iekf")
    config = load_config(registry, overrides=[f"estimator.use={other}"])
    assert config.choices["estimator"] == other


def test_unknown_key_is_named(registry, tmp_path):
    path = write(tmp_path, "[trial]\nsede = 5\n")
    with pytest.raises(ConfigError) as error:
        load_config(registry, [path])
    assert str(error.value) == (
        "unknown config key 'trial.sede' (did you mean 'seed'? "
        "known keys: object, gripper, seed, x_m, y_m, yaw_deg, rest, pictures, units, "
        "grasps, next_grasp, until_std_mm, after_view, retries, symmetry)"
    )
    # A renamed key points to its new name.
    with pytest.raises(ConfigError, match="did you mean 'regrasp_b_xy_m'"):
        load_config(registry, overrides=["estimator.iekf.regrasp_b_xyz_m=0.002"])
    # Nothing close: no guess.
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["trial.zzzz=1"])
    assert "did you mean" not in str(error.value)


def test_unknown_section_is_named(registry):
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["segmentor.use=x"])
    assert str(error.value).startswith("unknown config section 'segmentor' (known: trial, ")


def test_unknown_implementation_is_named_with_alternatives(registry):
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["estimator.use=kalman9000"])
    available = ", ".join(registry.names("estimator"))
    assert str(error.value) == (
        f"config key 'estimator.use': no estimator named 'kalman9000' (available: {available})"
    )


def test_unknown_plugin_parameter_is_named(registry):
    name = registry.names("estimator")[0]
    with pytest.raises(ConfigError, match=rf"unknown config key 'estimator\.{name}\.nope'"):
        load_config(registry, overrides=[f"estimator.{name}.nope=1"])


def test_wrong_type_is_named(registry):
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["trial.seed=1.5"])
    assert str(error.value) == "config key 'trial.seed': expected int, got float"
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["trial.gripper=robotiq"])
    assert str(error.value) == (
        "config key 'trial.gripper': 'robotiq' is not a hand of world 'pybullet' "
        "(auto, pg70, sdh); no installed world offers it (symfuse plugins lists the worlds)"
    )


def test_a_hand_of_another_world_names_that_world(registry):
    from pipeline.api.sim import Pybullet

    class WidePybullet(Pybullet):
        name = "pybullet-wide"
        extra_hands: ClassVar[dict[str, str]] = {"wide": "wide.urdf"}

    wide = registry_with(WidePybullet)
    with pytest.raises(ConfigError) as error:
        load_config(wide, overrides=["trial.gripper=wide"])
    assert str(error.value) == (
        "config key 'trial.gripper': 'wide' is not a hand of world 'pybullet' "
        "(auto, pg70, sdh); world pybullet-wide offers it: --set world.use=pybullet-wide"
    )
    config = load_config(wide, overrides=["trial.gripper=wide", "world.use=pybullet-wide"])
    assert config.settings["trial"].gripper == "wide"


def test_bad_files_are_named(registry, tmp_path):
    with pytest.raises(ConfigError, match=r"config file '.*missing.toml' does not exist"):
        load_config(registry, [tmp_path / "missing.toml"])
    path = write(tmp_path, "[trial\nseed = 1\n", "broken.toml")
    with pytest.raises(ConfigError, match=r"config file '.*broken.toml' is not valid TOML"):
        load_config(registry, [path])


def test_override_syntax():
    assert parse_override("a.b=3") == {"a": {"b": 3}}
    assert parse_override("a.b.c=[1, 2.5]") == {"a": {"b": {"c": [1, 2.5]}}}
    assert parse_override("a.b=icp") == {"a": {"b": "icp"}}
    assert parse_override('a.b="x y"') == {"a": {"b": "x y"}}
    with pytest.raises(ConfigError, match=r"expected section\.key=value"):
        parse_override("seed=3")
    with pytest.raises(ConfigError, match=r"expected section\.key=value"):
        parse_override("trial.seed")


def test_resolved_config_round_trips(registry, tmp_path):
    first = load_config(registry, overrides=["trial.seed=11", "trial.yaw_deg=12.5"])
    written = first.write(tmp_path / "config.toml")
    second = load_config(registry, [written])
    assert second == first
    assert second.to_dict() == tomllib.loads(written.read_text())


def test_every_parameter_is_in_the_resolved_config(registry):
    config = load_config(registry)
    document = config.to_dict()
    for stage in STAGES:
        name = config.choices[stage]
        params = registry.get(stage, name).cls.Params
        assert set(document[stage][name]) == set(params.__dataclass_fields__)


def test_params_reject_bool_for_number_and_accept_int_for_float():
    from pipeline.params import build

    @dataclass(frozen=True)
    class P:
        gain: float = param(1.0, "gain")
        mode: Literal["a", "b"] = param("a", "mode")
        sizes: tuple[int, ...] = param((1, 2), "sizes")

    assert build(P, {"gain": 2, "sizes": [3]}, "s") == P(gain=2.0, sizes=(3,))
    with pytest.raises(ConfigError, match=r"'s.gain': expected float, got bool"):
        build(P, {"gain": True}, "s")
    with pytest.raises(ConfigError, match=r"'s.sizes\[1\]': expected int, got str"):
        build(P, {"sizes": [1, "x"]}, "s")


def test_declared_bounds_are_enforced_with_the_dotted_key(registry):
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["estimator.iekf.point_std_m=0"])
    assert str(error.value) == "config key 'estimator.iekf.point_std_m': must be > 0, got 0.0"
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["estimator.iekf.max_iterations=0"])
    assert str(error.value) == "config key 'estimator.iekf.max_iterations': must be >= 1, got 0"
    with pytest.raises(ConfigError) as error:
        load_config(registry, overrides=["estimator.iekf.consistency_alpha=1.0"])
    assert str(error.value) == (
        "config key 'estimator.iekf.consistency_alpha': must be < 1, got 1.0"
    )


def test_changed_names_what_the_user_set_and_where(registry, tmp_path):
    """A file's key counts where it differs from the shipped default (a resolved
    config.toml sets only what it changes); a --set or an option counts even at the
    default; the later source of a key wins."""
    resolved = load_config(registry, overrides=["trial.seed=4"])
    whole = resolved.write(tmp_path / "config.toml")
    partial = write(tmp_path, '[trial]\nyaw_deg = 10.0\ngripper = "auto"\n')
    config = load_config(
        registry,
        [whole, partial],
        ["planner.use=top-parallel", "trial.yaw_deg=20"],
        options=[("trial.gripper=pg70", "--gripper")],
    )
    assert config.changed == {
        "planner.use": "--set",
        "trial.yaw_deg": "--set",
        "trial.gripper": "--gripper",
        "trial.seed": str(whole),
    }
    assert config.changed_sections([str(whole), str(partial)]) == ["trial"]
    assert config.changed_sections(["--gripper"]) == ["trial"]
    assert load_config(registry, [whole]).changed == {"trial.seed": str(whole)}
    assert load_config(registry).changed == {}


def test_an_implementation_brought_in_whole_is_set_where_its_use_was(registry):
    config = load_config(registry, overrides=["estimator.use=icp"])
    params = [key for key in config.changed if key.startswith("estimator.icp.")]
    assert params and {config.changed[key] for key in params} == {"--set"}
    named = load_config(registry, overrides=["estimator.icp.max_iterations=5"])
    assert named.changed["estimator.icp.max_iterations"] == "--set"
    assert named.changed["estimator.icp.point_std_m"] == "--set"  # its table was named


def test_differing_gives_the_config_back_over_the_defaults(registry, tmp_path):
    path = write(tmp_path, '[trial]\nseed = 3\n[estimator]\nuse = "icp"\n')
    config = load_config(registry, [path], ["planner.use=top-parallel"])
    sparse = config.differing()
    assert sparse["trial"] == {"seed": 3} and "planner" not in sparse
    assert load_config(registry, settings=sparse) == config


def test_changed_is_not_part_of_a_configs_identity(registry, tmp_path):
    via_set = load_config(registry, overrides=["trial.seed=2"])
    via_file = load_config(registry, [write(tmp_path, "[trial]\nseed = 2\n")])
    assert via_set == via_file and via_set.changed != via_file.changed


def test_a_trial_refuses_strategies_for_one_grasp_whoever_set_them(registry):
    with pytest.raises(ConfigError, match=r"--next-grasp \(trial.next_grasp\) applies"):
        load_config(registry, overrides=["trial.next_grasp=random"]).check_trial(registry)
    several = load_config(registry, overrides=["trial.grasps=2", "trial.until_std_mm=1"])
    several.check_trial(registry)


def test_stages_are_checked_without_being_built(registry, monkeypatch):
    """A pair of parameters that does not go together is refused by the config, naming
    the key; the implementation is not built for it (a sensor's check needs no scene)."""
    bad = load_config(registry, overrides=["segmenter.table-cluster.min_height_m=0.05"])
    built = []
    monkeypatch.setattr(registry, "create", lambda *args: built.append(args))
    with pytest.raises(ConfigError, match=r"'segmenter.table-cluster.min_height_m' is read with"):
        bad.check_stages(registry, ["segmenter"])
    load_config(registry).check_stages(registry, ["sensor", "segmenter", "tactile"])
    assert built == []
    load_config(registry).check_stages(registry, ["world"])  # its own __init__: built
    assert [args[:2] for args in built] == [("world", "pybullet")]


def test_a_commands_defaults_lie_under_files_and_overrides(registry, tmp_path):
    defaults = ("symfuse complete", {"initialiser": {"vc": {"kind": "evidence"}}})
    config = load_config(registry, command_defaults=defaults)
    assert config.stage_params("initialiser").kind == "evidence"
    assert config.changed == {"initialiser.vc.kind": "symfuse complete"}
    # A file (a trial's own config.toml, say) and --set both say otherwise.
    path = tmp_path / "c.toml"
    path.write_text('[initialiser.vc]\nkind = "vertical-plane"\n')
    assert (
        load_config(registry, [path], command_defaults=defaults).stage_params("initialiser").kind
        == "vertical-plane"
    )
    override = ['initialiser.vc.kind="vertical-plane"']
    config = load_config(registry, overrides=override, command_defaults=defaults)
    assert config.stage_params("initialiser").kind == "vertical-plane"
