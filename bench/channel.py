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

``--undone-warp`` reads each drawing a second time through ``medium``'s residual warp, its
photometric steps and the warp's exact inverse: alignment still perfect, but the picture
resampled twice, as a photo's view is. ``--bundles`` reads trained models' drawings with the
same codes through the whole ``medium`` corruption and each model's spatial transformer
instead: what their alignment leaves on top of the photometric noise.

    .venv/bin/python bench/channel.py --feather /work/shared/data/drawings/feather
    .venv/bin/python bench/channel.py --feather ... --only airplay,flag --undone-warp --bundles m1.dmm m2.dmm

A linear reading is not the best one, so ``sigma`` is what a linear decoder meets, and the
payload a ceiling for decoders that read no better; the CNN's bit errors sit at that level.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

WIDTH = 96
TEST_SAMPLES = 1000
RIDGE = 10.0
GRAM_BLOCK = 8192
WORD_RATE = 0.99
GEOMETRIC_STEPS = {"perspective", "scale", "rotation", "translation"}
SIGMA_GRID = np.linspace(0.02, 0.6, 59)
#: the views of a panel drawing (``--undone-warp`` adds the second)
PERFECT, UNDONE = "perfect alignment", "medium's warp undone exactly"


# -- the channel of one variable ---------------------------------------------------------------


def gaussian_channel(levels: np.ndarray, sigma: float, outputs: int) -> np.ndarray:
    """``P(y | x)`` of ``y = x + N(0, sigma^2)`` for inputs ``levels`` in ``[0, 1]``, ``y`` on a
    grid of ``outputs`` points reaching five ``sigma`` beyond the range: ``(len(levels), outputs)``."""
    y = np.linspace(-5 * sigma, 1 + 5 * sigma, outputs)
    channel = np.exp(-((y[None] - levels[:, None]) ** 2) / (2 * sigma**2))
    return channel / channel.sum(1, keepdims=True)


def information_density(p: np.ndarray, channel: np.ndarray) -> np.ndarray:
    """``log2 P(y | x) / P(y)`` (bits) for the input distribution ``p``."""
    return np.log2(channel / (p @ channel)[None] + 1e-300)


def amplitude_limited(sigma: float, inputs: int = 41, outputs: int = 801, iters: int = 600) -> tuple[float, float]:
    """Capacity (bits) and dispersion (bits^2) of the Gaussian channel with its input held to
    ``[0, 1]``: Blahut-Arimoto over ``inputs`` evenly spaced levels."""
    channel = gaussian_channel(np.linspace(0.0, 1.0, inputs), sigma, outputs)
    p = np.full(inputs, 1.0 / inputs)
    for _ in range(iters):
        p *= np.exp2((channel * information_density(p, channel)).sum(1))
        p /= p.sum()
    info = information_density(p, channel)
    capacity = float((p[:, None] * channel * info).sum())
    dispersion = float((p[:, None] * channel * (info - capacity) ** 2).sum())
    return capacity, dispersion


def binary_input(sigma: float, outputs: int = 2001) -> float:
    """Capacity (bits) of the same channel with the input at one end or the other (one bit per group)."""
    p = np.array([0.5, 0.5])
    channel = gaussian_channel(np.array([0.0, 1.0]), sigma, outputs)
    return float((p[:, None] * channel * information_density(p, channel)).sum())


