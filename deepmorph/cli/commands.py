"""The command line's own commands: the drawing (``list-primitives``, ``inspect``, ``morph``,
``render``) and the model (``train``, ``info``, ``tune-decoder``, ``encode``). Each parses its
arguments and calls the library; photos are the photo commands' (:mod:`deepmorph.cli.photo_commands`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, Optional

import typer
from rich.table import Table

from deepmorph.cli.frame import (
    PANEL_CODES,
    PANEL_DRAWINGS,
    PANEL_MODELS,
    DeviceOpt,
    DropOpt,
    JsonOpt,
    ModelArg,
    MoveOpt,
    RotateOpt,
    ScaleOpt,
    SeedOpt,
    SeverityName,
    ShiftOpt,
    SvgArg,
    ThreadsOpt,
    ValidationOpt,
    add_commands,
    err,
    out,
    parse_pair,
    print_json,
    safe,
    setting_option,
    step_progress,
    training_result,
    warn_dropped,
    write_text_atomic,
)
from deepmorph.training.settings import (
    DEFAULTS,
    PAYLOAD_BITS,
    PHOTO_SAMPLES,
    RENDER_SAMPLES,
    TUNE_DEFAULTS,
    ReadIn,
    TuneSettings,
    chosen,
)
from deepmorph_core.codec import CRC_WIDTHS
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import refuse_to_overwrite
from deepmorph_core.threads import use_threads

if TYPE_CHECKING:
    import numpy as np

    from deepmorph.training.many import DrawingResult
    from deepmorph_core.capacity import CapacityReport
    from deepmorph_core.morphable import MorphableDrawing


BatchOpt = Annotated[int, setting_option("batch")]
ImageWidthOpt = Annotated[int, setting_option("width")]
PixelsOpt = Annotated[Optional[int], setting_option("print_px")]
TrainSeverityOpt = Annotated[SeverityName, setting_option("severity")]

TABLE_ROWS = 60  # primitives shown in inspect's table (a rich table of thousands of rows takes seconds)


def _bounds(move: float | None, shift: str | None, scale: str | None, rotate: str | None) -> dict[str, Any]:
    """The default bounds ``--move``, ``--shift``, ``--scale`` and ``--rotate`` give, parsed
    (``None`` where not given)."""
    return {
        "move": move,
        "shift": parse_pair(shift, "shift", single_ok=True),
        "scale": parse_pair(scale, "scale"),
        "rotate": parse_pair(rotate, "rotate"),
    }


def _load(
    svg: Path, move: float | None, shift: str | None, scale: str | None, rotate: str | None, drop: bool = False
) -> MorphableDrawing:
    from deepmorph_core.morphable import MorphableDrawing

    md = MorphableDrawing.load(svg, **_bounds(move, shift, scale, rotate), drop_unsupported=drop)
    warn_dropped(md.drawing)
    return md


def list_primitives(as_json: JsonOpt = False) -> None:
    """List the primitive and path-segment kinds the installed plugins provide."""
    from deepmorph_core.plugins import default_registry

    reg = default_registry()
    rows = []
    for r in [*reg.primitives.values(), *reg.path_segments.values()]:
        info = r.info
        reads = " ".join(f"<{t}>" for t in info["tags"]) if r.category == "primitive" else f"path {info['commands']}"
        rows.append(
            {
                "kind": r.key,
                "category": r.category,
                "reads": reads,
                "plugin": r.plugin,
                "distribution": r.distribution,
                "morphable": info["morphable"],
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
    from deepmorph_core.reading_channel import channel_name

    md = _load(svg, move, shift, scale, rotate, drop)
    info = md.describe()
    if md.colour:  # what a new model reads of its colours (--read-in)
        info["reading_channel"] = channel_name(md.read_in().channel)
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
    palette = info["palette"]
    if palette:
        out.print(f"palette ({len(palette)} paints, luminance 0 = black, 1 = white):")
        for row in palette[:TABLE_ROWS]:
            shapes = ", ".join(str(i) for i in row["shapes"][:12]) + (" ..." if len(row["shapes"]) > 12 else "")
            out.print(f"  {row['paint']}  luminance {row['luminance']:.2f}  shapes {shapes}")
        if "reading_channel" in info:
            out.print(f"read in {info['reading_channel']} by a new model (train --read-in to choose)")
    for s in info["skipped"]:
        out.print(f"skipped line {s['line']}: {s['reason']}")
    if info["n_variables"] == 0:
        out.print(
            "This drawing has 0 variables: nothing may morph yet. Add bounds to the SVG, e.g. "
            'xmlns:dm="urn:deepmorph:1" dm:move="0.5" on the root <svg> (see docs/bounds.md), '
            "or pass defaults such as --move 0.5."
        )


def capacity(
    svg: SvgArg,
    move: MoveOpt = None,
    shift: ShiftOpt = None,
    scale: ScaleOpt = None,
    rotate: RotateOpt = None,
    crc: Annotated[
        Optional[int],
        typer.Option("--crc", help="CRC bits: 8, 10-16 (default: the codec's choice; colour at least 12)."),
    ] = None,
    drop: DropOpt = False,
    pixels: Annotated[
        Optional[int],
        typer.Option("--pixels", min=8, max=10000, help="The print's smallest width in the photo, in pixels."),
    ] = None,
    print_mm: Annotated[
        Optional[float], typer.Option("--print-mm", help="The printed width in mm (with --distance-cm).")
    ] = None,
    distance_cm: Annotated[
        Optional[float], typer.Option("--distance-cm", help="The camera's distance from the print in cm.")
    ] = None,
    frame_px: Annotated[
        int, typer.Option("--frame-px", min=16, help="The photo's long side in pixels (1080p phone: 1920).")
    ] = 1920,
    fov_deg: Annotated[
        float, typer.Option("--fov-deg", help="The camera's field of view across that side, in degrees.")
    ] = 65.0,
    read_in: Annotated[ReadIn, setting_option("read_in")] = DEFAULTS.read_in,
    as_json: JsonOpt = False,
) -> None:
    """Predict the payload a drawing carries before training: its readable variables, the
    largest payload that reads from 99 % of captures, and what limits it; with how far its
    variables move in a photo at 96, 150, 200 and 300 px across (and at --pixels, or at the
    width a --print-mm print has at --distance-cm). From 200 px up the payload is planned from how
    well photos of the print show the drawing's moves, measured in about half a minute."""
    from deepmorph_core.capacity import PIXELS_MEASURED, at_pixels, for_print, predict, with_channel
    from deepmorph_core.print_size import legibility, pixels_across, plan, plan_sizes, rows_to_json
    from deepmorph_core.reading_channel import channel_for, channel_name

    if crc is not None and crc not in CRC_WIDTHS[1:]:
        raise typer.BadParameter(f"expected 8 or 10 to 16, got {crc}", param_hint="--crc")
    if (print_mm is None) != (distance_cm is None):
        raise typer.BadParameter("give both --print-mm and --distance-cm, or neither", param_hint="--print-mm")
    if print_mm is not None and pixels is not None:
        raise typer.BadParameter("give --pixels or --print-mm/--distance-cm, not both", param_hint="--pixels")
    if print_mm is not None and distance_cm is not None:
        pixels = pixels_across(print_mm, distance_cm, frame_px, fov_deg)
    drawing = _load(svg, move, shift, scale, rotate, drop).read_in(channel_for(read_in))
    report = predict(drawing, crc_bits=crc)
    if report.readable_groups and not as_json:  # the plan from PIXELS_MEASURED px up starts from the channel there
        err.print(f"measuring how photos of a print {PIXELS_MEASURED} px wide show its moves (about half a minute) ...")
    report = with_channel(report, drawing)
    read_in = channel_name(drawing.channel)
    sizes = plan(drawing, report.visible_mask, plan_sizes(pixels), report, DEFAULTS.width, crc)
    train_px = int(pixels) if pixels is not None and at_pixels(int(pixels)) else None
    report = for_print(report, train_px, crc)  # the model to train for a print that wide
    if drawing.colour and report.readable_groups:  # some colour drawings are hard to find in photos
        report = _found(report, drawing, _bounds(move, shift, scale, rotate), train_px, not as_json)
    camera = {"print_mm": print_mm, "distance_cm": distance_cm, "frame_px": frame_px, "fov_deg": fov_deg}
    # a model reads prints at least as wide as its decoder's frame (the default one before training)
    legible = None if pixels is None else legibility(pixels, DEFAULTS.width, print_mm, frame_px, fov_deg)
    if as_json:
        plan_json = {
            "pixels": pixels,
            "camera": camera if print_mm is not None else None,
            "legibility": None if legible is None else legible.to_json(),
            "sizes": rows_to_json(sizes),
        }
        print_json({"svg": str(svg), "reading_channel": read_in, **report.to_json(), "print_size": plan_json})
        return
    spec = report.codec
    hidden = report.n_variables - report.visible
    rows = [
        (
            "read in",
            read_in if read_in == "luminance" else f"{read_in} (its colours differ far more there than in luminance)",
        ),
        ("variables", f"{report.n_variables} ({report.visible} visible, {hidden} change nothing a renderer shows)"),
        ("readable", f"{report.readable_groups} (visible variables, look-alikes counted once)"),
        ("code bits", f"{report.code_bits} read reliably (predicted)"),
        (
            "payload",
            "none predicted to read from 99 % of captures"
            if spec is None
            else f"{report.payload_bits} bits at 99 % (CRC {spec.crc_bits}, BCH t={spec.bch_t}: "
            f"{spec.code_bits} code bits); train with "
            + (f"--pixels {train_px} " if train_px is not None else "")
            + "--payload-bits auto",
        ),
    ]
    table = Table(title=safe(svg), show_header=False)
    table.add_column("what")
    table.add_column("value", overflow="fold")
    for k, v in rows:
        table.add_row(k, v)
    out.print(table)
    for line in report.limits():
        out.print(f"limit: {safe(line)}")
    _print_sizes(sizes, pixels, print_mm, distance_cm, frame_px, fov_deg)
    if legible is not None:
        out.print(safe(legible.sentence()))


