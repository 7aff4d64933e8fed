"""The channel a drawing's morph variables form: how many payload bits a perfect decoder could read.

For each drawing of bench/capacity.py's panel: the encoder's spread start at one code bit per
group of look-alike variables (:func:`deepmorph_core.networks.spread_weights`), ``--samples``
resvg renders of random codes at 96 px framed by their ink as decoding frames photos, then the
photometric steps of the ``medium`` corruption (blur, motion blur, light, contrast, noise, JPEG;
its residual perspective, scale, turn and shift left out, so alignment counts as perfect). A
ridge map from the pixels to each group's encoder output, fitted on all but the last 1000
renders and measured on those, gives the rms error ``sigma`` of reading the group, in units of
its range (the full morph is 1). From ``sigma``, per readable group: the capacity of a Gaussian
channel whose input is limited to that range (Blahut-Arimoto) and its dispersion. Over the
groups: their sum, the same for one bit per group (today's code), and the normal approximation
of the information bits a code of that many symbols carries with 99 % of its words right
(Polyanskiy, Poor and Verdu 2010); less the default CRC, the payload a perfect decoder could
carry at 99 %, and its ratio to the visible variables.

``--pixels 96,200,300`` reads each drawing once per print width in the photo, at that width,
with the capture's blur and motion in the camera's pixels (``deepmorph train --pixels``); a
bare run reads at 96 px as a default model does. ``--standardise`` puts each image at zero
mean and unit variance before the ridge map (a linear reading that ignores contrast).

``--reader cnn`` reads the groups with the project's decoder CNN trained as a regressor of their
positions (``--cnn-steps``, fresh corruption each step) instead of a ridge map, each group set
anywhere in its range (``--continuous``; a regression of one-bit positions measures how well a
reader tells two apart, not how finely it places them). A print wider than 96 px is area-averaged
into the decoder's 96-px frame, as the photo chain frames it.

Beside each ceiling, the project's own figure as a share of it: the payload ``deepmorph capacity
--pixels`` plans for prints that wide (``planned``: from 200 px a model trained with ``--pixels``,
below it the default one), and what trained models read (``read``): with ``--measured``, the
largest payload bench/capacity.py's default models read at 99 % (close-ups whose prints span
144-192 px, shown at 96 px); with ``--measured-pixels``, bench/pixels_panel.py's ``--pixels``
models, each close-up width they passed at (>= 99 % medium, >= 95 % hard, no wrong payload)
shown on the widest row at or below it (240 px on the 200-px row, 330 on the 300-px row).
``--panel pixels`` measures bench/pixels_panel.py's drawings instead of bench/capacity.py's
(``held-out``: capacity's held-out icons). ``--tabulate RUN.json`` prints a saved run's tables
again with these columns, measuring nothing.

``--undone-warp`` reads each drawing a second time through ``medium``'s residual warp, its
photometric steps and the warp's exact inverse: alignment still perfect, but the picture
resampled twice, as a photo's view is. ``--bundles`` reads trained models' drawings with the
same codes through the whole ``medium`` corruption and each model's spatial transformer
instead: what their alignment leaves on top of the photometric noise.

    .venv/bin/python bench/channel.py --feather /work/shared/data/drawings/feather
    .venv/bin/python bench/channel.py --feather ... --only airplay,flag --undone-warp --bundles m1.dmm m2.dmm
    .venv/bin/python bench/channel.py --feather ... --pixels 96,200,300 --standardise --measured capacity.json
    .venv/bin/python bench/channel.py --feather ... --tabulate channel.json --measured capacity.json
    .venv/bin/python bench/channel.py --feather ... --panel pixels --pixels 96,200,300 --standardise \
        --measured-pixels pixels_panel.json

A linear reading is not the best one, so ``sigma`` is what a linear decoder meets, and the
payload a ceiling for decoders that read no better; a trained model's bit errors sit at that
level, while ``--reader cnn`` places the groups more finely.
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

from deepmorph_core.channel import (  # noqa: E402
    GROUPS_WIDTH,
    TEST_SAMPLES,
    ChannelTable,
    channel_table,
    corrupted,
    framed_renders,
    group_codes,
    information_at,
    medium_steps,
    payload_within,
    ridge_rms,
)

WIDTH = GROUPS_WIDTH
#: the CNN reader's batch and peak learning rate (one-cycle schedule)
CNN_BATCH, CNN_LR = 32, 2e-3
#: the CNN reader's stride-2 layers in a frame wider than the decoder's (no full-resolution stem)
WIDE_FRAME = (16, 32, 48, 64, 64)
#: the views of a panel drawing (``--undone-warp`` adds the second)
PERFECT, UNDONE = "perfect alignment", "medium's warp undone exactly"


def group_sigma(
    drawing: Any, views: dict[str, Callable[[Any, Any], Any]], args: argparse.Namespace, width: int = WIDTH
) -> tuple[dict[str, np.ndarray], int]:
    """Rms error of reading each readable group of ``drawing`` through each view's steps (the
    same renders of the spread start, framed ``width`` pixels wide), and the visible variables
    (groups and visibility judged at :data:`WIDTH`). The groups are set by one code bit each, or
    with ``--continuous`` (always for ``--reader cnn``) anywhere between: a regression of binary
    positions measures how well a reader classifies, not how finely it reads positions."""
    codes = group_codes(drawing, args.samples + TEST_SAMPLES, args.seed, continuous_inputs(args))
    renders = framed_renders(drawing, codes.unit, width)
    targets = codes.targets
    sigmas = {}
    for view, steps in views.items():
        if args.reader == "cnn":
            sigmas[view] = cnn_rms(renders, targets, steps, args.cnn_steps, args.seed + 2, args.cnn_width)
        else:
            seen = corrupted(renders, steps, args.seed + 2, standardise=args.standardise)
            sigmas[view] = ridge_rms(seen, targets, TEST_SAMPLES, width)
    return sigmas, codes.visible


def continuous_inputs(args: argparse.Namespace) -> bool:
    """Whether the groups are read at positions anywhere in their range (not one bit each)."""
    return args.continuous or args.reader == "cnn"


def reader_name(args: argparse.Namespace) -> str:
    """The table's name of the reading: ``linear`` or ``cnn``, and the inputs it read."""
    frame = f" at {args.cnn_width} px" if args.reader == "cnn" and args.cnn_width != WIDTH else ""
    return f"{args.reader}{frame}{', continuous' if continuous_inputs(args) else ''}"