class ChannelTable:
    """Capacity, dispersion and binary capacity against sigma, computed once and interpolated."""

    def __init__(self) -> None:
        rows = [(*amplitude_limited(s), binary_input(s)) for s in SIGMA_GRID]
        self.capacity, self.dispersion, self.binary = (np.array(col) for col in zip(*rows))

    def __call__(self, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s = np.clip(sigma, SIGMA_GRID[0], SIGMA_GRID[-1])
        return tuple(np.interp(s, SIGMA_GRID, col) for col in (self.capacity, self.dispersion, self.binary))


def information_at(capacity: float, dispersion: float, symbols: int, word_rate: float = WORD_RATE) -> float:
    """Normal approximation of the information bits a code of ``symbols`` uses of channels with
    summed ``capacity`` and ``dispersion`` carries with ``word_rate`` of its words right."""
    if symbols == 0:
        return 0.0
    q = statistics.NormalDist().inv_cdf(word_rate)
    return max(0.0, capacity - math.sqrt(dispersion) * q + 0.5 * math.log2(symbols))


def payload_within(information_bits: float) -> int:
    """The largest payload whose bits and default CRC fit in ``information_bits`` (0 if none)."""
    from deepmorph_core.codec import choose_codec

    for payload in range(int(information_bits), 0, -1):
        if payload + choose_codec(payload, bch_t=0).crc_bits <= information_bits:
            return payload
    return 0


# -- reading the groups ------------------------------------------------------------------------


def ridge_rms(pixels: np.ndarray, targets: np.ndarray, test: int, width: int = WIDTH) -> np.ndarray:
    """Rms error per target column of a ridge map fitted on all rows but the last ``test``.

    Solved in its dual form (the Gram matrix of the fitted rows, accumulated in float64 over
    blocks of pixels), which gives the primal's weights and needs no pixels-by-pixels matrix:
    a 300-px frame has 90,000. The ridge grows with the frame's area (:data:`RIDGE` at
    :data:`WIDTH` px, times ``(width / WIDTH)^2``), so that wider frames are regularised alike."""
    fit, held = slice(None, -test), slice(-test, None)
    mean_x, mean_t = pixels[fit].mean(0, dtype=np.float64), targets[fit].mean(0)
    rows = len(pixels)
    gram = np.zeros((rows, rows))
    for lo in range(0, pixels.shape[1], GRAM_BLOCK):
        block = pixels[:, lo : lo + GRAM_BLOCK].astype(np.float64) - mean_x[lo : lo + GRAM_BLOCK]
        gram += block @ block.T
    fitted = gram[fit, fit].copy()
    fitted[np.diag_indices_from(fitted)] += RIDGE * (width / WIDTH) ** 2
    dual = np.linalg.solve(fitted, targets[fit] - mean_t)
    return np.sqrt(((gram[held, fit] @ dual + mean_t - targets[held]) ** 2).mean(0))


def medium_part(width: int, geometric: bool, print_px: int | None = None) -> Any:
    """The ``medium`` corruption with only its geometric steps (``geometric``) or without them;
    with ``print_px``, its pixel parameters the camera's for a print that many pixels wide."""
    from deepmorph_core.corruption import AugmentPipeline
    from deepmorph_core.severity import residual_steps

    steps = [
        {"name": name, "p": p, "params": params}
        for name, p, params in residual_steps("medium", width, print_px=print_px)
        if (name in GEOMETRIC_STEPS) == geometric
    ]
    return AugmentPipeline({"steps": steps})


def framed_renders(drawing: Any, unit: Any, width: int) -> Any:
    """resvg renders of the encoder outputs ``unit`` (B, N_v), framed by their ink: (B, 1, H, W)."""
    from deepmorph_core.framing import frame_renders

    real = drawing.render_real(drawing.values_from_unit(unit), width)
    return frame_renders(real, drawing.neutral_moments(width), tuple(real.shape[-2:]))


def corrupted(
    images: Any, steps: Callable[[Any, Any], Any], seed: int, batch: int = 500, standardise: bool = False
) -> np.ndarray:
    """``steps(images, generator)`` over ``images`` in batches, as float32 rows of pixels; with
    ``standardise``, each row at zero mean and unit variance (a reading that ignores contrast
    and brightness, as a CNN's normalisation does)."""
    import torch

    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        out = [steps(images[i : i + batch], generator) for i in range(0, len(images), batch)]
    flat = torch.cat(out).flatten(1)
    if standardise:
        flat = (flat - flat.mean(1, keepdim=True)) / flat.std(1, keepdim=True).clamp_min(1e-6)
    return flat.numpy()


def group_sigma(
    drawing: Any, views: dict[str, Callable[[Any, Any], Any]], args: argparse.Namespace, width: int = WIDTH
) -> tuple[dict[str, np.ndarray], int]:
    """Rms error of a linear reading of each readable group of ``drawing`` through each view's
    steps (the same renders of the spread start at one code bit per group, framed ``width``
    pixels wide), and the visible variables (groups and visibility judged at :data:`WIDTH`)."""
    import torch

    from deepmorph_core.capacity import INVISIBLE
    from deepmorph_core.networks import spread_weights, twin_groups

    effects = drawing.effects(drawing.rasterizer(WIDTH))
    groups = twin_groups(effects)
    shown = drawing.visibility(WIDTH) > INVISIBLE
    firsts = [members[0] for members, _ in groups if shown[members].any()]
    weights = spread_weights(effects, len(groups), torch.Generator().manual_seed(args.seed))
    rng = np.random.default_rng(args.seed + 1)
    bits = torch.from_numpy(rng.integers(0, 2, (args.samples + TEST_SAMPLES, len(groups))).astype(np.float32))
    unit = torch.sigmoid((2 * bits - 1) @ weights.T)
    renders = framed_renders(drawing, unit, width)
    targets = unit[:, firsts].numpy().astype(np.float64)
    sigmas = {}
    for view, steps in views.items():
        seen = corrupted(renders, steps, args.seed + 2, standardise=args.standardise)
        sigmas[view] = ridge_rms(seen, targets, TEST_SAMPLES, width)
    return sigmas, int(shown.sum())


def undone_warp(width: int, print_px: int | None = None) -> Callable[[Any, Any], Any]:
    """``medium``'s residual warp, then its photometric steps, then the warp's exact inverse:
    perfect alignment that pays for resampling the picture twice, as a photo's view is."""
    import torch

    from deepmorph_core.corruption import fused_matrices, warp_white

    geometry = medium_part(width, geometric=True).steps
    light = medium_part(width, geometric=False, print_px=print_px)

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
        pipeline = medium_part(width, geometric=False, print_px=print_px)
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
    "drawing", "view", "print px", "visible", "readable groups", "sigma median", "sigma worst", "capacity bits",
    "one bit per group", "information bits at 99 %", "payload at 99 %", "payload / visible",
]  # fmt: skip