def _found(
    report: CapacityReport, drawing: MorphableDrawing, bounds: dict[str, Any], print_px: int | None, say: bool
) -> CapacityReport:
    """``report`` with how often the photo chain finds ``drawing``'s prints in simulated hard
    photos (:func:`~deepmorph_detect.findable.findability`), for a model trained with the default
    ``bounds`` (:func:`_bounds`) for prints ``print_px`` wide."""
    from dataclasses import replace

    from deepmorph_core.morphable import bound_defaults
    from deepmorph_detect.findable import SHOTS, findability

    if say:
        err.print(f"simulating {SHOTS} hard photos to see how often its prints are found (a few seconds) ...")
    defaults = bound_defaults(**bounds).model_dump(exclude_none=True)
    found = findability(drawing, defaults, print_px, shots=SHOTS)
    return replace(report, found=(found.found, found.shots))


def _print_sizes(
    sizes: list[Any], pixels: float | None, print_mm: float | None, distance_cm: float | None, frame_px: int, fov: float
) -> None:
    """The travel table of ``capacity``: how far the visible variables move at each print width."""
    from deepmorph_core.print_size import READING_NOTE

    if print_mm is not None:
        out.print(
            f"a {print_mm:g} mm print at {distance_cm:g} cm spans {pixels:.0f} px of a {frame_px}-px, {fov:g}° frame"
        )
    table = Table(title="moves in the photo (control points across each variable's range), and the payload")
    for column in ("print width", "median move", "smallest move", "under 1 px", "payload bits"):
        table.add_column(column, justify="right")
    for row in sizes:
        mark = " ←" if pixels is not None and abs(row.pixels - pixels) < 0.5 else ""
        table.add_row(f"{row.pixels:.0f} px{mark}", f"{row.median_move:.1f} px", f"{row.smallest_move:.1f} px",
                      str(row.sub_pixel), row.payload_text)  # fmt: skip
    out.print(table)
    out.print(f"note: {READING_NOTE}")


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
    as_json: JsonOpt = False,
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
    if as_json:
        print_json({"written": [str(out_path)], "variables": md.n_variables, "seed": seed})
        return
    out.print(f"wrote {out_path} (random morph of {md.n_variables} variables, seed {seed})")


