"""Core's commands: the drawing (``list-primitives``, ``inspect``, ``morph``, ``render``) and the
model (``train``, ``info``, ``tune-decoder``, ``encode``). Each parses its arguments and calls
the library; photos are the photo chain's commands (:mod:`deepmorph_detect.commands`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer
from rich.table import Table

from deepmorph_core.cli.frame import (
    DropOpt,
    JsonOpt,
    ModelArg,
    MoveOpt,
    RotateOpt,
    ScaleOpt,
    SeedOpt,
    ShiftOpt,
    SvgArg,
    ThreadsOpt,
    ValidationOpt,
    err,
    out,
    parse_pair,
    print_json,
    safe,
    step_progress,
    warn_dropped,
    write_text_atomic,
)
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import refuse_to_overwrite

if TYPE_CHECKING:
    import numpy as np

    from deepmorph_core.morphable import MorphableDrawing


TABLE_ROWS = 60  # primitives shown in inspect's table (a rich table of thousands of rows takes seconds)


def _load(
    svg: Path, move: float | None, shift: str | None, scale: str | None, rotate: str | None, drop: bool = False
) -> MorphableDrawing:
    from deepmorph_core.morphable import MorphableDrawing

    md = MorphableDrawing.load(
        svg,
        move=move,
        shift=parse_pair(shift, "shift", single_ok=True),
        scale=parse_pair(scale, "scale"),
        rotate=parse_pair(rotate, "rotate"),
        drop_unsupported=drop,
    )
    warn_dropped(md.drawing)
    return md


def list_primitives(as_json: JsonOpt = False) -> None:
    """List the primitive and path-segment kinds the installed plugins provide."""
    from deepmorph_core.plugins import default_registry

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
        print_json(rows)
        return
    table = Table(title="DeepMorph primitives")
    for col in ("kind", "reads", "plugin", "distribution", "morphable parameters"):
        table.add_column(col, overflow="fold")
    for row in rows:
        table.add_row(row["kind"], row["reads"], row["plugin"], row["distribution"] or "-", row["morphable"])
    out.print(table)


def inspect(
    svg: SvgArg,
    move: MoveOpt = None,
    shift: ShiftOpt = None,
    scale: ScaleOpt = None,
    rotate: RotateOpt = None,
    drop: DropOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Show the primitives of a drawing, its variables N_v and their bounds."""
    md = _load(svg, move, shift, scale, rotate, drop)
    info = md.describe()
    if as_json:
        print_json(info)
        return
    table = Table(title=f"{safe(svg)}: {len(info['primitives'])} primitives, N_v = {info['n_variables']}")
    for col in ("#", "kind", "line", "points", "variables", "bounds", "paints"):
        table.add_column(col, overflow="fold")
    for p in info["primitives"][:TABLE_ROWS]:
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
    if len(info["primitives"]) > TABLE_ROWS:
        out.print(f"... and {len(info['primitives']) - TABLE_ROWS} more primitives (--json lists every one)")
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


def morph(
    svg: SvgArg,
    out_path: Annotated[Path, typer.Option("--out", help="Where to write the morphed SVG.")],
    random: Annotated[bool, typer.Option("--random", help="Draw a uniformly random morph inside the bounds.")] = False,
    seed: Annotated[Optional[int], typer.Option("--seed", help="Seed for --random.")] = None,
    move: MoveOpt = None,
    shift: ShiftOpt = None,
    scale: ScaleOpt = None,
    rotate: RotateOpt = None,
    drop: DropOpt = False,
) -> None:
    """Write a morph of a drawing (inside its bounds) as a new SVG."""
    if not random:
        raise DeepMorphError("nothing to do: pass --random (payloads are encoded with 'deepmorph encode')")
    refuse_to_overwrite(out_path, "--out", [("input drawing", svg)])
    md = _load(svg, move, shift, scale, rotate, drop)
    if md.n_variables == 0:
        raise DeepMorphError(f"{svg}: the drawing has 0 variables; add dm: bounds or pass --move 0.5")
    values = md.values_from_unit(md.random_unit(1, seed))
    write_text_atomic(out_path, md.to_svg(values[0]))
    out.print(f"wrote {out_path} (random morph of {md.n_variables} variables, seed {seed})")


