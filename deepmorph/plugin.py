"""The facade's plugin module, loaded through the ``deepmorph`` entry point
(``builtin_registry``) exactly as third-party plugins are: the payload registry's commands and
the studio."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    import typer


@hookimpl
def deepmorph_register_commands(cli: typer.Typer) -> None:
    """Add ``registry`` (``add``, ``list``, ``show``, ``remove``, ``export``), ``decode --registry``'s
    lookup and ``studio``."""
    from deepmorph import commands

    commands.register(cli)
