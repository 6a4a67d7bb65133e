"""The registry of each pluggable kind (frontiernet/registry.py): built-in entries, entry points
read when names are asked for and imported when one is used, one-line errors listing the names."""

from __future__ import annotations

import importlib.metadata

import pytest

from frontiernet.errors import InputError
from frontiernet.registry import Registry

GROUP = "frontiernet.test-kind"


@pytest.fixture()
def plugins(monkeypatch):
    """Two entry points of GROUP: ``double`` (this module's `double`) and ``broken`` (no module)."""
    real = importlib.metadata.entry_points
    entries = [importlib.metadata.EntryPoint("double", "test_registry:double", GROUP),
               importlib.metadata.EntryPoint("broken", "no_such_module_here:thing", GROUP),
               importlib.metadata.EntryPoint("one", "test_registry:double", GROUP)]
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda **kw: entries if kw.get("group") == GROUP else real(**kw))


def double(x):
    return 2 * x


def one(x):
    return 1


def test_built_in_entries_come_first_and_win_over_plugins_of_their_name(plugins):
    registry = Registry("test kind", GROUP, {"one": one, "zero": lambda x: 0})
    assert registry.names() == ["one", "zero", "broken", "double"]
    assert "double" in registry and "triple" not in registry
    assert registry.get("one") is one and registry.get("double")(3) == 6


def test_an_unknown_name_is_one_line_listing_every_name(plugins):
    registry = Registry("test kind", GROUP, {"one": one})
    with pytest.raises(InputError, match=r"^test kind 'triple' is unknown; valid: one, broken, double$"):
        registry.get("triple")
    with pytest.raises(InputError, match=r"^m.xyz: model format 'xyz' is unknown; valid: one, broken, double$"):
        registry.get("xyz", label="m.xyz: model format")


def test_a_plugin_is_imported_only_when_used_and_a_broken_one_is_left_out_of_load_all(plugins, caplog):
    registry = Registry("test kind", GROUP, {"one": one})
    assert "broken" in registry.names()  # named without importing it
    with pytest.raises(ModuleNotFoundError):
        registry.get("broken")
    assert registry.load_all() == [one, double]
    assert "test kind 'broken' (no_such_module_here:thing) failed to load" in caplog.text


def test_a_kind_without_a_group_has_its_built_in_entries_only():
    registry = Registry("scene source", None, {"mesh": one})
    assert registry.names() == ["mesh"] and registry.plugins() == {}
    with pytest.raises(InputError, match="scene source 'usd' is unknown; valid: mesh"):
        registry.get("usd")


def test_every_kind_has_its_registry():
    from frontiernet.cli.bench import BENCH_ACTIONS
    from frontiernet.cli.main import COMMANDS
    from frontiernet.depth import DEPTH_SOURCES
    from frontiernet.model.predictor import RUNTIMES, Predictor
    from frontiernet.scenes.spec import SCENE_SOURCES, SOURCES

    assert {"scene", "explore", "bench", "datagen", "train", "deploy"} <= set(COMMANDS.names())
    assert "inference" in BENCH_ACTIONS.names()
    assert RUNTIMES.get("safetensors") is Predictor and {"onnx", "pt"} <= set(RUNTIMES.names())
    assert DEPTH_SOURCES.names()[:2] == ["ground_truth", "emulated"]
    assert tuple(SCENE_SOURCES.names()) == SOURCES == ("mesh", "hm3d", "floorplan", "procedural")
