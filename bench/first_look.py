"""How far off the photo chain's first look is: close-ups aligned to the unmorphed drawing.

The chain aligns a photo to the *unmorphed* drawing and reads the view that alignment rectifies.
For close-ups of fresh payloads (``deepmorph_detect.photo_validation.close_ups``' prints, placed
by ``close_up_placed``, whose homography says where the print truly lies) whose drawing spans
about ``--widths`` camera pixels, this measures each alignment's offset from the truth over a
9 x 9 grid across the viewBox, as rms pixels of the decoder's frame (its width across the
viewBox) after the per-axis shift and scale that framing by ink removes:

* **first look**: the detector's proposal aligned to the unmorphed drawing (what the first
  looks read);
* **true morph**: the same alignment refined to the print's own morph (its true code), what a
  perfect reading would align to.

The gap between the two is the morph's own pull on the alignment (``docs/design-notes.md``).

    .venv/bin/python bench/first_look.py                          # the bundled ghost
    .venv/bin/python bench/first_look.py model.dmm --widths 96,240,330 --samples 60
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, parse_ints, set_threads, table, write_json  # noqa: E402

GRID = 9


def framed_offset(found: np.ndarray, truth: np.ndarray, viewbox: tuple[float, ...], width: int) -> float:
    """rms offset in pixels of a ``width``-px frame across ``viewbox`` between where ``found``
    and ``truth`` (SVG units -> photo pixels) put the drawing, after the per-axis shift and scale
    that framing by ink removes."""
    x, y, w, h = viewbox
    gx, gy = np.meshgrid(np.linspace(x, x + w, GRID), np.linspace(y, y + h, GRID))
    points = np.stack([gx.ravel(), gy.ravel(), np.ones(GRID * GRID)])
    seen = np.linalg.inv(found) @ truth @ points
    seen = seen[:2] / seen[2]
    left = []
    for axis in range(2):
        fit = np.stack([points[axis], np.ones(GRID * GRID)], 1)
        coef, *_ = np.linalg.lstsq(fit, seen[axis], rcond=None)
        left.append(seen[axis] - fit @ coef)
    return float(np.sqrt(np.mean(np.sum(np.square(left), 0)))) * width / w


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", nargs="*", type=Path, help="trained bundles (default: the bundled ghost)")
    ap.add_argument("--widths", type=parse_ints, default=[96, 150, 240, 330])
    ap.add_argument("--samples", type=int, default=60, help="close-ups per width")
    ap.add_argument("--severity", default="medium")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "first_look.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)

    import torch

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.corruption import build_pipeline
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.check import MORPH_WIDTH
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import PRINT_PX, photo_for_print, printed
    from deepmorph_detect.refine import refine_at
    from deepmorph_detect.scenes import CLOSE_UP_SIZE, close_up_placed, model_added_steps

    rows, results = [], []
    for path in args.bundles or [BUNDLED_MODEL]:
        model = DeepMorphModel.load(path)
        locator = Locator(model)
        viewbox = model.drawing.drawing.viewbox
        md = model.drawing
        colours = build_pipeline(args.severity, PRINT_PX, colour=True, channel=md.channel) if md.colour else None
        added = model_added_steps(model)
        for width in args.widths:
            rng = np.random.default_rng(args.seed + width)
            photo_px = photo_for_print(width)
            art_px = max(PRINT_PX, 2 * round(CLOSE_UP_SIZE[1] * photo_px))
            first, true_morph, missed = [], [], 0
            for _ in range(args.samples):
                code = rng.integers(0, 2, model.codec.spec.code_bits).astype(np.uint8)
                values = model.morph_values(torch.from_numpy(code.astype(np.float32))[None])[0]
                art, paper = printed(model, md.to_svg(values), colours, rng, art_px)
                photo, art_to_image = close_up_placed(art, args.severity, rng, photo_px, extra=added, paper=paper)
                svg_to_art = art.shape[1] / viewbox[2]
                truth = art_to_image @ np.array(
                    [[svg_to_art, 0, -viewbox[0] * svg_to_art], [0, svg_to_art, -viewbox[1] * svg_to_art], [0, 0, 1]]
                )
                aligned = locator.alignments(photo)
                if not aligned:
                    missed += 1
                    continue
                found = aligned[0]
                first.append(framed_offset(found.alignment.homography, truth, viewbox, model.width))
                morph = locator.reader.morphs.of_code(code)
                own = refine_at(found.pyramid, found.alignment.homography, morph, MORPH_WIDTH)
                if own is not None:
                    true_morph.append(framed_offset(own.homography, truth, viewbox, model.width))
            row = {
                "bundle": str(path),
                "print_px": width,
                "samples": args.samples,
                "not_aligned": missed,
                "first_look_median": statistics.median(first) if first else None,
                "first_look_p90": float(np.percentile(first, 90)) if first else None,
                "true_morph_median": statistics.median(true_morph) if true_morph else None,
                "true_morph_p90": float(np.percentile(true_morph, 90)) if true_morph else None,
            }
            results.append(row)
            rows.append(
                [
                    path.stem,
                    width,
                    f"{row['first_look_median']:.2f} / {row['first_look_p90']:.2f}" if first else "-",
                    f"{row['true_morph_median']:.3f} / {row['true_morph_p90']:.3f}" if true_morph else "-",
                    missed,
                ]
            )
            print(f"{path.stem} {width} px done", file=sys.stderr, flush=True)
    print(f"{args.severity} close-ups, offset in px of the decoder's frame (median / 90th percentile)")
    print(table(["bundle", "print px", "first look", "aligned to the true morph", "not aligned"], rows))
    write_json(args.out, {"environment": {**environment(), "threads": threads}, "results": results})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