def render(
    svg: SvgArg,
    out_path: Annotated[Path, typer.Option("--out", help="Output PNG.")],
    size: Annotated[
        int, typer.Option("--width-px", min=8, max=4096, help="Width of the PNG in pixels (the height follows).")
    ] = 256,
    soft: Annotated[bool, typer.Option("--soft", help="Use the soft (differentiable) rasterizer.")] = False,
    overlay_base: Annotated[
        Optional[Path],
        typer.Option("--base", help="A base drawing (the unmorphed one, say) drawn in red under the SVG."),
    ] = None,
    drop: DropOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Render a drawing with the real renderer (resvg) or the soft rasterizer."""
    from deepmorph_core.image_io import image_format, save_gray, save_rgb
    from deepmorph_core.render import overlay

    refuse_to_overwrite(out_path, "--out", [("input drawing", svg), ("base drawing", overlay_base)])
    image_format(out_path)
    ink = _render_ink(svg, size, soft, drop)
    if overlay_base is None:
        save_gray(1.0 - ink, out_path)
    else:
        base = _render_ink(overlay_base, size, soft, drop)
        if base.shape != ink.shape:
            raise DeepMorphError(f"{overlay_base}: its aspect ratio differs from {svg}'s; cannot overlay")
        save_rgb(overlay(base, ink), out_path)
    renderer = "soft" if soft else "resvg"
    if as_json:
        print_json({"written": [str(out_path)], "width": ink.shape[1], "height": ink.shape[0], "renderer": renderer})
        return
    out.print(f"wrote {out_path} ({ink.shape[1]}x{ink.shape[0]}, {renderer})")


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
    payload_bits: Annotated[
        str,
        typer.Option(
            "--payload-bits",
            help="Payload length in bits (1-256), or auto: the largest `deepmorph capacity` predicts to read.",
        ),
    ] = str(PAYLOAD_BITS),
    crc: Annotated[
        Optional[int],
        typer.Option(
            "--crc",
            help="CRC bits: 8, 10-16 (default: 8, 16 above 32 payload bits; colour 12 or more; auto as counted).",
        ),
    ] = None,
    ecc_t: Annotated[Optional[int], typer.Option("--ecc-t", min=0, max=16, help="BCH correctable bit errors.")] = None,
    steps: Annotated[int, setting_option("steps")] = DEFAULTS.steps,
    batch: BatchOpt = DEFAULTS.batch,
    width: ImageWidthOpt = DEFAULTS.width,
    print_px: PixelsOpt = DEFAULTS.print_px,
    severity: TrainSeverityOpt = DEFAULTS.severity,
    hard_fraction: Annotated[float, setting_option("hard_fraction")] = DEFAULTS.hard_fraction,
    small_prints: Annotated[float, setting_option("small_prints")] = DEFAULTS.small_prints,
    seed: SeedOpt = DEFAULTS.seed,
    encoder_init: Annotated[Literal["spread", "random"], setting_option("encoder_init")] = DEFAULTS.encoder_init,
    spatial_transformer: Annotated[bool, setting_option("spatial_transformer")] = DEFAULTS.spatial_transformer,
    readout: Annotated[bool, setting_option("readout")] = DEFAULTS.readout,
    early_stop: Annotated[bool, setting_option("early_stop")] = DEFAULTS.early_stop,
    renders_tune: Annotated[int, setting_option("renders_tune")] = DEFAULTS.renders_tune,
    verifier: Annotated[Optional[bool], setting_option("verifier")] = DEFAULTS.verifier,
    trust_samples: Annotated[Optional[int], setting_option("trust_samples")] = DEFAULTS.trust_samples,
    read_in: Annotated[ReadIn, setting_option("read_in")] = DEFAULTS.read_in,
    device: DeviceOpt = DEFAULTS.device,
    shards: Annotated[Optional[int], setting_option("shards")] = DEFAULTS.shards,
    threads: ThreadsOpt = DEFAULTS.threads,
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue the checkpoint at --out (on any number of processes).")
    ] = False,
    checkpoint_every: Annotated[int, setting_option("checkpoint_every")] = DEFAULTS.checkpoint_every,
    move: MoveOpt = None,
    shift: ShiftOpt = None,
    scale: ScaleOpt = None,
    rotate: RotateOpt = None,
    drop: DropOpt = False,
    validation: ValidationOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Train an encoder/decoder pair that hides --payload-bits in the drawing.

    Under `torchrun --nproc_per_node N -m deepmorph train ...` the N processes train it together
    (docs/training.md); the first alone writes and prints.
    """
    settings = chosen(locals())  # first: the options alone
    from deepmorph.training.codec import train_model
    from deepmorph.training.distributed import world_from_env

    def describe(m: dict[str, Any]) -> str:
        return (
            f"stage {m['stage']} loss {m['loss']:.3f} bit acc {m['bit_acc']:.3f} all-bits {m['word_acc']:.2f}"
            f" read {m['read']:.2f}"
        )

    use_threads(threads)
    world = world_from_env()
    with step_progress("training", describe) as on_start:
        summary = train_model(
            svg,
            out_path,
            payload_bits=_payload_bits(payload_bits),
            crc_bits=crc,
            ecc_t=ecc_t,
            resume=resume,
            bounds=_bounds(move, shift, scale, rotate),
            train=settings,
            on_start=on_start,
            on_warning=lambda text: err.print(f"warning: {text}"),
            drop_unsupported=drop,
            validation_samples=_validation_samples(validation),
            on_validation=lambda: err.print("validating on fresh payloads ..."),
            world=world,
            on_verifier=lambda text: err.print(f"proposal verifier: {text} ..."),
        )
    if not world.main:
        return
    if as_json:
        result = training_result(
            summary,
            on_start.last,
            stage2_start=summary.stage2_start,
            stopped_early=summary.stopped_early,
            payload_bits=summary.payload_bits,
            shrunk=[s.model_dump() for s in summary.shrunk],
        )
        verified = summary.verifier.as_json() if summary.verifier else None
        trust = summary.trust.model_dump() if summary.trust else None
        print_json(
            {**result, "validation": [r.model_dump() for r in summary.validation], "trust": trust, "verifier": verified}
        )
        return
    out.print(
        f"wrote {summary.bundle} ({summary.steps} steps in {summary.elapsed_s:.0f} s, stage 2 from step "
        f"{summary.stage2_start}{', stopped early: its batches read well enough' if summary.stopped_early else ''}"
        f"); log {summary.log}" + (f", plot {summary.plot}" if summary.plot else "")
    )
    _print_validation([r.model_dump() for r in summary.validation])
    if summary.trust is not None:
        out.print(f"wrong payloads: {safe(summary.trust.describe())}")
    if summary.verifier is not None:
        out.print(f"verifier: {summary.verifier.text()}")


def train_many(
    folder: Annotated[Path, typer.Argument(help="A folder of .svg drawings.", show_default=False)],
    out_dir: Annotated[Path, typer.Option("--out", help="The folder of bundles: <drawing>.dmm each.")],
    payload_bits: Annotated[
        str, typer.Option("--payload-bits", help="Payload bits for every drawing, or auto: each its predicted size.")
    ] = "auto",
    steps: Annotated[int, setting_option("steps", "Training steps of each drawing.")] = DEFAULTS.steps,
    batch: BatchOpt = DEFAULTS.batch,
    width: ImageWidthOpt = DEFAULTS.width,
    print_px: PixelsOpt = DEFAULTS.print_px,
    severity: TrainSeverityOpt = DEFAULTS.severity,
    seed: SeedOpt = DEFAULTS.seed,
    move: MoveOpt = None,
    device: DeviceOpt = DEFAULTS.device,
    jobs: Annotated[
        Optional[int],
        typer.Option("--jobs", min=1, max=64, help="Worker processes (default: one per CUDA device, one on the CPU)."),
    ] = None,
    threads: ThreadsOpt = DEFAULTS.threads,
    validation: ValidationOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Train every drawing in a folder: done bundles are skipped, checkpoints resumed, one
    process per device; a drawing that fails is reported and the others go on. Exits with 1
    when a drawing failed."""
    settings = chosen(locals())  # first: the options alone
    from deepmorph.training.many import train_many as run

    def progress(result: DrawingResult, finished: int, total: int) -> None:
        what = result.error if result.status == "failed" else f"{result.steps} steps, {result.seconds:.0f} s"
        err.print(f"[{finished}/{total}] {safe(Path(result.drawing).name)}: {result.status} ({safe(what)})")
        for text in result.warnings:
            err.print(f"warning: {safe(text)}")

    results = run(
        folder,
        out_dir,
        payload_bits=_payload_bits(payload_bits),
        bounds={"move": move},
        train=settings,
        device=device,
        jobs=jobs,
        validation_samples=_validation_samples(validation),
        on_result=progress,
    )
    failed = [r for r in results if r.status == "failed"]
    counts = {s: sum(r.status == s for r in results) for s in ("trained", "resumed", "done", "failed")}
    if as_json:
        print_json({"drawings": [r.to_json() for r in results], "counts": counts})
    else:
        table = Table(title=f"{len(results)} drawings: " + ", ".join(f"{n} {s}" for s, n in counts.items() if n))
        for column in ("drawing", "status", "payload bits", "steps", "time", "read", "error"):
            table.add_column(column, overflow="fold")
        for r in results:
            read = ", ".join(f"{name} {rate:.1%}" for name, rate in r.validation.items()) or "-"
            table.add_row(
                safe(Path(r.drawing).name),
                r.status,
                "-" if r.payload_bits is None else str(r.payload_bits),
                "-" if r.steps is None else str(r.steps),
                f"{r.seconds:.0f} s" if r.status in ("trained", "resumed") else "-",
                read,
                safe(r.error or ""),
            )
        out.print(table)
    if failed:
        raise typer.Exit(1)


def _payload_bits(text: str) -> int | Literal["auto"]:
    """``--payload-bits``: a size from 1 to 256, or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        bits = int(text)
    except ValueError:
        bits = 0
    if not 1 <= bits <= 256:
        raise typer.BadParameter(f"expected a number of bits from 1 to 256, or auto; got {text!r}")
    return bits


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
        acc += f", {r['missed']} not found" if r.get("missed") else ""
        lines.append(
            f"{r['name']} ({r['severity']}): {r['read']}/{r['samples']} read ({r['read'] / r['samples']:.1%}), "
            f"{r['wrong']} wrong{acc}; {r['seconds']:.0f} s"
        )
    return lines


def _print_validation(records: list[dict[str, Any]]) -> None:
    for line in _validation_lines(records):
        out.print(f"validation: {safe(line)}")


def _payload_sizing(record: dict[str, Any]) -> str:
    """How the payload's size was chosen, after its number in ``info``."""
    if record.get("payload_auto") is None:
        return ""
    shrunk = record.get("shrunk") or []
    if not shrunk:
        return " (auto)"
    steps = "; then ".join(
        f"{s['payload_bits'][0]} -> {s['payload_bits'][1]} at step {s['step']} ("
        + (
            f"it read {s['read']:.1%} of fresh renders"
            if s.get("measured_on") == "renders"
            else f"its batches read {s['read']:.0%} of code words"
        )
        + f"; its code bits carried about {s['information']:.0f} bits)"
        for s in shrunk
    )
    return f" (auto, sized by training: {steps})"


def info(model: ModelArg, as_json: JsonOpt = False) -> None:
    """Describe a model bundle: payload and code bits, codec, image size, bounds, training record."""
    from deepmorph_core.model import DeepMorphModel

    data = DeepMorphModel.load(model).info()
    data["trained_on"] = _trained_on(data["record"])
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
        ("payload bits", str(data["payload_bits"]) + _payload_sizing(rec)),
        (
            "code bits",
            f"{data['code_bits']} (CRC {codec['crc_bits']}, BCH t={codec['bch_t']}: {codec['ecc_bits']} ECC bits)",
        ),
        ("variables N_v", str(data["n_variables"])),
        ("image size", "x".join(map(str, data["image_size"][::-1]))),
        ("read in", data.get("reading_channel", "luminance")),
        (
            "smallest print",
            f"{data['smallest_print_px']} px across in a photo (trained for prints that wide, --pixels); narrower "
            "ones are reported too small and never read"
            if (data.get("train") or {}).get("print_px")
            else f"{data['smallest_print_px']} px across in a photo (the decoder's frame); narrower ones that do not "
            "read are reported too small",
        ),
        (
            "decoder",
            f"{'spatial transformer, then ' if dec['spatial_transformer'] else ''}CNN "
            f"(stem {dec['stem']}, channels {list(dec['channels'])}, head {dec['hidden']})"
            f"{' + linear readout' if dec.get('readout') else ''}",
        ),
        ("bounds defaults", json.dumps(data["bounds_defaults"]) or "-"),
        (
            "training",
            f"{rec['step']}/{rec['total_steps']} steps, {rec['elapsed_s']:.0f} s on {rec['device']} "
            f"({rec['threads']} threads), stage 2 from {rec['stage2_start']}, "
            f"{'finished' if rec['finished'] else 'checkpoint (resume to finish)'}"
            + (" early: its batches read well enough" if rec.get("stopped_early") else ""),
        ),
        ("trained on", ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in data["trained_on"].items())),
        ("last metrics", json.dumps(rec["metrics"])),
        ("versions", json.dumps(data["versions"])),
    ]
    det = data["detector"]
    if det is None:
        rows.append(
            ("detector", "the shipped universal one (`deepmorph train-detector` fine-tunes one for this drawing)")
        )
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
    ver = data["verifier"]
    if ver is not None:
        c = ver["check"]
        rows.append(
            (
                "verifier",
                f"threshold {ver['threshold']:.3g}; held-out scenes {c['scenes']}: prints kept "
                f"{c['prints_kept']}/{c['prints']}, other proposals turned away "
                f"{c['others_turned_away']}/{c['others']}; {ver['elapsed_s']:.0f} s "
                f"({ver['threads']} thread{'s' if ver['threads'] != 1 else ''})",
            )
        )
    for run in data["tuning"]:
        rows.append(
            (
                "decoder tuned",
                f"{run['steps']}/{run['total_steps']} steps, {run['elapsed_s']:.0f} s"
                + (f" on {run['device']}" if "device" in run else "")  # none in tunings from before it was recorded
                + f", small prints {run['small_prints']:.0%}, bit acc {run.get('bit_acc', float('nan')):.4f}"
                + ("" if run["finished"] else " (interrupted)"),
            )
        )
    for line in _validation_lines(data["validation"]) or ["none (run `deepmorph validate MODEL --save`)"]:
        rows.append(("validated", line))
    if data.get("trust"):
        rows.append(("wrong payloads", data["trust"]["text"]))
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