def render(
    svg: SvgArg,
    out_path: Annotated[Path, typer.Option("--out", help="Output PNG.")],
    size: Annotated[int, typer.Option("--size", min=8, max=4096, help="Width in pixels.")] = 256,
    soft: Annotated[bool, typer.Option("--soft", help="Use the soft (differentiable) rasterizer.")] = False,
    overlay_base: Annotated[
        Optional[Path], typer.Option("--overlay", help="Draw this base drawing in red under the SVG.")
    ] = None,
    drop: DropOpt = False,
) -> None:
    """Render a drawing with the real renderer (resvg) or the soft rasterizer."""
    from deepmorph_core.image_io import image_format, save_gray, save_rgb
    from deepmorph_core.render import overlay

    refuse_to_overwrite(out_path, "--out", [("input drawing", svg), ("overlay's base drawing", overlay_base)])
    image_format(out_path)
    ink = _render_ink(svg, size, soft, drop)
    if overlay_base is None:
        save_gray(1.0 - ink, out_path)
    else:
        base = _render_ink(overlay_base, size, soft, drop)
        if base.shape != ink.shape:
            raise DeepMorphError(f"{overlay_base}: its aspect ratio differs from {svg}'s; cannot overlay")
        save_rgb(overlay(base, ink), out_path)
    out.print(f"wrote {out_path} ({ink.shape[1]}x{ink.shape[0]}, {'soft' if soft else 'resvg'})")


def _render_ink(svg: Path, size: int, soft: bool, drop: bool = False) -> np.ndarray:
    from deepmorph_core.render import render_svg_ink

    md = _load(svg, None, None, None, None, drop)  # validates the file: hostile input never reaches resvg
    md.drawing.pixel_size(size)  # refused before rendering when too large
    if soft:
        return md.render_soft(md.neutral_values(), size).detach()[0, 0].numpy()
    return render_svg_ink(md.to_svg(md.neutral_values()[0]), size)


