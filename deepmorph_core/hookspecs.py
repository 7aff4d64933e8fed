"""Hook specifications: the whole plugin surface of DeepMorph.

Every hook is ``deepmorph_<something>``. Registration hooks receive a register object owned
by the host (llm's and tox's habit), so that naming, duplicate detection and error messages
live in one place (:mod:`deepmorph_core.plugins`) rather than in each plugin.

A plugin is a module (or object) exposed under the ``deepmorph`` entry-point group::

    [project.entry-points.deepmorph]
    my_plugin = "my_package.plugin"

whose functions are decorated with :data:`deepmorph_core.hookimpl`. A plugin module should
import its heavy parts (torch, its classes) inside its hook functions: every ``deepmorph``
command loads every plugin module, and ``deepmorph --help`` should not wait for torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    import typer

    from deepmorph_core.bundle import ValidationRecord
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.plugins import Register

PROJECT = "deepmorph"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def deepmorph_register_primitives(register: Register) -> None:
    """Register primitive kinds and path-segment kinds.

    Called once, the first time primitives or path segments are looked up. Call
    ``register.primitive(cls)`` for each class implementing
    :class:`~deepmorph_core.protocols.Primitive` and ``register.path_segment(cls)`` for each
    implementing :class:`~deepmorph_core.protocols.PathSegment`, or pass the class's import path
    with what listings show (``register.primitive("pkg.mod:Star", kind="star", tags=("star",),
    morphable="...")``) so that listing kinds does not import it. A kind already registered by
    another plugin is an error naming both plugins.
    """


@hookspec
def deepmorph_register_augmentations(register: Register) -> None:
    """Register capture corruptions.

    Called once, the first time augmentations are looked up. Call ``register.augmentation(cls)``
    for each class implementing :class:`~deepmorph_core.protocols.Augmentation`; keyed by
    ``cls.name``.
    """


@hookspec
def deepmorph_register_detectors(register: Register) -> None:
    """Register drawing detectors (what proposes where a drawing may be in a photo).

    Called once, the first time detectors are looked up. Call ``register.detector(cls)`` for
    each class implementing :class:`~deepmorph_core.protocols.Detector`; keyed by ``cls.name``.
    The photo chain uses the detector a model bundle names (``centrenet`` by default), or the
    one a caller asks for by name.
    """


@hookspec
def deepmorph_register_commands(cli: typer.Typer) -> None:
    """Add commands to the ``deepmorph`` command line.

    Called once when the command line starts, with the :class:`typer.Typer` application:
    decorate functions with ``cli.command()``. Import what a command needs inside the command,
    not at the top of the plugin module, so that ``deepmorph --help`` stays fast. A command
    reports a failure by raising :class:`~deepmorph_core.errors.DeepMorphError`, which the
    command line prints as one ``error:`` line with exit status 1.
    """


@hookspec
def deepmorph_validate_model(model: DeepMorphModel, samples: int, seed: int) -> ValidationRecord | None:
    """Validate a trained model on fresh payloads, in a way of the plugin's own.

    Called after training and tuning (and by ``deepmorph validate``), after the built-in
    validation on real renders (:mod:`deepmorph.training.validation`). Draw ``samples`` random
    payloads from ``seed``, read them back the plugin's way (the photo chain reads simulated
    photos), and return a :class:`~deepmorph_core.bundle.ValidationRecord`, or ``None`` to add
    nothing. The records are stored in the bundle and shown by ``deepmorph info``.
    """
