"""``deepmorph studio``: start the local web app and print (and open) its address with its token."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from deepmorph.cli.frame import err, out

LOOPBACK = ("127.0.0.1", "localhost", "::1")


def default_data() -> Path:
    """``$DEEPMORPH_HOME``, else ``~/.deepmorph`` (where ``deepmorph registry`` keeps its file)."""
    home = os.environ.get("DEEPMORPH_HOME")
    return Path(home) if home else Path.home() / ".deepmorph"


def studio(
    port: Annotated[int, typer.Option("--port", min=1, max=65535, help="The port to listen on.")] = 8765,
    host: Annotated[
        str, typer.Option("--host", help="The address to listen on (0.0.0.0: every network, with a warning).")
    ] = "127.0.0.1",
    no_browser: Annotated[bool, typer.Option("--no-browser", help="Print the address; do not open a browser.")] = False,
    data: Annotated[
        Optional[Path],
        typer.Option(
            "--data",
            help="Folder for the registry, the drawing and trained models (default: ~/.deepmorph, or $DEEPMORPH_HOME).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """A local web app for the whole journey: drawing and bounds, capacity, training, payloads, print, scan."""
    import uvicorn

    from deepmorph.studio.app import Studio, create_app

    folder = data if data is not None else default_data()
    studio_state = Studio(folder)
    if host not in LOOPBACK:
        err.print(
            f"warning: --host {host}: the studio is reachable from other machines; anyone who learns its token "
            "can use it, and traffic is not encrypted. Use 127.0.0.1 unless you mean this."
        )
        studio_state.hosts = {"*"} if host in ("0.0.0.0", "::") else {*studio_state.hosts, host}
    shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
    url = f"http://{shown}:{port}/?token={studio_state.token}"
    out.print(f"DeepMorph studio: {url}")
    out.print(f"data in {folder}; Ctrl-C stops it")
    sys.stdout.flush()  # the address reaches a pipe (a script waiting for it) at once
    if not no_browser:
        import webbrowser

        webbrowser.open(url)
    uvicorn.run(create_app(studio_state), host=host, port=port, log_level="warning", access_log=False)


__all__ = ["studio"]
