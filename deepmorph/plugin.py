"""The application's plugin module, loaded through the ``deepmorph`` entry point
(``builtin_commands``) exactly as third-party plugins are: the photo commands, the payload
registry's commands and the studio."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    import typer


@hookimpl
def deepmorph_register_commands(cli: typer.Typer) -> None:
    """Add ``registry`` (``add``, ``list``, ``show``, ``remove``, ``export``:
    :mod:`deepmorph.cli.registry_commands`), ``studio`` (the local web app:
    :mod:`deepmorph.studio.cli`), then ``decode``, ``synth``, ``bench-scenes``, ``bench-photos``,
    ``train-detector``, ``train-verifier``, ``export`` and ``demo`` (:mod:`deepmorph.cli.photo_commands`)."""
    from deepmorph.cli import photo_commands, registry_commands
    from deepmorph.cli.frame import add_commands
    from deepmorph.studio.cli import studio

    registry_commands.register(cli)
    add_commands(cli, (("studio", studio, None),))
    photo_commands.register(cli)