def _px(result: dict) -> str:
    """A row's print width: ``200 (camera)`` when its capture is in camera pixels."""
    return f"{result.get('print_px', WIDTH)}{' (camera)' if result.get('camera_pixels') else ''}"


def rows(results: list[dict]) -> list[list[Any]]:
    return [
        [
            r["name"], r["view"], _px(r), r["visible"], r["readable_groups"],
            round(r["sigma_median"], 3), round(r["sigma_worst"], 3),
            round(r["capacity_bits"], 1), round(r["binary_bits"], 1), round(r["information_at_99"], 1),
            r["payload_at_99"], round(r["ratio"], 2),
        ]
        for r in results
    ]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--feather", type=Path, required=True, help="the Feather icon folder")
    ap.add_argument("--only", help="comma-separated drawing names of the panel to run")
    ap.add_argument("--held-out", action="store_true", help="the held-out icons instead of the panel")
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
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "channel.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)
    from capacity import panel

    drawings = panel(args.feather, args.held_out)
    if args.only:
        keep = set(args.only.split(","))
        drawings = [d for d in drawings if d[0] in keep]
    table_ = ChannelTable()
    done: list[dict] = []

    def record(result: dict) -> None:
        done.append(result)
        print(table(HEADERS, rows([result])).splitlines()[-1], flush=True)
        write_json(args.out, {"environment": {**environment(), "threads": threads}, "drawings": done})

    for name, svg, move in drawings:
        for result in measure_drawing(name, svg, move, args, table_):
            record(result)
    for bundle in args.bundles:
        record(measure_bundle(bundle, args, table_))
    print(table(HEADERS, rows(done)))
    for view in (PERFECT, UNDONE):
        for px in sorted({_px(r) for r in done}):
            ratios = [r["ratio"] for r in done if r["view"] == view and _px(r) == px]
            if ratios:
                print(f"payload / visible at 99 %, {view}, {px} px: median {statistics.median(ratios):.2f}, "
                      f"worst {min(ratios):.2f}, best {max(ratios):.2f}")  # fmt: skip
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
