"""The ``deepmorph`` command line: the frame every command runs in.

Commands only parse their arguments and call the library. Core's own commands are in
:mod:`deepmorph_core.cli.commands`; every other command arrives through the
``deepmorph_register_commands`` hook, the built-in photo commands included
(:mod:`deepmorph_detect.commands`). Every user-facing failure is a
:class:`~deepmorph_core.errors.DeepMorphError`, printed as one ``error: ...`` line with exit
status 1; usage errors exit with 2 (typer's convention).
"""

from __future__ import annotations

import sys

import typer

from deepmorph_core.cli.frame import err, print_error
from deepmorph_core.errors import DeepMorphError

_app: typer.Typer | None = None


def application() -> typer.Typer:
    """The command-line application with core's commands and every plugin's (built once)."""
    global _app
    if _app is None:
        from deepmorph_core.cli import commands
        from deepmorph_core.plugins import default_registry

        app = typer.Typer(
            name="deepmorph",
            help="Hide bitstrings in vector drawings: inspect, morph and render SVG drawings.",
            no_args_is_help=True,
            pretty_exceptions_enable=False,
            add_completion=False,
        )
        commands.register(app)
        default_registry().register_commands(app)
        _app = app
    return _app


def main() -> None:
    """Console-script entry point: run the app, turning DeepMorph errors into one line."""
    try:
        application()()
    except DeepMorphError as exc:
        print_error(exc)
        sys.exit(1)
    except KeyboardInterrupt:
        err.print("interrupted")
        sys.exit(130)


__all__ = ["application", "main"]
