"""The plugin manager and the registries it fills.

Plugins (built-in ones included) are found through the ``deepmorph`` entry-point group, loaded
into a :class:`pluggy.PluginManager` and checked (``check_pending``: a misspelled hook is an
error). Each registration hook runs the first time its kinds are looked up, with a
:class:`Register` that owns naming and duplicates: a command that never renders a drawing
never imports the primitives, and ``deepmorph --help`` imports no network.

A plugin may register a class, or declare it by import path with what listings show (a
primitive's kind, tags and morphable parameters, say): the class is imported when first used
and checked then against its declaration, so ``deepmorph list-primitives`` lists every
installed kind without importing torch, and a declaration that drifts from its class is an
error rather than a wrong listing.
"""

from __future__ import annotations

import importlib
import importlib.metadata
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import pluggy

from deepmorph_core import hookspecs
from deepmorph_core.errors import PluginError

if TYPE_CHECKING:
    from deepmorph_core.protocols import Augmentation, Detector, PathSegment, Primitive

ENTRY_POINT_GROUP = "deepmorph"

#: What each category's implementations must define (checked when the class is first used);
#: the protocols themselves are in :mod:`deepmorph_core.protocols`.
_REQUIRED: dict[str, tuple[str, ...]] = {
    "primitive": ("kind", "tags", "priority", "morphable", "from_element", "control_points", "outline", "write"),
    "path-segment": ("kind", "commands", "svgpath_types", "morphable", "from_svgpath", "add_pieces", "flatten", "to_d"),
    "augmentation": ("name", "__call__"),
    "detector": ("name", "from_model", "detect"),
}

#: What a category's registration states up front (the key first): what listings show.
_DECLARED: dict[str, tuple[str, ...]] = {
    "primitive": ("kind", "tags", "morphable"),
    "path-segment": ("kind", "commands", "morphable"),
    "augmentation": ("name",),
    "detector": ("name",),
}

#: Registry table -> the registration hook that fills it.
_HOOK_OF_TABLE = {
    "primitives": "deepmorph_register_primitives",
    "path_segments": "deepmorph_register_primitives",
    "augmentations": "deepmorph_register_augmentations",
    "detectors": "deepmorph_register_detectors",
}


class Registration:
    """One registered kind and where it came from.

    Attributes:
        category: ``"primitive"``, ``"path-segment"``, ``"augmentation"`` or ``"detector"``.
        key: its kind or name.
        info: what it declared (``kind``, ``tags``, ``commands``, ``morphable``, ``name``: see
            ``_DECLARED``), known without importing the class.
        plugin: the plugin that registered it.
        distribution: ``"name version"`` of the distribution that installed the plugin, or
            ``None`` when it was not installed from one.
    """

    def __init__(self, category: str, info: dict[str, Any], target: type | str, plugin: str,
                 distribution: str | None):  # fmt: skip
        self.category = category
        self.key: str = info[_DECLARED[category][0]]
        self.info = info
        self.plugin = plugin
        self.distribution = distribution
        self._target = target
        self._obj: type | None = target if isinstance(target, type) else None

    @property
    def loaded(self) -> bool:
        """Whether the class is imported (registered as a class, or used since)."""
        return self._obj is not None

    @property
    def obj(self) -> Any:
        """The class, imported and checked against its declaration on first use.

        Raises:
            PluginError: it cannot be imported, lacks part of its protocol, or differs from
                what the plugin declared; the message names the plugin.
        """
        if self._obj is None:
            cls = _import_target(str(self._target), self._where)
            _check_class(cls, self.category, self._where)
            for name, declared in self.info.items():
                actual = getattr(cls, name)
                if actual != declared:
                    raise PluginError(
                        f"{self._where}: declared with {name}={declared!r}, but {self._target} has {name}={actual!r}"
                    )
            self._obj = cls
        return self._obj

    @property
    def _where(self) -> str:
        return f"plugin {self.plugin!r}: {self.category} {self.key!r}"

    def __repr__(self) -> str:
        return f"Registration({self.category} {self.key!r} from {self.plugin!r})"


def _import_target(target: str, where: str) -> type:
    module, _, attr = target.partition(":")
    try:
        obj: Any = importlib.import_module(module)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except Exception as exc:  # any import failure is the plugin's, reported by name
        raise PluginError(f"{where}: cannot import {target}: {exc}") from None
    if not isinstance(obj, type):
        raise PluginError(f"{where}: {target} is not a class")
    return obj


