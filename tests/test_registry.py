"""The plugin manager and stage registry: discovery, selection, attribution of failures."""

from __future__ import annotations

import types
from dataclasses import dataclass

import numpy as np
import pytest

from pipeline import hookimpl
from pipeline.errors import EXIT_PLUGIN_RAISED, ConfigError, PluginError, PluginRaised
from pipeline.params import describe, param
from pipeline.registry import Origin, PluginManager, load_registry
from pipeline.stages import STAGES, Segmenter
from pipeline.types import PointCloud


class Crop(Segmenter):
    """Keep points above a height."""

    name = "crop"

    @dataclass(frozen=True)
    class Params:
        min_z_m: float = param(0.0, "lowest kept height (m)")
        keep_fraction: float = param(1.0, "fraction kept", at_least=0.0, at_most=1.0)

    def segment(self, observation):
        return PointCloud(np.zeros((1, 3)))


class Boom(Segmenter):
    """Always fails."""

    name = "boom"

    def segment(self, observation):
        raise ValueError("kaput")


def plugin_module(*classes):
    module = types.ModuleType("fake_plugin")

    @hookimpl
    def symfuse_register_stages(registry):
        for cls in classes:
            registry.add(cls)

    module.symfuse_register_stages = symfuse_register_stages
    return module


def registry_of(*plugins):
    manager = PluginManager()
    for name, dist, module in plugins:
        manager.register(module, Origin(name, dist, "9.9"))
    return manager.build_registry()


def test_builtins_are_discovered_through_entry_points():
    registry = load_registry()
    for registration in registry.registrations():
        assert registration.origin.distribution == "symfuse"
        assert registration.origin.plugin == registration.name
    # every stage has at least one built-in implementation
    assert all(registry.names(stage) for stage in STAGES)


def test_selection_by_name_builds_typed_params():
    registry = registry_of(("crop", "cropdist", plugin_module(Crop)))
    segmenter = registry.create("segmenter", "crop", {"min_z_m": 1})
    assert segmenter.params == Crop.Params(min_z_m=1.0)
    assert registry.get("segmenter", "crop").origin.distribution == "cropdist"


def test_an_implementation_built_directly_takes_a_mapping_validated_like_a_config():
    assert Crop({"min_z_m": 1}).params == Crop.Params(min_z_m=1.0)
    assert Crop().params == Crop.Params()
    with pytest.raises(ConfigError, match=r"unknown config key 'segmenter\.crop\.min_z'"):
        Crop({"min_z": 1})
    with pytest.raises(ConfigError, match=r"'segmenter\.crop\.min_z_m': expected float"):
        Crop({"min_z_m": "high"})


def test_an_inclusive_upper_bound_admits_its_value_and_nothing_above():
    assert Crop({"keep_fraction": 1.0}).params.keep_fraction == 1.0
    with pytest.raises(ConfigError, match=r"'segmenter\.crop\.keep_fraction': must be <= 1"):
        Crop({"keep_fraction": 1.5})
    with pytest.raises(ConfigError, match="must be <= 1"):
        Crop(Crop.Params(keep_fraction=1.01))
    (info,) = [i for i in describe(Crop.Params) if i.name == "keep_fraction"]
    assert ">= 0, <= 1" in info.type_name


def test_unknown_name_lists_what_is_available():
    registry = registry_of(("crop", "cropdist", plugin_module(Crop)))
    with pytest.raises(PluginError) as error:
        registry.create("segmenter", "voxel-grid")
    assert str(error.value) == (
        "no segmenter named 'voxel-grid' (available: crop; "
        "the plugin providing it may not be installed)"
    )
    with pytest.raises(PluginError, match=r"available: none installed"):
        registry.create("estimator", "iekf")


def test_exception_in_a_stage_names_plugin_and_distribution():
    registry = registry_of(("boom", "boomdist", plugin_module(Boom)))
    segmenter = registry.create("segmenter", "boom")
    with pytest.raises(PluginRaised) as error:
        segmenter.segment(None)
    assert error.value.exit_code == EXIT_PLUGIN_RAISED
    assert str(error.value) == (
        "segmenter 'boom' (plugin 'boom' from distribution 'boomdist 9.9') "
        "failed in segment: ValueError: kaput"
    )
    assert isinstance(error.value.__cause__, ValueError)


def test_exception_while_registering_names_the_plugin():
    module = types.ModuleType("broken")

    @hookimpl
    def symfuse_register_stages(registry):
        raise RuntimeError("missing model file")

    module.symfuse_register_stages = symfuse_register_stages
    manager = PluginManager()
    manager.register(module, Origin("broken", "brokendist", "0.1"))
    with pytest.raises(PluginRaised) as error:
        manager.build_registry()
    assert str(error.value) == (
        "plugin 'broken' from distribution 'brokendist 0.1' failed in "
        "symfuse_register_stages: RuntimeError: missing model file"
    )


def test_duplicate_implementation_names_are_rejected():
    with pytest.raises(PluginError) as error:
        registry_of(("a", "dist-a", plugin_module(Crop)), ("b", "dist-b", plugin_module(Crop)))
    assert "segmenter 'crop' is registered twice" in str(error.value)
    assert "dist-a" in str(error.value) and "dist-b" in str(error.value)


def test_duplicate_plugin_names_are_rejected_not_skipped():
    manager = PluginManager()
    manager.register(plugin_module(Crop), Origin("same", "dist-a", "1"))
    with pytest.raises(PluginError, match="plugin name 'same' is declared twice"):
        manager.register(plugin_module(Boom), Origin("same", "dist-b", "1"))


def test_misspelled_hook_is_an_error():
    module = types.ModuleType("typo")

    @hookimpl
    def symfuse_register_stage(registry):  # missing the final "s"
        pass

    module.symfuse_register_stage = symfuse_register_stage
    manager = PluginManager()
    with pytest.raises(PluginError, match="symfuse_register_stage"):
        manager.register(module, Origin("typo", "typodist", "1"))
        manager.check_hooks()


def test_non_stage_class_is_rejected():
    with pytest.raises(PluginError, match="not a stage implementation"):
        registry_of(("odd", "odddist", plugin_module(dict)))
