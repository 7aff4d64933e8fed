"""Two bundles' photo chains side by side on the same scenes, with QR's time in the same run.

Both bundles must hold the same drawing and code (say, one with a retrained detector). For each
severity, ``--n`` scenes (640x480, one print, one other icon, one ArUco marker) are decoded by
both chains, in alternating order, and OpenCV's QR ``detectAndDecode`` runs on a same-size
frame holding a QR code between them; then ``--negatives`` scenes without the drawing. The
table gives prints found and read, wrong payloads reported ok, corner error, and the median
time per frame with its ratio to QR's and to the first bundle's. The machine is noisy: the
ratios, taken in one run, are what to read.

    .venv/bin/python bench/side_by_side.py --b slim.dmm --n 200 --negatives 300
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import set_threads  # noqa: E402
from _pairs import add_scene_arguments, compare, print_report  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", type=Path, default=None, help="first bundle (default: the bundled ghost)")
    ap.add_argument("--b", type=Path, required=True, help="second bundle (the same drawing and code)")
    add_scene_arguments(ap, "side_by_side.json")
    args = ap.parse_args()
    set_threads(args.threads)
    import cv2

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.locate import Locator

    cv2.setNumThreads(args.threads)
    paths = {"a": args.a or BUNDLED_MODEL, "b": args.b}
    models = {k: DeepMorphModel.load(p) for k, p in paths.items()}
    a, b = models["a"], models["b"]
    if a.drawing.to_svg(a.drawing.neutral_values()[0]) != b.drawing.to_svg(b.drawing.neutral_values()[0]) or (
        a.codec.spec != b.codec.spec
    ):
        sys.exit("side_by_side: the two bundles must hold the same drawing and code")
    locators = {k: Locator(m) for k, m in models.items()}

    def locate(k: str, image: Any, camera: Any) -> tuple[float, list[Any]]:
        t0 = time.perf_counter()
        found = locators[k].locate(image, camera)
        return 1000 * (time.perf_counter() - t0), found

    report, rows = compare(a, locate, args)
    names = {k: str(p) for k, p in paths.items()}
    report["bundles"] = names
    print_report(report, rows, names, "bundle", args.out)


if __name__ == "__main__":
    main()
