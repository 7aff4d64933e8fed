"""Hook specifications: the whole plugin surface of DeepMorph.

Every hook is ``deepmorph_<something>``. Registration hooks receive a register object owned
by the host (llm's and tox's habit), so that naming, duplicate detection and error messages
live in one place (:mod:`deepmorph_core.plugins`) rather than in each plugin.

A plugin is a module (or object) exposed under the ``deepmorph`` entry-point group::

    [project.entry-points.deepmorph]
    my_plugin = "my_package.plugin"

whose functions are decorated with :data:`deepmorph_core.hookimpl`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from deepmorph_core.plugins import Register

PROJECT = "deepmorph"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def deepmorph_register_primitives(register: Register) -> None:
    """Register primitive kinds and path-segment kinds.

    Called once when the plugin manager loads. Call ``register.primitive(cls)`` for each class
    implementing :class:`~deepmorph_core.protocols.Primitive` and ``register.path_segment(cls)``
    for each implementing :class:`~deepmorph_core.protocols.PathSegment`. A kind already
    registered by another plugin is an error naming both plugins.
    """


@hookspec
def deepmorph_register_augmentations(register: Register) -> None:
    """Register capture corruptions.

    Call ``register.augmentation(cls)`` for each class implementing
    :class:`~deepmorph_core.protocols.Augmentation`; keyed by ``cls.name``.
    """


@hookspec
def deepmorph_register_detectors(register: Register) -> None:
    """Register drawing detectors.

    Call ``register.detector(cls)`` for each class implementing
    :class:`~deepmorph_core.protocols.Detector`; keyed by ``cls.name``.
    """