def train(
    svg: SvgArg,
    out_path: Annotated[Path, typer.Option("--out", help="Model bundle to write (.dmm); also the checkpoint.")],
    payload_bits: Annotated[int, typer.Option("--payload-bits", min=1, max=256, help="Payload length in bits.")] = 24,
    crc: Annotated[
        Optional[int], typer.Option("--crc", help="CRC bits: 8 or 16 (default: 8 up to 32 payload bits).")
    ] = None,
    ecc_t: Annotated[Optional[int], typer.Option("--ecc-t", min=0, max=16, help="BCH correctable bit errors.")] = None,
    steps: Annotated[int, typer.Option("--steps", min=1, help="Training steps (both stages).")] = 3000,
    batch: Annotated[int, typer.Option("--batch", min=2, help="Morphs per step.")] = 32,
    width: Annotated[int, typer.Option("--width", min=32, max=512, help="Decoder image width in pixels.")] = 96,
    severity: Annotated[
        str, typer.Option("--severity", help="Capture corruption: none, easy, medium, hard.")
    ] = "medium",
    hard_fraction: Annotated[
        float, typer.Option("--real-render-share", min=0, max=1, help="Share of each batch drawn by resvg.")
    ] = 0.25,
    small_prints: Annotated[
        float,
        typer.Option(
            "--small-prints",
            min=0,
            max=1,
            help="Share of each batch captured as a small print (corrupted at 55-95 % of the width, enlarged).",
        ),
    ] = 0.0,
    seed: SeedOpt = 0,
    encoder_init: Annotated[
        str,
        typer.Option(
            "--encoder-init", help="Encoder start: spread (each bit drives its own variables) or random (the paper's)."
        ),
    ] = "spread",
    spatial_transformer: Annotated[
        bool,
        typer.Option(
            "--spatial-transformer/--no-spatial-transformer",
            help="Learn a homography in front of the decoder that undoes leftover perspective.",
        ),
    ] = True,
    device: Annotated[str, typer.Option("--device", help="cpu or cuda.")] = "cpu",
    threads: ThreadsOpt = None,
    resume: Annotated[bool, typer.Option("--resume", help="Continue the checkpoint at --out.")] = False,
    checkpoint_every: Annotated[
        int, typer.Option("--checkpoint-every", min=1, help="Steps between checkpoints (a crash loses at most these).")
    ] = 250,
    move: MoveOpt = None,
    shift: ShiftOpt = None,
    scale: ScaleOpt = None,
    rotate: RotateOpt = None,
    drop: DropOpt = False,
    validation: ValidationOpt = None,
) -> None:
    """Train an encoder/decoder pair that hides --payload-bits in the drawing."""
    from deepmorph_core.train import train_model

    def describe(m: dict[str, Any]) -> str:
        return f"stage {m['stage']} loss {m['loss']:.3f} bit acc {m['bit_acc']:.3f} all-bits {m['word_acc']:.2f}"

    with step_progress("training", describe) as on_start:
        summary = train_model(
            svg,
            out_path,
            payload_bits=payload_bits,
            crc_bits=crc,
            ecc_t=ecc_t,
            resume=resume,
            bounds={
                "move": move,
                "shift": parse_pair(shift, "shift", single_ok=True),
                "scale": parse_pair(scale, "scale"),
                "rotate": parse_pair(rotate, "rotate"),
            },
            train={
                "steps": steps,
                "batch": batch,
                "width": width,
                "severity": severity,
                "seed": seed,
                "encoder_init": encoder_init,
                "spatial_transformer": spatial_transformer,
                "device": device,
                "threads": threads,
                "hard_fraction": hard_fraction,
                "small_prints": small_prints,
                "checkpoint_every": checkpoint_every,
            },
            on_start=on_start,
            on_warning=lambda text: err.print(f"warning: {text}"),
            drop_unsupported=drop,
            validation_samples=_validation_samples(validation),
            on_validation=lambda: err.print("validating on fresh payloads ..."),
        )
    out.print(
        f"wrote {summary.bundle} ({summary.steps} steps in {summary.elapsed_s:.0f} s, stage 2 from step "
        f"{summary.stage2_start}); log {summary.log}" + (f", plot {summary.plot}" if summary.plot else "")
    )
    _print_validation([r.model_dump() for r in summary.validation])


