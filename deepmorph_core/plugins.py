"""The plugin manager and the registries it fills.

Plugins (built-in ones included) are found through the ``deepmorph`` entry-point group, loaded
into a :class:`pluggy.PluginManager`, checked (``check_pending``: a misspelled hook is an error),
and asked to register their kinds through a :class:`Register` that owns naming and duplicates.
"""

from __future__ import annotations

import importlib.metadata
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import pluggy

from deepmorph_core import hookspecs
from deepmorph_core.errors import PluginError
from deepmorph_core.protocols import Augmentation, Detector, PathSegment, Primitive

ENTRY_POINT_GROUP = "deepmorph"

#: What each protocol's implementations must define (checked at registration).
_REQUIRED: dict[type, tuple[str, ...]] = {
    Primitive: ("kind", "tags", "priority", "morphable", "from_element", "control_points", "outline", "sdf", "write"),
    PathSegment: ("kind", "commands", "svgpath_types", "morphable", "from_svgpath", "add_pieces", "flatten", "to_d"),
    Augmentation: ("name", "__call__"),
    Detector: ("name", "detect"),
}


@dataclass(frozen=True)
class Registration:
    """One registered kind and where it came from."""

    category: str  # "primitive" | "path-segment" | "augmentation" | "detector"
    key: str
    obj: Any
    plugin: str
    distribution: str | None  # "name version", or None when not installed from a distribution


@dataclass
class Registry:
    """Everything the loaded plugins registered, keyed by kind or name."""

    primitives: dict[str, Registration] = field(default_factory=dict)
    path_segments: dict[str, Registration] = field(default_factory=dict)
    augmentations: dict[str, Registration] = field(default_factory=dict)
    detectors: dict[str, Registration] = field(default_factory=dict)
    plugin_manager: pluggy.PluginManager | None = None

    def primitives_for_tag(self, tag: str) -> list[type[Primitive]]:
        """Primitive classes reading the element ``tag``, highest priority first."""
        found = [r.obj for r in self.primitives.values() if tag in r.obj.tags]
        return sorted(found, key=lambda c: -int(getattr(c, "priority", 0)))

    def segment_for(self, svgpath_segment: Any) -> type[PathSegment] | None:
        """The registered path-segment class converting this ``svg.path`` segment, if any."""
        for reg in self.path_segments.values():
            if isinstance(svgpath_segment, reg.obj.svgpath_types):
                return reg.obj
        return None

    def all(self) -> list[Registration]:
        """Every registration, primitives first."""
        return [
            *self.primitives.values(),
            *self.path_segments.values(),
            *self.augmentations.values(),
            *self.detectors.values(),
        ]


class Register:
    """Handed to registration hooks; checks what a plugin registers and names it in errors."""

    def __init__(self, registry: Registry, plugin: str, distribution: str | None):
        self._registry = registry
        self._plugin = plugin
        self._distribution = distribution

    def _add(self, table: dict[str, Registration], category: str, key: Any, obj: Any) -> None:
        if not isinstance(key, str) or not key:
            raise PluginError(f"plugin {self._plugin!r}: {category} {obj!r} has no valid name/kind")
        if key in table:
            other = table[key].plugin
            raise PluginError(
                f"plugin {self._plugin!r}: {category} kind {key!r} is already registered by plugin {other!r}"
            )
        table[key] = Registration(category, key, obj, self._plugin, self._distribution)

    def _check(self, obj: Any, protocol: type, category: str) -> None:
        if not isinstance(obj, type):
            raise PluginError(f"plugin {self._plugin!r}: {category} must be a class, got {obj!r}")
        missing = [name for name in _REQUIRED[protocol] if not hasattr(obj, name)]
        if missing:
            raise PluginError(f"plugin {self._plugin!r}: {category} {obj.__name__} lacks {', '.join(sorted(missing))}")

    def primitive(self, cls: type[Primitive]) -> None:
        """Register a primitive kind (keyed by ``cls.kind``)."""
        self._check(cls, Primitive, "primitive")
        if not isinstance(cls.tags, tuple) or not all(isinstance(t, str) for t in cls.tags):
            raise PluginError(f"plugin {self._plugin!r}: primitive {cls.__name__}.tags must be a tuple of str")
        self._add(self._registry.primitives, "primitive", cls.kind, cls)

    def path_segment(self, cls: type[PathSegment]) -> None:
        """Register a path-segment kind (keyed by ``cls.kind``); its command letters must be new."""
        self._check(cls, PathSegment, "path segment")
        taken = {c: r for r in self._registry.path_segments.values() for c in r.obj.commands}
        for letter in cls.commands:
            if letter in taken:
                raise PluginError(
                    f"plugin {self._plugin!r}: path command {letter!r} of {cls.kind!r} is already "
                    f"handled by {taken[letter].key!r} from plugin {taken[letter].plugin!r}"
                )
        self._add(self._registry.path_segments, "path-segment", cls.kind, cls)

    def augmentation(self, cls: type[Augmentation]) -> None:
        """Register a capture corruption (keyed by ``cls.name``)."""
        self._check(cls, Augmentation, "augmentation")
        self._add(self._registry.augmentations, "augmentation", cls.name, cls)

    def detector(self, cls: type[Detector]) -> None:
        """Register a detector (keyed by ``cls.name``)."""
        self._check(cls, Detector, "detector")
        self._add(self._registry.detectors, "detector", cls.name, cls)