def cnn_rms(
    renders: Any,
    targets: np.ndarray,
    steps: Callable[[Any, Any], Any],
    train_steps: int,
    seed: int,
    frame: int = WIDTH,
) -> np.ndarray:
    """Rms error per target column of the project's decoder CNN (:class:`~deepmorph_core.networks.Decoder`)
    trained as a regressor of the targets: ``train_steps`` Adam steps of :data:`CNN_BATCH`
    renders of all but the last :data:`TEST_SAMPLES`, each through ``steps`` afresh and
    area-averaged into a ``frame``-pixel frame as the photo chain frames a wider print; measured
    on the last ones, each seen once. At :data:`WIDTH` px the decoder is the default one; in a
    wider frame its first layer is strided (:data:`WIDE_FRAME`), so that it costs about as much."""
    import torch
    import torch.nn.functional as F

    from deepmorph_core.networks import Decoder, DecoderConfig

    fit = len(renders) - TEST_SAMPLES
    wanted = torch.from_numpy(targets).float()

    def framed(images: Any, generator: Any) -> Any:
        seen = steps(images, generator)
        return seen if seen.shape[-1] == frame else F.interpolate(seen, size=(frame, frame), mode="area")

    torch.manual_seed(seed)
    net = Decoder(
        targets.shape[1], (frame, frame), None if frame == WIDTH else DecoderConfig(stem=0, channels=WIDE_FRAME)
    )
    optimiser = torch.optim.Adam(net.parameters(), lr=CNN_LR / 2)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, CNN_LR, total_steps=train_steps)
    generator = torch.Generator().manual_seed(seed)
    for _ in range(train_steps):
        rows = torch.randint(0, fit, (CNN_BATCH,), generator=generator)
        with torch.no_grad():
            seen = framed(renders[rows], generator)
        loss = F.mse_loss(torch.sigmoid(net(seen)), wanted[rows])
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
    net.eval()
    generator = torch.Generator().manual_seed(seed + 1)
    with torch.no_grad():
        read = torch.cat(
            [torch.sigmoid(net(framed(renders[i : i + 250], generator))) for i in range(fit, len(renders), 250)]
        )
    return ((read - wanted[fit:]) ** 2).mean(0).sqrt().numpy().astype(np.float64)


