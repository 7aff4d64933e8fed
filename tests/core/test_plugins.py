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


def test_kinds_declared_by_import_path_are_listed_without_importing_them(builtin_registry) -> None:
    """The built-in kinds are declared by import path: listing them (what ``list-primitives``
    shows) imports no class; using one imports it, checked against its declaration."""
    for reg in [*builtin_registry.primitives.values(), *builtin_registry.path_segments.values()]:
        assert not reg.loaded and reg.info["morphable"]
    assert builtin_registry.primitives["circle"].info["tags"] == ("circle",)
    assert builtin_registry.primitives["circle"].obj is Circle
    assert builtin_registry.primitives["circle"].loaded and not builtin_registry.primitives["rect"].loaded


def test_every_declaration_matches_its_class(builtin_registry, bezier_registry) -> None:
    """What each installed plugin declares is what its class says (resolving checks it)."""
    for registry in (builtin_registry, bezier_registry):
        for reg in registry.all():
            cls = reg.obj
            assert all(getattr(cls, name) == value for name, value in reg.info.items()), reg


def _declaring(name: str, **declared):
    @hookimpl
    def deepmorph_register_primitives(register):
        register.primitive(declared.pop("path"), **declared)

    return plugin_module(name, deepmorph_register_primitives=deepmorph_register_primitives)


def test_a_declaration_that_drifts_from_its_class_is_an_error_naming_the_plugin() -> None:
    drifted = _declaring(
        "drifted", path="deepmorph_primitives.circle:Circle", kind="circle", tags=("circle", "disc"), morphable="x"
    )
    registry = load_registry([drifted], entry_points=False)
    assert registry.primitives["circle"].info["tags"] == ("circle", "disc")  # listed as declared ...
    with pytest.raises(PluginError, match=r"'drifted': primitive 'circle': declared with tags=\('circle', 'disc'\)"):
        _ = registry.primitives["circle"].obj  # ... refused once used


@pytest.mark.parametrize(
    ("declared", "message"),
    [
        ({"path": "no_such_module_xyz:Star", "kind": "star", "tags": ("star",), "morphable": "x"},
         r"'star': cannot import no_such_module_xyz:Star"),
        ({"path": "deepmorph_primitives.circle:Nope", "kind": "star", "tags": ("star",), "morphable": "x"},
         "cannot import deepmorph_primitives.circle:Nope"),
        ({"path": "deepmorph_primitives.circle", "kind": "star", "tags": ("star",), "morphable": "x"},
         'expected "package.module:Class"'),
        ({"path": "deepmorph_primitives.circle:Circle", "kind": "circle"}, "needs tags=, morphable="),
        ({"path": Circle, "kind": "circle"}, "are read from the class"),
    ],
)  # fmt: skip
def test_bad_declarations_are_clear_errors(declared: dict, message: str) -> None:
    registry = load_registry([_declaring("odd", **declared)], entry_points=False)
    with pytest.raises(PluginError, match=message):
        for reg in registry.primitives.values():
            _ = reg.obj


def test_a_primitive_needs_an_outline_and_no_sdf_of_its_own() -> None:
    """The registry asks of a primitive what the rasterizer consumes: its outline."""
    from deepmorph_primitives.line import Line

    members = {k: getattr(Line, k) for k in ("from_element", "control_points", "outline", "write")}
    Outlined = type(
        "Outlined", (), {"kind": "outlined", "tags": ("outlined",), "priority": 0, "morphable": "x", **members}
    )
    NoOutline = type("NoOutline", (), {"kind": "no-outline", "tags": ("no-outline",), "priority": 0, "morphable": "x",
                                       **{k: v for k, v in members.items() if k != "outline"}})  # fmt: skip
    assert not hasattr(Outlined, "sdf")

    @hookimpl
    def deepmorph_register_primitives(register):
        register.primitive(Outlined)

    good = plugin_module("outlined_plugin", deepmorph_register_primitives=deepmorph_register_primitives)
    assert "outlined" in load_registry([good], entry_points=False).primitives

    @hookimpl
    def deepmorph_register_primitives(register):  # noqa: F811
        register.primitive(NoOutline)

    bad = plugin_module("no_outline_plugin", deepmorph_register_primitives=deepmorph_register_primitives)
    with pytest.raises(PluginError, match="NoOutline lacks.*outline"):
        _ = load_registry([bad], entry_points=False).primitives
