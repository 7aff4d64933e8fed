"""The photo chain's plugin module, loaded through the ``deepmorph`` entry point
(``builtin_detectors``) exactly as third-party plugins are: the built-in detector and the
photo commands."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    import typer

    from deepmorph_core.plugins import Register


@hookimpl
def deepmorph_register_detectors(register: Register) -> None:
    """Register the built-in detector (imported here, not at load: see hookspecs)."""
    from deepmorph_detect.centrenet import CentreNetDetector

    register.detector(CentreNetDetector)


@hookimpl
def deepmorph_register_commands(cli: typer.Typer) -> None:
    """Add ``decode``, ``synth``, ``bench-scenes``, ``bench-photos``, ``train-detector`` and ``demo``."""
    from deepmorph_detect import commands

    commands.register(cli)