def undone_warp(width: int, print_px: int | None = None) -> Callable[[Any, Any], Any]:
    """``medium``'s residual warp, then its photometric steps, then the warp's exact inverse:
    perfect alignment that pays for resampling the picture twice, as a photo's view is."""
    import torch

    from deepmorph_core.corruption import fused_matrices, warp_white

    geometry = medium_steps(width, geometric=True).steps
    light = medium_steps(width, geometric=False, print_px=print_px)

    def steps(images: Any, generator: Any) -> Any:
        _, matrix = fused_matrices(geometry, images, generator)
        seen = light(warp_white(images, matrix), generator=generator)
        return warp_white(seen, torch.linalg.inv(matrix))

    return steps


def measure_drawing(
    name: str, svg: Path, move: float | None, args: argparse.Namespace, table_: ChannelTable
) -> list[dict]:
    """A panel drawing read with perfect alignment (the photometric steps of ``medium``) and,
    with ``--undone-warp``, through :func:`undone_warp` too (the same codes); with ``--pixels``,
    once per print width, read at that width with the capture in the camera's pixels."""
    from deepmorph_core.morphable import MorphableDrawing

    drawing = MorphableDrawing.load(svg, **({} if move is None else {"move": move}))
    results = []
    for print_px in args.pixels or [None]:
        width = print_px or WIDTH
        pipeline = medium_steps(width, geometric=False, print_px=print_px)
        views = {PERFECT: lambda x, g, pipeline=pipeline: pipeline(x, generator=g)}
        if args.undone_warp:
            views[UNDONE] = undone_warp(width, print_px)
        start = time.perf_counter()
        sigmas, visible = group_sigma(drawing, views, args, width)
        seconds = round(time.perf_counter() - start, 1)
        results += [
            {
                "name": name,
                "view": view,
                "reader": reader_name(args),
                "print_px": width,
                "camera_pixels": print_px is not None,
                "variables": drawing.n_variables,
                "visible": visible,
                **channel_summary(sigma, visible, table_),
                "seconds": seconds,
            }
            for view, sigma in sigmas.items()
        ]
    return results


def measure_bundle(path: Path, args: argparse.Namespace, table_: ChannelTable) -> dict:
    """A trained model's drawing read through the whole ``medium`` corruption and the model's
    spatial transformer: what its alignment leaves (the same codes as :func:`measure_drawing`)."""
    from deepmorph_core.corruption import build_pipeline
    from deepmorph_core.model import DeepMorphModel

    start = time.perf_counter()
    model = DeepMorphModel.load(path).eval()
    if model.width != WIDTH:
        raise SystemExit(f"{path}: the model reads {model.width} px; this benchmark measures {WIDTH} px")
    pipeline = build_pipeline("medium", WIDTH)
    align = model.decoder.align

    def steps(images: Any, generator: Any) -> Any:
        view = pipeline(images, generator=generator)
        return view if align is None else align(view)

    sigmas, visible = group_sigma(model.drawing, {"model": steps}, args)
    sigma = sigmas["model"]
    return {
        "name": f"{model.meta.drawing_name} ({path.name})",
        "view": "medium, the model's spatial transformer",
        "reader": reader_name(args),
        "variables": model.drawing.n_variables,
        "visible": visible,
        **channel_summary(sigma, visible, table_),
        "seconds": round(time.perf_counter() - start, 1),
    }


def channel_summary(sigma: np.ndarray, visible: int, table_: ChannelTable) -> dict:
    """What groups read with rms errors ``sigma`` carry: summed capacity, the same with one bit
    per group, the information a code carries at :data:`WORD_RATE`, its payload and ratio."""
    capacity, dispersion, binary = table_(sigma)
    information = information_at(float(capacity.sum()), float(dispersion.sum()), len(sigma))
    payload = payload_within(information)
    return {
        "readable_groups": len(sigma),
        "sigma": [round(float(s), 4) for s in sigma],
        "sigma_median": float(np.median(sigma)),
        "sigma_worst": float(sigma.max()),
        "capacity_bits": float(capacity.sum()),
        "binary_bits": float(binary.sum()),
        "information_at_99": information,
        "payload_at_99": payload,
        "ratio": payload / visible if visible else 0.0,
    }


HEADERS = [
    "drawing", "view", "reader", "print px", "visible", "readable groups", "sigma median", "sigma worst",
    "capacity bits", "one bit per group", "information bits at 99 %", "payload at 99 %", "payload / visible",
    "planned", "planned / ceiling", "read", "read / ceiling",
]  # fmt: skip


