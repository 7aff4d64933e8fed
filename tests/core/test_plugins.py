"""The plugin spine: built-ins register through the entry point like anyone else; mistakes in
plugins are clear errors naming the plugin."""

from __future__ import annotations

import importlib.metadata
import types

import pytest

import deepmorph_primitives.plugin as builtin_plugin
from deepmorph_core import hookimpl
from deepmorph_core.errors import PluginError
from deepmorph_core.plugins import load_registry
from deepmorph_primitives.circle import Circle


def plugin_module(name: str, **hooks) -> types.ModuleType:
    mod = types.ModuleType(name)
    for key, fn in hooks.items():
        setattr(mod, key, fn)
    return mod


def test_builtins_are_an_ordinary_entry_point() -> None:
    eps = {ep.name: ep.value for ep in importlib.metadata.entry_points(group="deepmorph")}
    assert eps.get("builtin_primitives") == "deepmorph_primitives.plugin"
    reg = load_registry()  # from the installed entry points only
    assert reg.primitives["circle"].plugin == "builtin_primitives"
    assert reg.primitives["circle"].distribution.startswith("deepmorph ")
    assert eps.get("builtin_detectors") == "deepmorph_detect.plugin"
    assert reg.detectors["centrenet"].plugin == "builtin_detectors"


def test_registry_contents(builtin_registry) -> None:
    assert set(builtin_registry.primitives) == {
        "line",
        "polyline",
        "polygon",
        "rect",
        "circle",
        "ellipse",
        "path",
        "half-circle",
    }
    assert set(builtin_registry.path_segments) == {"path-line", "path-arc"}
    assert [c.kind for c in builtin_registry.primitives_for_tag("path")] == ["half-circle", "path"]


def test_duplicate_kind_names_both_plugins() -> None:
    @hookimpl
    def deepmorph_register_primitives(register):
        register.primitive(Circle)

    rogue = plugin_module("rogue_circles", deepmorph_register_primitives=deepmorph_register_primitives)
    registry = load_registry([builtin_plugin, rogue], entry_points=False)  # registration waits for a look-up
    for _ in range(2):  # and fails at every look-up: a table is never left half full
        with pytest.raises(PluginError, match="'rogue_circles'.*'circle' is already registered by plugin"):
            _ = registry.primitives


def test_misspelled_hook_is_an_error() -> None:
    @hookimpl
    def deepmorph_register_primitive(register):  # missing "s"
        pass

    typo = plugin_module("typo_plugin", deepmorph_register_primitive=deepmorph_register_primitive)
    with pytest.raises(PluginError, match="typo_plugin.*misspelled"):
        load_registry([builtin_plugin, typo], entry_points=False)


def test_invalid_primitive_class_is_an_error() -> None:
    class Half:
        kind = "half"
        tags = ("half",)

    @hookimpl
    def deepmorph_register_primitives(register):
        register.primitive(Half)

    bad = plugin_module("bad_plugin", deepmorph_register_primitives=deepmorph_register_primitives)
    with pytest.raises(PluginError, match="bad_plugin.*Half lacks"):
        _ = load_registry([bad], entry_points=False).primitives


def test_path_command_conflict_is_an_error() -> None:
    from deepmorph_primitives.segments import ArcSegment

    class OtherArc(ArcSegment):
        kind = "other-arc"

    @hookimpl
    def deepmorph_register_primitives(register):
        register.path_segment(OtherArc)

    clash = plugin_module("clash", deepmorph_register_primitives=deepmorph_register_primitives)
    with pytest.raises(PluginError, match="path command 'A' of 'other-arc' is already handled by 'path-arc'"):
        _ = load_registry([builtin_plugin, clash], entry_points=False).path_segments


def test_broken_entry_point_is_reported_by_name(monkeypatch) -> None:
    real = importlib.metadata.entry_points

    def fake(group=None, **kw):
        eps = list(real(group=group, **kw))
        return eps + [importlib.metadata.EntryPoint("broken", "no_such_module_xyz", "deepmorph")]

    monkeypatch.setattr(importlib.metadata, "entry_points", fake)
    with pytest.raises(PluginError, match="plugin 'broken' .* failed to load"):
        load_registry()