def _distribution_label(dist: importlib.metadata.Distribution | None) -> str | None:
    if dist is None:
        return None
    return f"{dist.metadata['Name']} {dist.version}"


def load_registry(plugins: Iterable[Any] = (), *, entry_points: bool = True) -> Registry:
    """Build a registry from installed entry points and/or explicitly given plugin modules.

    Args:
        plugins: plugin modules or objects to register directly (tests use this with
            ``entry_points=False`` so that nothing installed leaks in).
        entry_points: also load every plugin in the ``deepmorph`` entry-point group.

    Raises:
        PluginError: a plugin fails to import, implements an unknown hook, or registers an
            invalid or duplicate kind. The message names the plugin.
    """
    pm = pluggy.PluginManager(hookspecs.PROJECT)
    pm.add_hookspecs(hookspecs)
    distributions: dict[str, str | None] = {}

    def add(plugin: Any, name: str, dist: str | None) -> None:
        try:
            pm.register(plugin, name=name)
        except pluggy.PluginValidationError as exc:
            raise PluginError(f"plugin {name!r}: {exc}") from None
        except ValueError as exc:  # duplicate plugin name or object
            raise PluginError(f"plugin {name!r}: {exc}") from None
        distributions[name] = dist

    for plugin in plugins:
        add(plugin, getattr(plugin, "__name__", repr(plugin)), None)
    if entry_points:
        for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
            if pm.has_plugin(ep.name):
                continue
            try:
                obj = ep.load()
            except Exception as exc:  # any import failure is the plugin's, reported by name
                raise PluginError(f"plugin {ep.name!r} ({ep.value}) failed to load: {exc}") from None
            add(obj, ep.name, _distribution_label(ep.dist))
    try:
        pm.check_pending()
    except pluggy.PluginValidationError as exc:
        name = pm.get_name(exc.plugin) if exc.plugin is not None else "?"
        raise PluginError(f"plugin {name!r}: {exc} (misspelled hook name?)") from None

    registry = Registry(plugin_manager=pm)
    for caller in (
        pm.hook.deepmorph_register_primitives,
        pm.hook.deepmorph_register_augmentations,
        pm.hook.deepmorph_register_detectors,
    ):
        for impl in caller.get_hookimpls():
            register = Register(registry, impl.plugin_name, distributions.get(impl.plugin_name))
            impl.function(register=register)
    return registry


_default: Registry | None = None


def default_registry() -> Registry:
    """The registry of every installed plugin, loaded once per process."""
    global _default
    if _default is None:
        _default = load_registry()
    return _default


def set_default_registry(registry: Registry | None) -> None:
    """Replace (or with ``None`` reset) the process-wide registry; used by tests and embedders."""
    global _default
    _default = registry