def _px(result: dict) -> str:
    """A row's print width: ``200 (camera)`` when its capture is in camera pixels."""
    return f"{result.get('print_px', WIDTH)}{' (camera)' if result.get('camera_pixels') else ''}"


def _share(part: int | None, ceiling: int) -> float | None:
    """``part`` as a share of the ceiling's payload (``None`` where either is missing or 0)."""
    return None if part is None or not ceiling else round(part / ceiling, 2)


def rows(results: list[dict]) -> list[list[Any]]:
    return [
        [
            r["name"], r["view"], r.get("reader", "linear"), _px(r), r["visible"], r["readable_groups"],
            round(r["sigma_median"], 3), round(r["sigma_worst"], 3),
            round(r["capacity_bits"], 1), round(r["binary_bits"], 1), round(r["information_at_99"], 1),
            r["payload_at_99"], round(r["ratio"], 2),
            r.get("planned_payload"), _share(r.get("planned_payload"), r["payload_at_99"]),
            r.get("read_payload"), _share(r.get("read_payload"), r["payload_at_99"]),
        ]
        for r in results
    ]  # fmt: skip


def measured_reads(paths: list[Path]) -> dict[str, int]:
    """``drawing -> largest payload read at 99 %`` from bench/capacity.py's JSON, read as that
    benchmark reads it (:func:`capacity.measured_sizes`; later files win, a broken one is named)."""
    from capacity import measured_sizes

    out: dict[str, int] = {}
    for (name, bits), size in measured_sizes(paths).items():
        out[name] = max(out.get(name, 0), bits if size["passed"] else 0)
    return out


def measured_pixels_reads(paths: list[Path]) -> dict[tuple[str, int], int]:
    """``(drawing, close-up width) -> payload read`` from bench/pixels_panel.py's JSON: each width
    a model passed at (>= its bars on medium and hard close-ups, no wrong payload), else 0;
    later files win, a broken one is named."""
    from pixels_panel import width_passes

    out: dict[tuple[str, int], int] = {}
    for path in paths:
        try:
            for r in json.loads(path.read_text())["results"]:
                for width in r["close_ups"]["medium"]:
                    out[(r["drawing"], int(width))] = r["payload_bits"] if width_passes(r["close_ups"], width) else 0
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise SystemExit(f"--measured-pixels {path}: not a bench/pixels_panel.py result ({exc})") from None
    return out


@functools.cache
def planned_payload(svg: Path, move: float | None, print_px: int) -> int:
    """The payload ``deepmorph capacity --pixels print_px`` plans for a panel drawing (from
    200 px a ``--pixels`` model's plan, below it the default one)."""
    from deepmorph_core.capacity import payload_for_width, predict, with_channel
    from deepmorph_core.morphable import MorphableDrawing

    drawing = MorphableDrawing.load(svg, **({} if move is None else {"move": move}))
    return payload_for_width(with_channel(predict(drawing), drawing), print_px, needs_px=0)[0] or 0


def with_figures(
    results: list[dict],
    reads: dict[str, int],
    drawings: dict[str, tuple[Path, float | None]],
    pixels_reads: dict[tuple[str, int], int] | None = None,
    widths: list[int] | None = None,
) -> None:
    """Each row of a panel drawing given the project's figures: ``planned_payload`` at its print
    width (:func:`planned_payload`, where a row lacks it), ``read_payload`` on the 96-px rows from
    ``reads`` and on wider rows from ``pixels_reads`` (each measured width on the widest row at or
    below it, among ``widths``, by default the rows')."""
    widths = widths or sorted({r.get("print_px", WIDTH) for r in results})
    for r in results:
        if r["name"] not in drawings:
            continue  # a bundle's row
        px = r.get("print_px", WIDTH)
        if r.get("planned_payload") is None:
            r["planned_payload"] = planned_payload(*drawings[r["name"]], px)
        if px == WIDTH and r["name"] in reads:
            r["read_payload"] = reads[r["name"]]
        for (name, measured_px), payload in (pixels_reads or {}).items():
            if name == r["name"] and px > WIDTH and max(w for w in widths if w <= measured_px) == px:
                r["read_payload"] = payload


