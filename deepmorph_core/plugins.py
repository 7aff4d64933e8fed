"""The plugin manager and the registries it fills.

Plugins (built-in ones included) are found through the ``deepmorph`` entry-point group, loaded
into a :class:`pluggy.PluginManager` and checked (``check_pending``: a misspelled hook is an
error). Each registration hook runs the first time its kinds are looked up, with a
:class:`Register` that owns naming and duplicates: a command that never renders a drawing
never imports the primitives, and ``deepmorph --help`` imports no network.
"""

from __future__ import annotations

import importlib.metadata
from collections.abc import Iterable
from dataclasses import dataclass
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
    Detector: ("name", "from_model", "detect"),
}

#: Registry table -> the registration hook that fills it.
_HOOK_OF_TABLE = {
    "primitives": "deepmorph_register_primitives",
    "path_segments": "deepmorph_register_primitives",
    "augmentations": "deepmorph_register_augmentations",
    "detectors": "deepmorph_register_detectors",
}


@dataclass(frozen=True)
class Registration:
    """One registered kind and where it came from."""

    category: str  # "primitive" | "path-segment" | "augmentation" | "detector"
    key: str
    obj: Any
    plugin: str
    distribution: str | None  # "name version", or None when not installed from a distribution


class Registry:
    """Everything the loaded plugins registered, keyed by kind or name.

    Each table is filled by its registration hook the first time it is read; a plugin error
    in that hook is raised then (and again at every later read: a table is never half full).

    Args:
        plugin_manager: the loaded and checked plugin manager.
        distributions: plugin name -> ``"name version"`` of the distribution that installed it.
    """

    def __init__(self, plugin_manager: pluggy.PluginManager, distributions: dict[str, str | None] | None = None):
        self.plugin_manager = plugin_manager
        self._distributions = distributions or {}
        self._tables: dict[str, dict[str, Registration]] = {name: {} for name in _HOOK_OF_TABLE}
        self._called: set[str] = set()

    def _table(self, name: str) -> dict[str, Registration]:
        hook = _HOOK_OF_TABLE[name]
        if hook not in self._called:
            try:
                for impl in getattr(self.plugin_manager.hook, hook).get_hookimpls():
                    plugin = impl.plugin_name
                    impl.function(register=Register(self, plugin, self._distributions.get(plugin)))
            except BaseException:
                for table, table_hook in _HOOK_OF_TABLE.items():
                    if table_hook == hook:
                        self._tables[table].clear()
                raise
            self._called.add(hook)
        return self._tables[name]

    @property
    def primitives(self) -> dict[str, Registration]:
        """Primitive kinds by ``kind``."""
        return self._table("primitives")

    @property
    def path_segments(self) -> dict[str, Registration]:
        """Path-segment kinds by ``kind``."""
        return self._table("path_segments")

    @property
    def augmentations(self) -> dict[str, Registration]:
        """Capture corruptions by ``name``."""
        return self._table("augmentations")

    @property
    def detectors(self) -> dict[str, Registration]:
        """Drawing detectors by ``name``."""
        return self._table("detectors")

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

    def detector(self, name: str) -> type[Detector]:
        """The detector class registered as ``name``.

        Raises:
            PluginError: no detector of that name, naming the ones there are.
        """
        found = self.detectors.get(name)
        if found is None:
            known = ", ".join(sorted(self.detectors)) or "none"
            raise PluginError(f"no detector {name!r} is installed (installed: {known})")
        return found.obj

    def all(self) -> list[Registration]:
        """Every registration, primitives first."""
        return [*self.primitives.values(), *self.path_segments.values(), *self.augmentations.values(),
                *self.detectors.values()]  # fmt: skip

    def register_commands(self, cli: Any) -> None:
        """Let every plugin add its commands to the command line ``cli`` (a ``typer.Typer``)."""
        self.plugin_manager.hook.deepmorph_register_commands(cli=cli)

    def validate_model(self, model: Any, samples: int, seed: int) -> list[Any]:
        """Every plugin's validation of a trained model (``ValidationRecord`` s, in plugin order).

        Raises:
            PluginError: a plugin returned something other than a validation record.
        """
        from deepmorph_core.bundle import ValidationRecord

        records = []
        for impl in self.plugin_manager.hook.deepmorph_validate_model.get_hookimpls():
            record = impl.function(model=model, samples=samples, seed=seed)
            if record is None:
                continue
            if not isinstance(record, ValidationRecord):
                got = type(record).__name__
                got = type(record).__name__
                raise PluginError(f"plugin {impl.plugin_name!r}: deepmorph_validate_model returned a {got}")
            records.append(record)
        return records


class Register:
    """Handed to registration hooks; checks what a plugin registers and names it in errors."""

    def __init__(self, registry: Registry, plugin: str, distribution: str | None):
        self._tables = registry._tables
        self._plugin = plugin
        self._distribution = distribution

    def _add(self, table: str, category: str, key: Any, obj: Any) -> None:
        entries = self._tables[table]
        if not isinstance(key, str) or not key:
            raise PluginError(f"plugin {self._plugin!r}: {category} {obj!r} has no valid name/kind")
        if key in entries:
            other = entries[key].plugin
            raise PluginError(
                f"plugin {self._plugin!r}: {category} kind {key!r} is already registered by plugin {other!r}"
            )
        entries[key] = Registration(category, key, obj, self._plugin, self._distribution)

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
        self._add("primitives", "primitive", cls.kind, cls)

    def path_segment(self, cls: type[PathSegment]) -> None:
        """Register a path-segment kind (keyed by ``cls.kind``); its command letters must be new."""
        self._check(cls, PathSegment, "path segment")
        taken = {c: r for r in self._tables["path_segments"].values() for c in r.obj.commands}
        for letter in cls.commands:
            if letter in taken:
                raise PluginError(
                    f"plugin {self._plugin!r}: path command {letter!r} of {cls.kind!r} is already "
                    f"handled by {taken[letter].key!r} from plugin {taken[letter].plugin!r}"
                )
        self._add("path_segments", "path-segment", cls.kind, cls)

    def augmentation(self, cls: type[Augmentation]) -> None:
        """Register a capture corruption (keyed by ``cls.name``)."""
        self._check(cls, Augmentation, "augmentation")
        self._add("augmentations", "augmentation", cls.name, cls)

    def detector(self, cls: type[Detector]) -> None:
        """Register a detector (keyed by ``cls.name``)."""
        self._check(cls, Detector, "detector")
        self._add("detectors", "detector", cls.name, cls)


def _distribution_label(dist: importlib.metadata.Distribution | None) -> str | None:
    if dist is None:
        return None
    return f"{dist.metadata['Name']} {dist.version}"


def load_registry(plugins: Iterable[Any] = (), *, entry_points: bool = True) -> Registry:
    """Build a registry from installed entry points and/or explicitly given plugin modules.

    Loading imports the plugin modules and checks their hook names; what they register is
    asked for when first looked up (:class:`Registry`).

    Args:
        plugins: plugin modules or objects to register directly (tests use this with
            ``entry_points=False`` so that nothing installed leaks in).
        entry_points: also load every plugin in the ``deepmorph`` entry-point group.

    Raises:
        PluginError: a plugin fails to import, or implements an unknown hook. The message
            names the plugin.
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
    return Registry(pm, distributions)


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
