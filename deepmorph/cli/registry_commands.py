"""``deepmorph registry``: the payload registry's commands (``add``, ``list``, ``show``,
``remove``, ``export``), added to the command line through the ``deepmorph_register_commands``
hook (:mod:`deepmorph.plugin`). Each parses its arguments and calls the library."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from deepmorph.cli.frame import PANEL_CODES, JsonOpt, ModelArg, add_commands, out, print_json, safe
from deepmorph_core.errors import DeepMorphError

if TYPE_CHECKING:
    from deepmorph.registry import Entry, ModelKey, PayloadRegistry

HELP = """The payload registry: what each payload of a model means (a URL or a text), shown by decode --registry.

A local SQLite file that several processes may write at once: --db, else ~/.deepmorph/registry.sqlite3.
"""

PayloadArg = Annotated[
    str,
    typer.Argument(help="The payload: hex (0x...), a decimal number (0d...) or a bit string of exactly the model's "
                        "payload length.", show_default=False),
]  # fmt: skip
DbOpt = Annotated[
    Optional[Path],
    typer.Option(
        "--db",
        help="The registry file [default: ~/.deepmorph/registry.sqlite3, or $DEEPMORPH_HOME/registry.sqlite3].",
        show_default=False,
    ),
]


def _registry(db: Path | None) -> PayloadRegistry:
    from deepmorph.registry import PayloadRegistry

    return PayloadRegistry(db)


def _line(e: Entry) -> str:
    """An entry on one line: a text's line breaks are shown as ``\\n``."""
    target = e.target if e.kind == "url" else json.dumps(e.target, ensure_ascii=False)
    note = f"  # {e.note}" if e.note else ""
    return f"{e.payload}  {e.kind:<4}  {target}  {e.drawing} (model {e.model[:12]}){note}"


def add(
    model: ModelArg,
    payload: PayloadArg,
    target: Annotated[str, typer.Argument(help="An http(s) URL, or a text with --text.", show_default=False)],
    text: Annotated[bool, typer.Option("--text", help="TARGET is a text to show, not a URL.")] = False,
    note: Annotated[Optional[str], typer.Option("--note", help="A note for whoever keeps the registry.")] = None,
    replace: Annotated[bool, typer.Option("--replace", help="Replace the payload's entry if it has one.")] = False,
    db: DbOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Give a payload of a model its meaning: a URL (http or https) or a text."""
    registry = _registry(db)
    entry = registry.add(model, payload, target, "text" if text else "url", note, replace=replace)
    if as_json:
        print_json({"written": [str(registry.path)], "entry": entry.to_json(), "replaced": entry.updated is not None})
        return
    verb = "replaced" if entry.updated is not None else "added"
    out.print(f"{verb} {_line(entry)} in {registry.path}")


def list_entries(
    model: Annotated[Optional[Path], typer.Argument(help="Only this model's entries.", show_default=False)] = None,
    db: DbOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """List the registry's entries, of every model or of one."""
    registry = _registry(db)
    entries = registry.list(model)
    if as_json:
        print_json([e.to_json() for e in entries])
        return
    for e in entries:
        out.print(_line(e))
    if not entries:
        out.print(f"no entries{f' of {safe(model)}' if model else ''} in {registry.path}")


def _key(model: Path, payload: str) -> tuple[ModelKey, str]:
    """The model's key and the payload in hex (one clear error when it does not fit)."""
    from deepmorph.registry import model_key
    from deepmorph_core.payload import Payload

    key = model_key(model)
    return key, Payload.of(payload, key.payload_bits).hex


def show(model: ModelArg, payload: PayloadArg, db: DbOpt = None, as_json: JsonOpt = False) -> None:
    """Show a payload's entry (an error when it has none)."""
    registry = _registry(db)
    key, hex_payload = _key(model, payload)
    entry = registry.get(key, hex_payload)
    if entry is None:
        raise DeepMorphError(f"{registry.path}: {hex_payload} of {key} has no entry")
    if as_json:
        print_json(entry.to_json())
        return
    rows = [("payload", entry.payload), ("model", f"{entry.drawing} ({entry.model})"), (entry.kind, entry.target),
            ("note", entry.note or "-"), ("added", entry.created), ("replaced", entry.updated or "-")]  # fmt: skip
    for name, value in rows:
        out.print(f"{name + ':':<9} {value}")


def remove(model: ModelArg, payload: PayloadArg, db: DbOpt = None, as_json: JsonOpt = False) -> None:
    """Remove a payload's entry (an error when it has none)."""
    registry = _registry(db)
    key, hex_payload = _key(model, payload)
    entry = registry.remove(key, hex_payload)
    if entry is None:
        raise DeepMorphError(f"{registry.path}: {hex_payload} of {key} has no entry")
    if as_json:
        print_json({"written": [str(registry.path)], "removed": entry.to_json()})
        return
    out.print(f"removed {_line(entry)} from {registry.path}")


def export(
    out_path: Annotated[
        Path, typer.Option("--out", help="The file to write: .csv or .json, by its extension.", show_default=False)
    ],
    model: Annotated[Optional[Path], typer.Argument(help="Only this model's entries.", show_default=False)] = None,
    db: DbOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Write the registry's entries (of every model or of one) to a CSV or JSON file, whole or not at all."""
    from deepmorph.registry import EXPORT_FORMATS
    from deepmorph_core.fileio import refuse_to_overwrite

    registry = _registry(db)
    refuse_to_overwrite(out_path, "--out", [("registry", registry.path), ("model file", model)])
    fmt = EXPORT_FORMATS.get(out_path.suffix.lower())
    if fmt is None:
        raise DeepMorphError(f"--out {out_path}: an export is written as .csv or .json; name it so")
    n = registry.export(out_path, fmt, model)
    if as_json:
        print_json({"written": [str(out_path)], "entries": n, "format": fmt})
        return
    out.print(f"wrote {out_path} ({n} entries, {fmt.upper()})")


def register(cli: typer.Typer) -> None:
    """Add the ``registry`` commands to ``cli``."""
    group = typer.Typer(name="registry", help=HELP, no_args_is_help=True)
    add_commands(
        group,
        (
            ("add", add, None),
            ("list", list_entries, None),
            ("show", show, None),
            ("remove", remove, None),
            ("export", export, None),
        ),
    )
    cli.add_typer(group, name="registry", rich_help_panel=PANEL_CODES)


__all__ = ["register"]
