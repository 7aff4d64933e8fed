"""Colour models read back: each trained panel drawing's payload, validation and training time,
next to the same drawing flattened to black and white.

The panel is :mod:`bench/colour.py`'s, by its rule. Train each drawing as a user would, on one
thread with the other core idle, then point this script at the bundles:

    for n in flat-color-icons/{bar-chart,crystal-oscillator,reading,switch-camera} \\
             fluent-emoji-flat/{face-without-mouth,pink-heart,backhand-index-pointing-left-light,books}; do
      deepmorph train ../shared/data/drawings/$n.svg --move 0.5 --payload-bits auto \\
        --threads 1 --out bench/results/colour_models/$(basename $n).dmm
    done
    .venv/bin/python bench/colour_reading.py bench/results/colour_models/*.dmm

For every bundle: the render validation its training ended with (``medium`` colour corruption),
``--close-ups`` fresh close-ups at ``medium`` and ``--hard`` at ``hard`` (printed through the
colour plugins, read by the photo chain with the model's detector, else the universal one;
``--detector none``: whole images only),
false accepts on ``--unrelated`` images that show none of the bundles' drawings (other icons of
``--icons``, rendered and photographed, noise and clutter: ``bench/capacity.py``'s set), the
minutes and threads of its training, the capacity ``deepmorph capacity`` predicts for it, and
for the drawing flattened to black and white (each paint black where its luminance is under 0.5, else white, opaque) the
predicted capacity and the soft rasterizer's time per training batch beside the colour one's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

COLOUR_PROPERTIES = ("fill", "stroke")


def flattened(svg_text: str) -> str:
    """The drawing with every paint opaque black or white by its luminance (gradients by their
    mean's): the black-and-white drawing with the same shapes and variables."""
    from lxml import etree

    from deepmorph_core.svg.gradients import Gradients
    from deepmorph_core.svg.style import parse_colour, style_declarations

    root = etree.fromstring(svg_text.encode("utf-8"))
    gradients = Gradients.from_root(root)

    def flat(value: str) -> str:
        text = value.strip()
        if text.lower() in ("none", "currentcolor", "inherit"):
            return text
        if text.lower().startswith("url(#"):
            paint = gradients.paint(text[5:].split(")")[0].strip("'\""))
        else:
            paint = parse_colour(text, "paint")
        if paint is None:
            return "none"
        return "#000" if paint.luminance < 0.5 else "#fff"

    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        for prop in ("opacity", "fill-opacity", "stroke-opacity"):
            element.attrib.pop(prop, None)
        for prop in COLOUR_PROPERTIES:
            if element.get(prop) is not None:
                element.set(prop, flat(element.get(prop)))
        if element.get("style"):
            decls = style_declarations(element.get("style"))
            decls = {k: (flat(v) if k in COLOUR_PROPERTIES else v) for k, v in decls.items() if "opacity" not in k}
            element.set("style", "; ".join(f"{k}: {v}" for k, v in decls.items()))
    return etree.tostring(root, encoding="unicode")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bundles", type=Path, nargs="+", help="trained colour bundles (.dmm)")
    p.add_argument("--close-ups", type=int, default=200, help="close-ups at medium severity per bundle (0: none)")
    p.add_argument("--hard", type=int, default=200, help="close-ups at hard severity per bundle (0: none)")
    p.add_argument("--unrelated", type=int, default=1000, help="unrelated images for false accepts (0: none)")
    p.add_argument("--icons", type=Path, default=None, help="a folder of other drawings for the unrelated images")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--print-px", type=float, default=None,
                   help="close-ups with the drawing about this many camera pixels wide (default: 144-192 px "
                        "in 240-px photos, or as wide as a --pixels model was trained for)")  # fmt: skip
    p.add_argument("--detector", help="the detector (default: the model's, else universal; none: whole images)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", default=str(RESULTS / "colour_reading.json"))
    args = p.parse_args(argv)
    threads = set_threads(args.threads)

    from capacity import unrelated_images
    from colour import raster_seconds

    from deepmorph_core.capacity import predict
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.morphable import MorphableDrawing
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import validate_close_ups

    started = time.perf_counter()
    models = [(path, DeepMorphModel.load(path)) for path in args.bundles]
    exclude = {Path(m.meta.drawing_name).stem for _, m in models}
    unrelated = unrelated_images(args.unrelated, args.icons, exclude, args.seed) if args.unrelated else []
    rows = []
    for path, model in models:
        meta = model.meta
        svg = meta.drawing_svg
        colour = model.drawing
        bounds = {k: tuple(v) if isinstance(v, list) else v for k, v in meta.bounds_defaults.items()}
        flat = MorphableDrawing.load(flattened(svg).encode("utf-8"), label=path.name, **bounds)
        records = {r.name: r for r in meta.validation}
        renders = records.get("renders")
        rec = meta.record
        det = args.detector
        close = hard = None
        if args.close_ups:
            close = validate_close_ups(model.eval(), args.close_ups, args.seed, "medium", args.print_px, det)
        if args.hard:
            hard = validate_close_ups(model.eval(), args.hard, args.seed + 1, "hard", args.print_px, det)
        locator = Locator(model, detector=det)
        accepts = sum(bool(found.result.ok) for _, image in unrelated for found in locator.locate(image))
        rows.append(
            {
                "drawing": meta.drawing_name,
                "variables": colour.n_variables,
                "payload_bits": model.codec.spec.payload_bits,
                "smallest_print_px": model.smallest_print_px,
                "predicted_colour": predict(colour).payload_bits,
                "predicted_flattened": predict(flat).payload_bits,
                "renders": None if renders is None else renders.read / renders.samples,
                "renders_wrong": None if renders is None else renders.wrong,
                "close_ups": None if close is None else close.read / close.samples,
                "close_ups_wrong": None if close is None else close.wrong,
                "hard": None if hard is None else hard.read / hard.samples,
                "hard_wrong": None if hard is None else hard.wrong,
                "false_accepts": accepts,
                "unrelated": len(unrelated),
                "train_minutes": round(rec.elapsed_s / 60, 1),
                "train_threads": rec.threads,
                "steps": rec.step,
                "raster_s_colour": raster_seconds(colour, model.width),
                "raster_s_flattened": raster_seconds(flat, model.width),
            }
        )
    print("Colour panel, trained with --payload-bits auto (medium validation; b/w: the same shapes flattened):")
    print(
        table(
            [
                "drawing",
                "N_v",
                "bits",
                "px",
                "pred.",
                "pred. b/w",
                "renders",
                "wrong",
                "close-ups",
                "wrong",
                "hard",
                "wrong",
                "false acc.",
                "min",
                "thr",
                "raster s",
                "b/w raster s",
            ],  # fmt: skip
            [
                [
                    r["drawing"],
                    r["variables"],
                    r["payload_bits"],
                    r["smallest_print_px"],
                    r["predicted_colour"],
                    r["predicted_flattened"],
                    r["renders"],
                    r["renders_wrong"],
                    r["close_ups"],
                    r["close_ups_wrong"],
                    r["hard"],
                    r["hard_wrong"],
                    f"{r['false_accepts']}/{r['unrelated']}",
                    r["train_minutes"],
                    r["train_threads"],
                    r["raster_s_colour"],
                    r["raster_s_flattened"],
                ]  # fmt: skip
                for r in rows
            ],
        )
    )
    out = write_json(
        args.out,
        {
            "benchmark": "colour_reading",
            "environment": {**environment(), "threads": threads},
            "rows": rows,
            "wall_s": time.perf_counter() - started,
        },
    )
    print(f"\nwrote {out} ({time.perf_counter() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
