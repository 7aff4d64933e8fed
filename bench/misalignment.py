"""How far off an alignment a model's decoder still reads: close-ups read at their true pose with
its corners moved.

For close-ups of fresh payloads (``deepmorph_detect.photo_validation.close_ups``, by ``--seed``
as ``bench/close_up_failures.py`` draws them), each print's true outline (``CloseUp.homography``)
has its four corners moved in random directions, their rms move ``--errors`` of the print's
width, and the view that outline rectifies is read by the model's decoder alone, once framed
where the outline puts the unmorphed drawing's ink (the chain's *framed by the template* look)
and once by the photo's own ink (its first look). A view reads when its payload is the right
one by the code alone (soft decoding, no checks). The table says which share reads at each error:
how precisely the chain must align a print for its first reading to carry the word, to set beside
the chain's alignment errors on the prints it misses (``bench/close_up_failures.py --at-truth``).

    .venv/bin/python bench/misalignment.py model.dmm --close-ups 100 --severity medium
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

FRAMINGS = ("template's ink", "photo's ink")


def moved_outline(truth: np.ndarray, corners: np.ndarray, error: float, rng: np.random.Generator) -> np.ndarray:
    """The homography (SVG units -> photo pixels) taking ``corners`` (the viewBox's) to where
    ``truth`` puts them, each moved in a random direction, their rms move ``error`` of the
    print's width there."""
    import cv2

    from deepmorph_detect.camera import project

    quad = project(truth, corners)
    width = float(np.linalg.norm(quad[1] - quad[0]))
    move = rng.normal(size=(4, 2))
    move *= error * width / np.sqrt((move**2).sum(axis=1).mean())
    return cv2.getPerspectiveTransform(corners.astype(np.float32), (quad + move).astype(np.float32)).astype(np.float64)


def read_share(model: Any, samples: int, seed: int, severity: str, errors: list[float]) -> dict[str, list[float]]:
    """Per framing (:data:`FRAMINGS`), the share of ``samples`` close-ups whose view at each
    error of ``errors`` reads the right payload."""
    from deepmorph_detect.camera import viewbox_corners
    from deepmorph_detect.locate import NO_DETECTOR, Locator
    from deepmorph_detect.photo_validation import close_ups

    locator = Locator(model, detector=NO_DETECTOR)  # aligned at the truth: nothing to find
    reader = locator.reader
    corners = viewbox_corners(locator.template.viewbox).astype(np.float64)
    rng = np.random.default_rng(seed + 1000)
    right = np.zeros((len(FRAMINGS), len(errors)))
    for shot in close_ups(model, samples, seed, severity):
        _, _, pyramid = locator.frame(shot.photo, None)
        for j, error in enumerate(errors):
            view = reader.rectify(pyramid, moved_outline(shot.homography, corners, error, rng))
            for i, moments in enumerate((reader.template_moments, None)):
                reading = reader.read(view, True, moments)
                right[i, j] += bool(
                    reading is not None and reading.result.ok and np.array_equal(reading.result.payload, shot.payload)
                )
    return {framing: [round(v / samples, 3) for v in right[i]] for i, framing in enumerate(FRAMINGS)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("models", nargs="+", type=Path, help="trained bundles (.dmm)")
    p.add_argument("--close-ups", type=int, default=100)
    p.add_argument("--severity", default="medium")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--errors", default="0,0.005,0.01,0.02,0.03", help="corner moves, shares of the print's width")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", type=Path, default=RESULTS / "misalignment.json")
    args = p.parse_args(argv)
    set_threads(args.threads)
    from deepmorph_core.model import DeepMorphModel

    errors = [float(e) for e in args.errors.split(",") if e]
    start = time.perf_counter()
    rows = []
    for path in args.models:
        model = DeepMorphModel.load(path).eval()
        shares = read_share(model, args.close_ups, args.seed, args.severity, errors)
        rows += [{"model": path.stem, "framed by": framing, "read": share} for framing, share in shares.items()]
    headers = ["model", "framed by", *(f"{100 * e:g} %" for e in errors)]
    print(f"\n{args.close_ups} {args.severity} close-ups read at their true pose, corners moved by a share of the")
    print("print's width (rms); the share of views whose payload is right by the code alone:")
    print(table(headers, [[r["model"], r["framed by"], *(f"{100 * v:.0f} %" for v in r["read"])] for r in rows]))
    write_json(args.out, {"benchmark": "misalignment", "environment": environment(), "severity": args.severity,
                          "close_ups": args.close_ups, "seed": args.seed, "errors": errors, "rows": rows,
                          "wall_s": round(time.perf_counter() - start, 1)})  # fmt: skip
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
