"""The ``deepmorph`` command line: the frame every command runs in.

Commands only parse their arguments and call the library. The drawing and training commands are
in :mod:`deepmorph.cli.commands`; every other command arrives through the
``deepmorph_register_commands`` hook, the built-in photo and registry commands included
(:mod:`deepmorph.cli.photo_commands`, :mod:`deepmorph.cli.registry_commands`, registered by
:mod:`deepmorph.plugin`). Every user-facing failure is a
:class:`~deepmorph_core.errors.DeepMorphError`, printed as one ``error: ...`` line with exit
status 1; usage errors exit with 2 (typer's convention); ``decode`` exits with 4 when an input
gave no verified payload. Building the application imports no torch: ``--help``, ``--version``
and ``list-primitives`` answer at once, and each command imports what it uses when it runs.
"""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from deepmorph.cli.frame import EXIT_NOTHING_READ, err, print_error
from deepmorph_core.errors import DeepMorphError

_app: typer.Typer | None = None

HELP = """Hide bitstrings in vector drawings, and read them back from photos.

An SVG drawing with dm: bounds is trained into a model (.dmm); the model hides a payload in a
morph of the drawing (encode) and finds, reads and poses printed codes in photos and videos
(decode). `deepmorph demo` runs it all on the bundled drawing.
"""

EPILOG = (
    f"Exit status: 0 done; 1 an error (one 'error:' line); 2 a usage error; {EXIT_NOTHING_READ} decode read no"
    " verified payload from an input. Run 'deepmorph COMMAND --help' for a command's options."
)

#: Libraries whose versions ``--version`` reports (distribution names; the first installed of
#: each group is shown). Read from the installed metadata: nothing is imported.
_VERSIONED = (
    ("torch",),
    ("onnxruntime",),
    ("opencv-contrib-python-headless", "opencv-contrib-python", "opencv-python-headless", "opencv-python"),
)


def version_text() -> str:
    """``deepmorph X.Y.Z``, then Python's and the main libraries' versions and the third-party
    plugins with their distributions, from installed metadata (nothing heavy is imported)."""
    import importlib.metadata
    import platform

    from deepmorph_core import __version__
    from deepmorph_core.plugins import default_registry

    libs = [f"python {platform.python_version()}"]
    for names in _VERSIONED:
        for name in names:
            try:
                libs.append(f"{name} {importlib.metadata.version(name)}")
                break
            except importlib.metadata.PackageNotFoundError:
                continue
    lines = [f"deepmorph {__version__}", ", ".join(libs)]
    own = f"deepmorph {__version__}"
    plugins = [f"{name} ({dist or 'not installed'})" for name, dist in default_registry().plugins.items()
               if dist != own]  # fmt: skip
    lines.append("plugins: " + (", ".join(plugins) or "none besides the built-in ones"))
    return "\n".join(lines)


def _show_version(value: bool) -> None:
    if value:
        sys.stdout.write(version_text() + "\n")
        raise typer.Exit()


def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            is_eager=True,
            callback=_show_version,
            help="Print the versions of deepmorph, its main libraries and its plugins, and exit.",
        ),
    ] = False,
) -> None:
    """Options of ``deepmorph`` itself (before the command)."""


def application() -> typer.Typer:
    """The command-line application with its own commands and every plugin's (built once)."""
    global _app
    if _app is None:
        from deepmorph.cli import commands
        from deepmorph_core.plugins import default_registry

        app = typer.Typer(
            name="deepmorph",
            help=HELP,
            epilog=EPILOG,
            no_args_is_help=True,
            pretty_exceptions_enable=False,
            add_completion=False,
        )
        app.callback()(_root)
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


__all__ = ["application", "main", "version_text"]