def _validation_samples(text: str | None) -> tuple[int, int] | None:
    """``--validation R,P``: payloads read from renders and from photos (``0`` for none);
    ``None`` for the defaults."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        counts = [int(p) for p in parts]
    except ValueError:
        counts = []
    if len(counts) not in (1, 2) or min(counts) < 0 or max(counts) > 100_000:
        raise typer.BadParameter(f"expected R,P (two counts from 0 to 100000), got {text!r}", param_hint="--validation")
    return (counts[0], counts[1] if len(counts) == 2 else 0)


def _validation_lines(records: list[dict[str, Any]]) -> list[str]:
    """One line per validation record: what was read, and how well."""
    lines = []
    for r in records:
        acc = "" if r["bit_accuracy"] is None else f", code-bit accuracy {r['bit_accuracy']:.4f}"
        lines.append(
            f"{r['name']} ({r['severity']}): {r['read']}/{r['samples']} read ({r['read'] / r['samples']:.1%}), "
            f"{r['wrong']} wrong{acc}; {r['seconds']:.0f} s"
        )
    return lines


def _print_validation(records: list[dict[str, Any]]) -> None:
    for line in _validation_lines(records):
        out.print(f"validation: {safe(line)}")


def info(model: ModelArg, as_json: JsonOpt = False) -> None:
    """Describe a model bundle: payload and code bits, codec, image size, bounds, training record."""
    from deepmorph_core.model import DeepMorphModel

    data = DeepMorphModel.load(model).info()
    if as_json:
        print_json(data)
        return
    table = Table(title=safe(model), show_header=False)
    table.add_column("field")
    table.add_column("value", overflow="fold")
    codec = data["codec"]
    rec = data["record"]
    dec = data["decoder"]
    rows = [
        ("drawing", data["drawing"]),
        ("payload bits", str(data["payload_bits"])),
        (
            "code bits",
            f"{data['code_bits']} (CRC {codec['crc_bits']}, BCH t={codec['bch_t']}: {codec['ecc_bits']} ECC bits)",
        ),
        ("variables N_v", str(data["n_variables"])),
        ("image size", "x".join(map(str, data["image_size"][::-1]))),
        (
            "decoder",
            f"{'spatial transformer, then ' if dec['spatial_transformer'] else ''}CNN "
            f"(stem {dec['stem']}, channels {list(dec['channels'])}, head {dec['hidden']})",
        ),
        ("bounds defaults", json.dumps(data["bounds_defaults"]) or "-"),
        (
            "training",
            f"{rec['step']}/{rec['total_steps']} steps, {rec['elapsed_s']:.0f} s on {rec['device']} "
            f"({rec['threads']} threads), stage 2 from {rec['stage2_start']}, "
            f"{'finished' if rec['finished'] else 'checkpoint (resume to finish)'}",
        ),
        ("last metrics", json.dumps(rec["metrics"])),
        ("versions", json.dumps(data["versions"])),
    ]
    det = data["detector"]
    if det is None:
        rows.append(("detector", "none (decode frames whole images; add one with `deepmorph train-detector`)"))
    else:
        drec = det["record"]
        rows.append(
            (
                "detector",
                f"{drec['step']}/{drec['total_steps']} steps, {drec['elapsed_s']:.0f} s "
                f"({'finished' if drec['finished'] else 'checkpoint (resume to finish)'}), "
                + "".join(f"fine-tuned after {e['record']['step']} steps, " for e in reversed(det.get("earlier", [])))
                + f"{json.dumps(drec['metrics'])}",
            )
        )
    for run in data["tuning"]:
        rows.append(
            (
                "decoder tuned",
                f"{run['steps']}/{run['total_steps']} steps, {run['elapsed_s']:.0f} s, small prints "
                f"{run['small_prints']:.0%}, bit acc {run.get('bit_acc', float('nan')):.4f}"
                + ("" if run["finished"] else " (interrupted)"),
            )
        )
    for line in _validation_lines(data["validation"]) or ["none (run `deepmorph validate MODEL --save`)"]:
        rows.append(("validated", line))
    graphs = data["graphs"]
    rows.append(
        (
            "ONNX graphs",
            ", ".join(f"{name} ({g['size'] / 1e6:.1f} MB, opset {g['opset']})" for name, g in graphs.items())
            or "none (exported when decoding; `deepmorph export` stores them)",
        )
    )
    for k, v in rows:
        table.add_row(k, safe(v))
    out.print(table)


def tune_decoder(
    model: ModelArg,
    out_path: Annotated[Path, typer.Option("--out", help="Bundle to write (may be the same file).")],
    steps: Annotated[int, typer.Option("--steps", min=1, help="Tuning steps.")] = 800,
    small_prints: Annotated[
        float,
        typer.Option("--small-prints", min=0, max=1, help="Share of each batch captured as a small print."),
    ] = 0.5,
    lr: Annotated[float, typer.Option("--lr", min=1e-6, max=1e-1, help="Start learning rate (cosine to 10 %).")] = 3e-4,
    seed: SeedOpt = 0,
    threads: ThreadsOpt = None,
    validation: ValidationOpt = None,
) -> None:
    """Train a trained model's decoder further, encoder frozen: printed codes and the detector stay valid."""
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.train import tune_decoder as tune

    with step_progress("tuning", lambda m: f"decoder bit acc {m['bit_acc']:.4f}") as on_start:
        run = tune(
            model,
            out_path,
            steps=steps,
            small_prints=small_prints,
            lr=lr,
            seed=seed,
            threads=threads,
            on_start=on_start,
            validation_samples=_validation_samples(validation),
            on_validation=lambda: err.print("validating on fresh payloads ..."),
            on_warning=lambda text: err.print(f"warning: {text}"),
        )
    out.print(f"wrote {out_path} ({run['steps']} steps in {run['elapsed_s']:.0f} s, bit acc {run['bit_acc']:.4f})")
    _print_validation(DeepMorphModel.load(out_path).info()["validation"])


