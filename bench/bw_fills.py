"""Black-and-white fills near their outlines: the soft raster of filled black-and-white drawings,
evaluated over each fill's whole box (bundles written before) and near its outline (new models).

The drawings are colour drawings flattened to black and white (``bench/colour_reading.py``'s
:func:`flattened`: every paint black or white by its luminance), so that they have a designer's
filled shapes; pass the colour reading panel (``bench/colour.py``'s rule). Per drawing: the
forward and backward pass of a batch of morphs at each setting, timed alternately in one
process; the mean and largest difference between the two renders of the same morphs, and each
one's mean difference to resvg's render of the SVG written for them.

    .venv/bin/python bench/bw_fills.py ../shared/data/drawings/flat-color-icons/bar-chart.svg ...
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402
from colour_reading import flattened  # noqa: E402

#: resvg ink above which a flattened drawing shows anything at all
INK = 0.1
#: the settings compared: whole boxes for black and white (as bundles written before), near outlines
SETTINGS = {"whole box": None, "near outlines": True}


def measure(path: Path, width: int, batch: int, repeats: int, move: float) -> dict[str, Any]:
    """Seconds of a forward and backward pass per setting, how far the two renders differ, and
    how far each is from resvg's render of the same morphs."""
    import torch

    from deepmorph_core.morphable import MorphableDrawing

    drawing = MorphableDrawing.load(flattened(path.read_text()).encode(), label=path.name, move=move)
    rasters = {name: drawing.rasterizer(width, flat_fills=flat) for name, flat in SETTINGS.items()}
    values = drawing.values_from_unit(drawing.random_unit(batch, seed=1))
    times: dict[str, list[float]] = {name: [] for name in rasters}
    renders: dict[str, torch.Tensor] = {}
    for _ in range(repeats + 1):  # the first round warms up and is not counted
        for name, raster in rasters.items():
            inputs = values.clone().requires_grad_(True)
            start = time.perf_counter()
            image = raster(inputs)
            image.sum().backward()
            times[name].append(time.perf_counter() - start)
            renders[name] = image.detach()
    real = 1.0 - drawing.render_real(values, width)  # resvg's ink of the same morphs
    fills = sum(mode == "fill" for prim in drawing.drawing.primitives for mode, _ in prim.style.paints)
    seconds = {name: statistics.median(t[1:]) for name, t in times.items()}
    before, after = seconds["whole box"], seconds["near outlines"]
    apart = (renders["whole box"] - renders["near outlines"]).abs()
    return {
        "drawing": path.stem,
        "path": str(path),
        "variables": drawing.n_variables,
        "fills": fills,
        "black_and_white": not drawing.colour,
        # flattened, a drawing of light paints is white on white paper: nothing to read or train
        "shows_ink": bool(real.amax() > INK),
        "seconds": seconds,
        "speedup": before / after,
        "mean_difference": float(apart.mean()),
        "max_difference": float(apart.max()),
        "mean_difference_to_resvg": {name: float((image - real).abs().mean()) for name, image in renders.items()},
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("drawings", nargs="+", type=Path, help="colour SVGs, flattened to black and white here")
    p.add_argument("--width", type=int, default=96)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--move", type=float, default=0.5)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", type=Path, default=RESULTS / "bw_fills.json")
    args = p.parse_args(argv)
    threads = set_threads(args.threads)
    rows = [measure(path, args.width, args.batch, args.repeats, args.move) for path in args.drawings]
    print(f"Soft raster of {args.batch} morphs, forward + backward, {args.width} px, {threads} thread(s):")
    print(
        table(
            [
                "drawing",
                "variables",
                "fills",
                "shows ink",
                "whole box s",
                "near outlines s",
                "speed-up",
                "mean / max difference",
                "to resvg: whole box / near outlines",
            ],
            [
                [
                    r["drawing"],
                    r["variables"],
                    r["fills"],
                    "yes" if r["shows_ink"] else "no (white on white)",
                    round(r["seconds"]["whole box"], 3),
                    round(r["seconds"]["near outlines"], 3),
                    round(r["speedup"], 1),
                    f"{r['mean_difference']:.1e} / {r['max_difference']:.3f}",
                    "{:.4f} / {:.4f}".format(*r["mean_difference_to_resvg"].values()),
                ]
                for r in rows
            ],
        )
    )
    speedups = sorted(r["speedup"] for r in rows if r["shows_ink"])
    if speedups:
        print(
            f"speed-up where a drawing shows ink: median {statistics.median(speedups):.1f}x, least {speedups[0]:.1f}x"
        )
    settings = {**vars(args), "drawings": [str(d) for d in args.drawings], "out": str(args.out)}
    write_json(args.out, {"environment": environment(), "threads": threads, "args": settings, "drawings": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