def summary(done: list[dict]) -> list[str]:
    """Per view and print width: the ceiling's payload per visible variable (median, worst,
    best), and the project's figures as shares of the ceiling (median, worst)."""
    lines = []
    for view in (PERFECT, UNDONE):
        for px in sorted({_px(r) for r in done}, key=lambda text: int(text.split()[0])):
            here = [r for r in done if r["view"] == view and _px(r) == px]
            if not here:
                continue
            ratios = [r["ratio"] for r in here]
            line = (f"payload / visible at 99 %, {view}, {px} px: median {statistics.median(ratios):.2f}, "
                    f"worst {min(ratios):.2f}, best {max(ratios):.2f}")  # fmt: skip
            for key, label in (("planned_payload", "planned"), ("read_payload", "read")):
                shares = [s for r in here if (s := _share(r.get(key), r["payload_at_99"])) is not None]
                if shares:
                    line += f"; {label} / ceiling median {statistics.median(shares):.2f}, worst {min(shares):.2f}"
            lines.append(line)
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--feather", type=Path, required=True, help="the Feather icon folder")
    ap.add_argument("--only", help="comma-separated drawing names of the panel to run")
    ap.add_argument(
        "--panel",
        choices=("capacity", "held-out", "pixels"),
        default="capacity",
        help="bench/capacity.py's panel, its held-out icons, or bench/pixels_panel.py's drawings",
    )
    ap.add_argument("--bundles", type=Path, nargs="*", default=[], help="trained models measured on their own view")
    ap.add_argument("--samples", type=int, default=6000, help="renders the ridge map is fitted on")
    ap.add_argument(
        "--undone-warp", action="store_true", help="also each drawing through medium's warp, undone exactly"
    )
    ap.add_argument(
        "--pixels",
        type=lambda text: [int(v) for v in text.split(",")],
        help="print widths in the photo (e.g. 96,200,300): each read at its width, the capture in camera pixels",
    )
    ap.add_argument("--standardise", action="store_true", help="each image at zero mean and unit variance first")
    ap.add_argument(
        "--reader", choices=("linear", "cnn"), default="linear", help="a ridge map, or the decoder CNN as a regressor"
    )
    ap.add_argument("--cnn-steps", type=int, default=3000, help="training steps of the CNN reader")
    ap.add_argument("--cnn-width", type=int, default=WIDTH, help="the CNN reader's frame in pixels (96: the decoder's)")
    ap.add_argument("--continuous", action="store_true", help="groups anywhere in their range, not one bit each")
    ap.add_argument(
        "--measured", type=Path, nargs="*", default=[], help="bench/capacity.py results: what trained models read"
    )
    ap.add_argument(
        "--measured-pixels",
        type=Path,
        nargs="*",
        default=[],
        help="bench/pixels_panel.py results: what --pixels models read",
    )
    ap.add_argument("--tabulate", type=Path, help="print a saved run's tables again (measures nothing)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "channel.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)
    if args.panel == "pixels":
        from pixels_panel import DRAWINGS
        from time_to_print import pick_drawings

        drawings = [(svg.stem, svg, move) for svg, move, _ in pick_drawings(args.feather, DRAWINGS)]
    else:
        from capacity import panel

        drawings = panel(args.feather, args.panel == "held-out")
    if args.only:
        keep = set(args.only.split(","))
        drawings = [d for d in drawings if d[0] in keep]
    reads = measured_reads(args.measured)
    pixels_reads = measured_pixels_reads(args.measured_pixels)
    by_name = {name: (svg, move) for name, svg, move in drawings}
    if args.tabulate is not None:
        try:
            done = json.loads(args.tabulate.read_text())["drawings"]
        except (OSError, ValueError, KeyError) as exc:
            raise SystemExit(f"--tabulate {args.tabulate}: not a channel benchmark result ({exc})") from None
        with_figures(done, reads, by_name, pixels_reads)
        print(table(HEADERS, rows(done)))
        print("\n".join(summary(done)))
        return
    table_ = channel_table()
    done: list[dict] = []

    def record(result: dict) -> None:
        done.append(result)
        with_figures([result], reads, by_name, pixels_reads, args.pixels or [WIDTH])
        print(table(HEADERS, rows([result])).splitlines()[-1], flush=True)
        write_json(args.out, {"environment": {**environment(), "threads": threads}, "drawings": done})

    for name, svg, move in drawings:
        for result in measure_drawing(name, svg, move, args, table_):
            record(result)
    for bundle in args.bundles:
        record(measure_bundle(bundle, args, table_))
    print(table(HEADERS, rows(done)))
    print("\n".join(summary(done)))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