def _trained_on(record: dict[str, Any]) -> dict[str, Any]:
    """How the codec was trained: device, processes and global batch (``"not recorded"`` in
    bundles written before they were)."""
    return {
        "device": record["device"],
        "world_size": record.get("world_size") or "not recorded",
        "global_batch": record.get("global_batch") or "not recorded",
    }


def tune_decoder(
    model: ModelArg,
    out_path: Annotated[Path, typer.Option("--out", help="Bundle to write (may be the same file).")],
    steps: Annotated[int, setting_option("steps", settings=TuneSettings)] = TUNE_DEFAULTS.steps,
    small_prints: Annotated[float, setting_option("small_prints", settings=TuneSettings)] = TUNE_DEFAULTS.small_prints,
    lr: Annotated[float, setting_option("lr", settings=TuneSettings)] = TUNE_DEFAULTS.lr,
    seed: SeedOpt = 0,
    threads: ThreadsOpt = None,
    validation: ValidationOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Train a trained model's decoder further, encoder frozen: printed codes and the detector stay valid."""
    from deepmorph.training.codec import tune_decoder as tune
    from deepmorph_core.model import DeepMorphModel

    use_threads(threads)
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
    validation_records = DeepMorphModel.load(out_path).info()["validation"]
    if as_json:
        print_json({"written": [str(out_path)], "bundle": str(out_path), "run": run, "validation": validation_records})
        return
    out.print(f"wrote {out_path} ({run['steps']} steps in {run['elapsed_s']:.0f} s, bit acc {run['bit_acc']:.4f})")
    _print_validation(validation_records)


def validate(
    model: ModelArg,
    samples: Annotated[
        int, typer.Option("--samples", min=1, max=100_000, help="Payloads read from renders.")
    ] = RENDER_SAMPLES,
    photos: Annotated[
        int, typer.Option("--photos", min=0, max=100_000, help="Payloads read from close-up photos.")
    ] = PHOTO_SAMPLES,
    trust: Annotated[
        int,
        typer.Option(
            "--trust",
            min=0,
            max=100_000,
            help="Also count wrong payloads in this many hard close-ups, six CRC bits unchecked (training's "
            "count; the code is never changed here).",
        ),
    ] = 0,
    seed: SeedOpt = 0,
    save: Annotated[bool, typer.Option("--save", help="Store the result in the bundle (shown by info).")] = False,
    threads: ThreadsOpt = None,
    device: DeviceOpt = "auto",
    as_json: JsonOpt = False,
) -> None:
    """Read fresh random payloads back from renders and photos: what the model really reads."""
    from deepmorph.training.trust import measure_trust, trust_warning
    from deepmorph.training.validation import validate as run_validation
    from deepmorph.training.validation import validation_warning
    from deepmorph_core.device import resolve_device
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.plugins import default_registry
    from deepmorph_detect.close_up_pool import one_per_thread

    use_threads(threads)
    where = resolve_device(device)
    m = DeepMorphModel.load(model)
    records = run_validation(m, default_registry(), samples, photos, seed=seed, device=where)
    counted = measure_trust(m, trust, seed, workers=one_per_thread()) if trust and m.codec.spec.crc_bits else None
    if save:
        m.meta.validation = records
        m.meta.trust = counted or m.meta.trust
        m.save(model)
    dumped = [r.model_dump() for r in records]
    if as_json:
        trusted = None if counted is None else counted.model_dump()
        print_json({"model": str(model), "validation": dumped, "trust": trusted, "saved": save})
    else:
        _print_validation(dumped)
        if counted is not None:
            out.print(f"wrong payloads: {safe(counted.describe())}")
    warnings = [validation_warning(records, str(model), own_detector=m.meta.detector is not None)]
    warnings.append(trust_warning(counted, str(model)) if counted is not None else None)
    for warning in filter(None, warnings):
        err.print(f"warning: {safe(warning)}")


def encode(
    model: ModelArg,
    payload: Annotated[
        str,
        typer.Option(
            "--payload",
            help="Hex (0x...), a decimal number (0d...) or a bit string of exactly the model's payload length.",
        ),
    ],
    out_path: Annotated[
        Path, typer.Option("--out", help="The code to write: .svg, .pdf (vector) or .png, by its extension.")
    ],
    png: Annotated[Optional[Path], typer.Option("--png", help="Also render a PNG for printing.")] = None,
    pdf: Annotated[Optional[Path], typer.Option("--pdf", help="Also write a vector PDF at the print's size.")] = None,
    width_mm: Annotated[
        float, typer.Option("--width-mm", min=1, max=2000, help="Printed width of every file written, in mm.")
    ] = 50.0,
    dpi: Annotated[int, typer.Option("--dpi", min=50, max=2400, help="Printer resolution of a PNG.")] = 300,
    as_json: JsonOpt = False,
) -> None:
    """Hide a payload in the model's drawing and write it at its printed size: an SVG (width and
    height in mm), a vector PDF page or a print-ready PNG, all or none."""
    from deepmorph_core.code import FILE_FORMATS, print_pixels
    from deepmorph_core.fileio import atomic_write_all
    from deepmorph_core.model import DeepMorphModel

    targets = [("--out", out_path, FILE_FORMATS.get(out_path.suffix.lower(), ""))]
    targets += [(option, path, fmt) for option, path, fmt in (("--png", png, "PNG"), ("--pdf", pdf, "PDF")) if path]
    for i, (option, path, fmt) in enumerate(targets):
        earlier = [(f"file given with {o}", p) for o, p, _ in targets[:i]]
        refuse_to_overwrite(path, option, [("model file", model), *earlier])
        if not fmt:
            raise DeepMorphError(f"--out {path}: a code is written as .svg, .pdf or .png; name it so")
        if FILE_FORMATS.get(path.suffix.lower()) != fmt:
            raise DeepMorphError(f"{option} {path}: this file is a {fmt}; name it .{fmt.lower()}")
    if any(fmt == "PNG" for *_, fmt in targets):
        px = print_pixels(width_mm, dpi)  # refused here, before any work, when too large
    code = DeepMorphModel.load(model).code(payload)
    atomic_write_all([(path, code.file(fmt, width_mm, dpi)) for _, path, fmt in targets])  # every one or none
    written = [f"{path} ({px} px wide at {dpi} dpi)" if fmt == "PNG" else str(path) for _, path, fmt in targets]
    listed = ", ".join(written[:-1]) + (" and " if len(written) > 1 else "") + written[-1]
    if as_json:
        print_json({"written": [str(path) for _, path, _ in targets], "payload": code.payload.to_json()})
        return
    out.print(f"wrote {listed} carrying {code.payload.hex}, {width_mm:g} x {code.height_mm(width_mm):.4g} mm")


def register(cli: typer.Typer) -> None:
    """Add the drawing and model commands to ``cli``."""
    add_commands(
        cli,
        (
            ("list-primitives", list_primitives, PANEL_DRAWINGS),
            ("inspect", inspect, PANEL_DRAWINGS),
            ("capacity", capacity, PANEL_DRAWINGS),
            ("morph", morph, PANEL_DRAWINGS),
            ("render", render, PANEL_DRAWINGS),
            ("train", train, PANEL_MODELS),
            ("train-many", train_many, PANEL_MODELS),
            ("tune-decoder", tune_decoder, PANEL_MODELS),
            ("info", info, PANEL_MODELS),
            ("validate", validate, PANEL_MODELS),
            ("encode", encode, PANEL_CODES),
        ),
    )