def _check_class(cls: Any, category: str, where: str) -> None:
    if not isinstance(cls, type):
        raise PluginError(f"{where} must be a class, got {cls!r}")
    missing = [name for name in _REQUIRED[category] if not hasattr(cls, name)]
    if missing:
        raise PluginError(f"{where}: {cls.__name__} lacks {', '.join(sorted(missing))}")


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
        """Primitive classes reading the element ``tag``, highest priority first (only these
        are imported)."""
        found = [r.obj for r in self.primitives.values() if tag in r.info["tags"]]
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

    @property
    def plugins(self) -> dict[str, str | None]:
        """Every loaded plugin's name -> ``"name version"`` of its distribution (``None``: given
        directly, not installed from one)."""
        return {name: self._distributions.get(name) for name, _ in self.plugin_manager.list_name_plugin()}

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
    """Handed to registration hooks; checks what a plugin registers and names it in errors.

    Each method takes a class, or the class's import path ``"package.module:Class"`` together
    with what listings show (keywords named after the class attributes): the class is then
    imported only when first used, and checked against these values then.
    """

    def __init__(self, registry: Registry, plugin: str, distribution: str | None):
        self._tables = registry._tables
        self._plugin = plugin
        self._distribution = distribution

    def _registration(self, category: str, target: Any, declared: dict[str, Any]) -> Registration:
        names = _DECLARED[category]
        given = {k: v for k, v in declared.items() if v is not None}
        if isinstance(target, str):
            if ":" not in target or not all(target.partition(":")[::2]):
                raise PluginError(f'plugin {self._plugin!r}: {category} {target!r}: expected "package.module:Class"')
            missing = [f"{k}=" for k in names if k not in given]
            if missing:
                raise PluginError(
                    f"plugin {self._plugin!r}: {category} {target!r} is registered by import path, so it needs "
                    f"{', '.join(missing)} (what listings show without importing it)"
                )
            info = {k: given[k] for k in names}
        else:
            _check_class(target, category, f"plugin {self._plugin!r}: {category}")
            if given:
                raise PluginError(
                    f"plugin {self._plugin!r}: {category} {target.__name__}: {', '.join(given)} are read from the "
                    "class; declare them only when registering by import path"
                )
            info = {k: getattr(target, k) for k in names}
        key = info[names[0]]
        if not isinstance(key, str) or not key:
            raise PluginError(f"plugin {self._plugin!r}: {category} {target!r} has no valid {names[0]}")
        return Registration(category, info, target, self._plugin, self._distribution)

    def _add(self, table: str, reg: Registration) -> None:
        entries = self._tables[table]
        if reg.key in entries:
            other = entries[reg.key].plugin
            raise PluginError(
                f"plugin {self._plugin!r}: {reg.category} kind {reg.key!r} is already registered by plugin {other!r}"
            )
        entries[reg.key] = reg

    def primitive(self, cls: type[Primitive] | str, *, kind: str | None = None, tags: tuple[str, ...] | None = None,
                  morphable: str | None = None) -> None:  # fmt: skip
        """Register a primitive kind (keyed by ``kind``)."""
        reg = self._registration("primitive", cls, {"kind": kind, "tags": tags, "morphable": morphable})
        if not isinstance(reg.info["tags"], tuple) or not all(isinstance(t, str) for t in reg.info["tags"]):
            raise PluginError(f"plugin {self._plugin!r}: primitive {reg.key!r}: tags must be a tuple of str")
        self._add("primitives", reg)

    def path_segment(self, cls: type[PathSegment] | str, *, kind: str | None = None, commands: str | None = None,
                     morphable: str | None = None) -> None:  # fmt: skip
        """Register a path-segment kind (keyed by ``kind``); its command letters must be new."""
        reg = self._registration("path-segment", cls, {"kind": kind, "commands": commands, "morphable": morphable})
        taken = {c: r for r in self._tables["path_segments"].values() for c in r.info["commands"]}
        for letter in reg.info["commands"]:
            if letter in taken:
                raise PluginError(
                    f"plugin {self._plugin!r}: path command {letter!r} of {reg.key!r} is already "
                    f"handled by {taken[letter].key!r} from plugin {taken[letter].plugin!r}"
                )
        self._add("path_segments", reg)

    def augmentation(self, cls: type[Augmentation] | str, *, name: str | None = None) -> None:
        """Register a capture corruption (keyed by ``name``)."""
        self._add("augmentations", self._registration("augmentation", cls, {"name": name}))

    def detector(self, cls: type[Detector] | str, *, name: str | None = None) -> None:
        """Register a detector (keyed by ``name``)."""
        self._add("detectors", self._registration("detector", cls, {"name": name}))


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
