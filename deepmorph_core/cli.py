"""The ``deepmorph`` command line: parses arguments and calls :mod:`deepmorph_core.api`.

Every user-facing failure is a :class:`~deepmorph_core.errors.DeepMorphError`, printed as one
``error: ...`` line with exit status 1; usage errors exit with 2 (typer's convention).
"""

from __future__ import annotations

import functools
import json
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Optional, TypeVar

import numpy as np
import typer
from rich.console import Console
from rich.table import Table
from rich.text import Text

from deepmorph_core.api import BUNDLED_DRAWING, MorphableDrawing
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.plugins import default_registry
from deepmorph_core.render import overlay, render_svg_ink, save_gray, save_rgb

app = typer.Typer(
    name="deepmorph",
    help="Hide bitstrings in vector drawings: inspect, morph and render SVG drawings.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
out = Console()
err = Console(stderr=True)

F = TypeVar("F", bound=Callable[..., Any])


def _print_error(exc: BaseException) -> None:
    """One line on stderr, never interpreted as markup, never wrapped."""
    err.print(Text.assemble(("error: ", "bold red"), str(exc)), soft_wrap=True, highlight=False)


def friendly(fn: F) -> F:
    """Turn a DeepMorphError raised by a command into one ``error:`` line and exit status 1."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except DeepMorphError as exc:
            _print_error(exc)
            raise typer.Exit(1) from None

    return wrapper  # type: ignore[return-value]


SvgArg = Annotated[Path, typer.Argument(help="An SVG drawing.", show_default=False)]
MoveOpt = Annotated[Optional[float], typer.Option("--move", help="Default dm:move radius for elements without bounds.")]
ShiftOpt = Annotated[Optional[str], typer.Option("--shift", help='Default dm:shift: "R" or "RX,RY".')]
ScaleOpt = Annotated[Optional[str], typer.Option("--scale", help='Default dm:scale: "LO,HI".')]
RotateOpt = Annotated[Optional[str], typer.Option("--rotate", help='Default dm:rotate in degrees: "LO,HI".')]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


def _pair(text: str | None, name: str, single_ok: bool = False) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        raise DeepMorphError(f"--{name}={text!r}: expected numbers") from None
    if single_ok and len(nums) == 1:
        return nums[0], nums[0]
    if len(nums) != 2:
        raise DeepMorphError(f'--{name}={text!r}: expected two numbers "LO,HI"')
    return nums[0], nums[1]


def _load(svg: Path, move: float | None, shift: str | None, scale: str | None, rotate: str | None) -> MorphableDrawing:
    return MorphableDrawing.load(
        svg,
        move=move,
        shift=_pair(shift, "shift", single_ok=True),
        scale=_pair(scale, "scale"),
        rotate=_pair(rotate, "rotate"),
    )


def _write_text_atomic(path: Path, text: str) -> None:
    """Write a file so that a crash never leaves it half written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@app.command("list-primitives")
@friendly
def list_primitives(as_json: JsonOpt = False) -> None:
    """List the primitive and path-segment kinds the installed plugins provide."""
    reg = default_registry()
    rows = []
    for r in [*reg.primitives.values(), *reg.path_segments.values()]:
        reads = " ".join(f"<{t}>" for t in r.obj.tags) if r.category == "primitive" else f"path {r.obj.commands}"
        rows.append(
            {
                "kind": r.key,
                "category": r.category,
                "reads": reads,
                "plugin": r.plugin,
                "distribution": r.distribution,
                "morphable": r.obj.morphable,
            }
        )
    if as_json:
        out.print_json(json.dumps(rows))
        return
    table = Table(title="DeepMorph primitives")
    for col in ("kind", "reads", "plugin", "distribution", "morphable parameters"):
        table.add_column(col, overflow="fold")
    for row in rows:
        table.add_row(row["kind"], row["reads"], row["plugin"], row["distribution"] or "-", row["morphable"])
    out.print(table)


@app.command()
@friendly
def inspect(
    svg: SvgArg,
    move: MoveOpt = None,
    shift: ShiftOpt = None,
    scale: ScaleOpt = None,
    rotate: RotateOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Show the primitives of a drawing, its variables N_v and their bounds."""
    md = _load(svg, move, shift, scale, rotate)
    info = md.describe()
    if as_json:
        out.print_json(json.dumps(info))
        return
    table = Table(title=f"{svg}: {len(info['primitives'])} primitives, N_v = {info['n_variables']}")
    for col in ("#", "kind", "line", "points", "variables", "bounds", "paints"):
        table.add_column(col, overflow="fold")
    for p in info["primitives"]:
        bounds = "fixed" if p["fixed"] else (", ".join(f"{k}={v}" for k, v in p["bounds"].items()) or "none")
        table.add_row(
            str(p["index"]),
            p["kind"],
            str(p["line"]),
            str(p["control_points"]),
            str(p["variables"]),
            bounds,
            " ".join(p["paints"]),
        )
    out.print(table)
    for g in info["groups"]:
        out.print(f"group at line {g['line']}: {g['variables']} variables, bounds {g['bounds']}")
    for s in info["skipped"]:
        out.print(f"skipped line {s['line']}: {s['reason']}")
    if info["n_variables"] == 0:
        out.print(
            "This drawing has 0 variables: nothing may morph yet. Add bounds to the SVG, e.g. "
            'xmlns:dm="urn:deepmorph:1" dm:move="0.5" on the root <svg> (see docs/bounds.md), '
            "or pass defaults such as --move 0.5."
        )


@app.command()
@friendly
def morph(
    svg: SvgArg,
    out_path: Annotated[Path, typer.Option("--out", help="Where to write the morphed SVG.")],
    random: Annotated[bool, typer.Option("--random", help="Draw a uniformly random morph inside the bounds.")] = False,
    seed: Annotated[Optional[int], typer.Option("--seed", help="Seed for --random.")] = None,
    move: MoveOpt = None,
    shift: ShiftOpt = None,
    scale: ScaleOpt = None,
    rotate: RotateOpt = None,
) -> None:
    """Write a morph of a drawing (inside its bounds) as a new SVG."""
    if not random:
        raise DeepMorphError("nothing to do: pass --random (payloads are encoded with 'deepmorph encode')")
    if out_path.resolve() == svg.resolve():
        raise DeepMorphError(f"{out_path}: refusing to overwrite the input drawing")
    md = _load(svg, move, shift, scale, rotate)
    if md.n_variables == 0:
        raise DeepMorphError(f"{svg}: the drawing has 0 variables; add dm: bounds or pass --move 0.5")
    values = md.values_from_unit(md.random_unit(1, seed))
    _write_text_atomic(out_path, md.to_svg(values[0]))
    out.print(f"wrote {out_path} (random morph of {md.n_variables} variables, seed {seed})")


@app.command()
@friendly
def render(
    svg: SvgArg,
    out_path: Annotated[Path, typer.Option("--out", help="Output PNG.")],
    size: Annotated[int, typer.Option("--size", min=8, max=4096, help="Width in pixels.")] = 256,
    soft: Annotated[bool, typer.Option("--soft", help="Use the soft (differentiable) rasterizer.")] = False,
    overlay_base: Annotated[
        Optional[Path], typer.Option("--overlay", help="Draw this base drawing in red under the SVG.")
    ] = None,
) -> None:
    """Render a drawing with the real renderer (resvg) or the soft rasterizer."""
    ink = _render_ink(svg, size, soft)
    if overlay_base is None:
        save_gray(1.0 - ink, out_path)
    else:
        base = _render_ink(overlay_base, size, soft)
        if base.shape != ink.shape:
            raise DeepMorphError(f"{overlay_base}: its aspect ratio differs from {svg}'s; cannot overlay")
        save_rgb(overlay(base, ink), out_path)
    out.print(f"wrote {out_path} ({ink.shape[1]}x{ink.shape[0]}, {'soft' if soft else 'resvg'})")


def _render_ink(svg: Path, size: int, soft: bool) -> np.ndarray:
    md = MorphableDrawing.load(svg)  # validates the file (hostile input never reaches resvg)
    if soft:
        return md.render_soft(md.neutral_values(), size).detach()[0, 0].numpy()
    return render_svg_ink(md.to_svg(md.neutral_values()[0]), size)


@app.command()
@friendly
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for the demo's files.")] = Path("deepmorph-demo"),
    seed: Annotated[int, typer.Option("--seed", help="Seed of the random morph.")] = 3,
    size: Annotated[int, typer.Option("--size", min=32, max=2048, help="Render width in pixels.")] = 256,
) -> None:
    """Run the bundled drawing through inspect, a random morph, real and soft renders, an overlay."""
    md = MorphableDrawing.load(BUNDLED_DRAWING)
    out.print(
        f"bundled drawing {BUNDLED_DRAWING.name}: {len(md.drawing.primitives)} primitives, N_v = {md.n_variables}"
    )
    values = md.values_from_unit(md.random_unit(1, seed))
    out_dir.mkdir(parents=True, exist_ok=True)
    morphed_svg = md.to_svg(values[0])
    _write_text_atomic(out_dir / "morphed.svg", morphed_svg)
    base = md.render_hard(None, size)
    hard = render_svg_ink(morphed_svg, size)
    soft = md.render_soft(values, size).detach()[0, 0].numpy()
    save_gray(1 - base, out_dir / "base.png")
    save_gray(1 - hard, out_dir / "morphed.png")
    save_gray(1 - soft, out_dir / "morphed-soft.png")
    save_rgb(overlay(base, hard), out_dir / "overlay.png")
    mad = float(np.abs(soft - hard).mean())
    out.print(f"wrote {out_dir}/morphed.svg, base.png, morphed.png, morphed-soft.png, overlay.png")
    out.print(f"soft vs resvg render of the morph: mean absolute difference {mad:.4f}")


def main() -> None:
    """Console-script entry point: run the app, turning DeepMorph errors into one line."""
    try:
        app()
    except DeepMorphError as exc:
        _print_error(exc)
        sys.exit(1)
    except KeyboardInterrupt:
        err.print("interrupted")
        sys.exit(130)


if __name__ == "__main__":
    main()
