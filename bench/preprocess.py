"""Preprocessing before the decoder: the paper's binarisation against the plain rectified view.

The paper blurs the rectified cutout (3x3 Gaussian, sigma 0.95), thresholds it with Otsu, masks
what lies outside a coarse region around the graphic, and blurs it again before decoding
(:func:`paper_preprocess`). Our decoder reads the rectified gray view as it
is. For every drawing found in ``--n`` labelled scenes per severity, this reads the same first
look (the photo aligned to the unmorphed drawing, rectified) three ways: plain, as in the paper,
and with shadows divided out (``flatten_illumination``, what the locator's second look uses);
it reports bit accuracy and whole payloads read right, side by side.

    .venv/bin/python bench/preprocess.py --n 100
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, add_scene_options, environment, load_scene_model, table, write_json  # noqa: E402

MASK_MARGIN = 0.06  # the coarse region: the unmorphed drawing's ink grown by this much of its width


def paper_preprocess(gray: Any, region: Any = None) -> Any:
    """The paper's preprocessing of a rectified cutout, for comparison: a 3x3 Gaussian blur
    (sigma 0.95), Otsu's threshold, everything outside a coarse ``region`` around the graphic
    set to paper, and the same blur again.

    The decoder does not use it: this benchmark measures it against the plain rectified view.

    Args:
        gray: ``(H, W)`` float image, 1 = white.
        region: ``(H, W)`` bool, where the graphic may lie; ``None`` keeps everything.

    Returns:
        ``(H, W)`` float32 in ``[0, 1]``.
    """
    import cv2
    import numpy as np

    u8 = np.clip(gray * 255, 0, 255).astype(np.uint8)
    _, binary = cv2.threshold(cv2.GaussianBlur(u8, (3, 3), 0.95), 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    if region is not None:
        binary[~region] = 255
    return cv2.GaussianBlur(binary, (3, 3), 0.95).astype(np.float32) / 255.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_options(ap, n=100, out=RESULTS / "preprocess.json")
    args = ap.parse_args()
    model_path, model = load_scene_model(args)
    import cv2
    import numpy as np

    from deepmorph_core.image_io import read_image_bgr
    from deepmorph_core.photo import flatten_illumination, to_gray
    from deepmorph_core.render import render_svg
    from deepmorph_detect.camera import project
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.metrics import match_placement
    from deepmorph_detect.read import RECTIFY_WIDTH_FACTOR
    from deepmorph_detect.refine import ImagePyramid, warp_to_template
    from deepmorph_detect.scene_folders import read_scenes, write_scenes

    locator = Locator(model)
    md = model.drawing
    width = model.width * RECTIFY_WIDTH_FACTOR  # the rectified view's width
    ink = render_svg(md.to_svg(md.neutral_values()[0]), width) < 0.5
    k = 2 * round(MASK_MARGIN * width) + 1
    region = cv2.dilate(ink.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
    ways = {
        "plain (ours)": lambda view: view,
        "paper": lambda view: paper_preprocess(view, region),
        "flattened": lambda view: flatten_illumination(view, locator.reader.ink_thickness),
    }
    reports = {}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for sev in args.severities.split(","):
            folder = Path(tmp) / sev
            t0 = time.perf_counter()
            write_scenes(model, folder, args.n, sev, args.seed, distractors=1, aruco=True)
            _, scenes = read_scenes(folder)
            stats = {name: {"bits": 0, "bits_right": 0, "payloads": 0, "read": 0, "wrong_ok": 0} for name in ways}
            for path, truth in scenes:
                gray = to_gray(read_image_bgr(path))
                pyramid = ImagePyramid(gray)
                drawings = [p for p in truth["placements"] if p.kind == "drawing"]
                candidates = locator.detector.detect(gray) if locator.detector is not None else []
                for aligned in locator.aligner.verify(pyramid, candidates):
                    alignment, seen_in = aligned.alignment, aligned.pyramid
                    p = match_placement(project(alignment.homography, locator.frame_corners), drawings)
                    if p is None:
                        continue
                    code = model.codec.encode(p.payload)
                    # one width for every view, which the paper's region mask is drawn at
                    view = warp_to_template(seen_in, alignment.homography, locator.template, width)
                    for name, prepare in ways.items():
                        s = stats[name]
                        s["payloads"] += 1
                        reading = locator.reader.read(prepare(view), soft=True)
                        if reading is None:
                            s["bits"] += len(code)
                            continue
                        result, probs = reading.result, reading.probabilities
                        s["bits"] += len(code)
                        s["bits_right"] += int(((probs > 0.5) == code).sum())
                        right = bool(np.array_equal(result.payload, p.payload))
                        s["read"] += bool(result.ok and right)
                        s["wrong_ok"] += bool(result.ok and not right)
            for name, s in stats.items():
                s["bit_accuracy"] = round(s["bits_right"] / max(s["bits"], 1), 4)
                s["payload_success"] = round(s["read"] / max(s["payloads"], 1), 4)
                rows.append([sev, name, s["payloads"], f"{100 * s['bit_accuracy']:.2f} %",
                             f"{100 * s['payload_success']:.1f} %", s["wrong_ok"]])  # fmt: skip
            reports[sev] = stats
            print(f"{sev}: {args.n} scenes in {time.perf_counter() - t0:.0f} s", flush=True)
    print()
    print(table(["severity", "preprocessing", "drawings found", "bit accuracy", "payload read", "wrong ok"], rows))
    write_json(args.out, {"environment": environment(), "model": str(model_path), "severities": reports})


if __name__ == "__main__":
    main()