def validate(
    model: ModelArg,
    samples: Annotated[int, typer.Option("--samples", min=1, max=100_000, help="Payloads read from renders.")] = 1000,
    photos: Annotated[
        int, typer.Option("--photos", min=0, max=100_000, help="Payloads read from close-up photos.")
    ] = 200,
    seed: SeedOpt = 0,
    save: Annotated[bool, typer.Option("--save", help="Store the result in the bundle (shown by info).")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Read fresh random payloads back from renders and photos: what the model really reads."""
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.plugins import default_registry
    from deepmorph_core.validation import validate as run_validation
    from deepmorph_core.validation import validation_warning

    m = DeepMorphModel.load(model)
    records = run_validation(m, default_registry(), samples, photos, seed=seed)
    if save:
        m.meta.validation = records
        m.save(model)
    dumped = [r.model_dump() for r in records]
    if as_json:
        print_json({"model": str(model), "validation": dumped, "saved": save})
    else:
        _print_validation(dumped)
    warning = validation_warning(records, str(model))
    if warning:
        err.print(f"warning: {safe(warning)}")


def encode(
    model: ModelArg,
    payload: Annotated[
        str, typer.Option("--payload", help="Hex (0x...) or a bit string of exactly the model's payload length.")
    ],
    out_path: Annotated[Path, typer.Option("--out", help="Morphed SVG to write.")],
    png: Annotated[Optional[Path], typer.Option("--png", help="Also render a PNG for printing.")] = None,
    width_mm: Annotated[float, typer.Option("--width-mm", min=1, max=2000, help="Printed width of the PNG.")] = 50.0,
    dpi: Annotated[int, typer.Option("--dpi", min=50, max=2400, help="Printer resolution of the PNG.")] = 300,
) -> None:
    """Hide a payload in the model's drawing and write the morphed SVG (and a print-ready PNG)."""
    from deepmorph_core.code import print_pixels
    from deepmorph_core.fileio import atomic_write_all
    from deepmorph_core.model import DeepMorphModel

    refuse_to_overwrite(out_path, "--out", [("model file", model)])
    if out_path.suffix.lower() != ".svg":
        raise DeepMorphError(f"--out {out_path}: the code is written as SVG; name it .svg")
    if png is not None:
        refuse_to_overwrite(png, "--png", [("model file", model), ("SVG given with --out", out_path)])
        if png.suffix.lower() != ".png":
            raise DeepMorphError(f"--png {png}: the print image is a PNG; name it .png")
        px = print_pixels(width_mm, dpi)  # refused here, before any work, when too large
    m = DeepMorphModel.load(model)
    code = m.code(payload)
    files = [(out_path, code.svg.encode("utf-8"))]
    msg = f"wrote {out_path} carrying {code.payload.hex}"
    if png is not None:
        files.append((png, code.png(width_mm, dpi)))
        msg += f" and {png} ({px} px wide = {width_mm:g} mm at {dpi} dpi)"
    atomic_write_all(files)  # both or neither
    out.print(msg)


def register(cli: typer.Typer) -> None:
    """Add core's commands to ``cli``."""
    from deepmorph_core.cli.frame import friendly

    for name, command in (
        ("list-primitives", list_primitives),
        ("inspect", inspect),
        ("morph", morph),
        ("render", render),
        ("train", train),
        ("info", info),
        ("tune-decoder", tune_decoder),
        ("validate", validate),
        ("encode", encode),
    ):
        cli.command(name)(friendly(command))
