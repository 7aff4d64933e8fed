"""The capture simulator's photographs, blurred by OpenCV or by kornia: time and pixels.

Every simulated photo (the scenes of ``deepmorph synth``, the benches and the verifier's
training; the close-ups ``train`` validates on) goes through the capture's blurs: the camera's
blur, motion blur, defocus and the soft edge of a cast shadow. Without a gradient on the CPU they
run through OpenCV's filters (``deepmorph_augment.kernels``); training batches that carry one
run through kornia's convolution. This bench makes the same photos both ways, alternating which
goes first, each seeded alike: ``--scenes`` 1280x720 scenes per severity (one print, one other
drawing, an ArUco marker: the verifier's training scenes) and ``--close-ups`` of
``validate_close_ups``. Per bundle and kind: the median milliseconds a photo each way, their
ratio, and the largest difference between the two photos in gray levels (0-255).

    .venv/bin/python bench/scene_speed.py panel/coffee.dmm panel/cpu.dmm --scenes 40 --close-ups 40
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

WAYS = ("kornia", "opencv")


class Blurs:
    """Switches the capture's blurs between OpenCV and kornia (``deepmorph_augment.kernels``)."""

    def __init__(self) -> None:
        import deepmorph_augment.kernels as kernels

        self.kernels, self.own = kernels, kernels._without_gradient

    def use(self, way: str) -> None:
        self.kernels._without_gradient = self.own if way == "opencv" else (lambda images, kernels: False)


def photo_of(item: Any) -> np.ndarray:
    """A scene's or a close-up's photo as an array."""
    return np.asarray(item.image if hasattr(item, "image") else item.photo)


def compare(make: Callable[[str, int], Any], n: int, blurs: Blurs) -> dict[str, Any]:
    """``n`` photos made both ways by ``make(way, index)``, alternating which goes first."""
    ms: dict[str, list[float]] = {way: [] for way in WAYS}
    largest = 0.0
    for i in range(n):
        photos = {}
        for way in WAYS if i % 2 == 0 else WAYS[::-1]:
            blurs.use(way)
            start = time.perf_counter()
            photos[way] = photo_of(make(way, i))
            ms[way].append(1000 * (time.perf_counter() - start))
        a, b = (photos[way].astype(np.float64) for way in WAYS)
        scale = 255.0 if photos["kornia"].dtype != np.uint8 else 1.0
        largest = max(largest, float(np.abs(a - b).max()) * scale)
    blurs.use("opencv")
    medians = {way: statistics.median(ms[way]) for way in WAYS}
    return {
        "n": n,
        "kornia_ms": round(medians["kornia"], 1),
        "opencv_ms": round(medians["opencv"], 1),
        "ratio": round(medians["opencv"] / medians["kornia"], 3),
        "largest_difference": round(largest, 3),
    }


def run_bundle(path: Path, args: argparse.Namespace, blurs: Blurs) -> list[dict[str, Any]]:
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.photo_validation import close_ups
    from deepmorph_detect.scenes import SceneMaker

    model = DeepMorphModel.load(path)
    rows = []
    for severity in ("medium", "hard"):
        makers = {way: SceneMaker(model, (1280, 720), severity, seed=args.seed, payload_pool=64) for way in WAYS}

        def scene(way: str, i: int, makers: dict[str, Any] = makers) -> Any:
            makers[way].rng = np.random.default_rng([args.seed, i])
            return makers[way].make(drawings=1, distractors=1, aruco=True)

        timed = compare(scene, args.scenes, blurs)
        rows.append({"bundle": path.stem, "photos": f"1280x720 scenes, {severity}", **timed})
    shots: dict[str, Iterator[Any]] = {
        way: close_ups(model, args.close_ups, args.seed, print_px=model.print_px) for way in WAYS
    }
    timed = compare(lambda way, i: next(shots[way]), args.close_ups, blurs)
    rows.append({"bundle": path.stem, "photos": "validation close-ups", **timed})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bundles", type=Path, nargs="*", help="bundles (default: the bundled ghost)")
    ap.add_argument("--scenes", type=int, default=40, help="1280x720 scenes per severity")
    ap.add_argument("--close-ups", type=int, default=40)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "scene_speed.json")
    args = ap.parse_args()
    set_threads(args.threads)
    import cv2

    from deepmorph_core.bundled import BUNDLED_MODEL

    cv2.setNumThreads(args.threads)
    blurs = Blurs()
    rows = [row for path in args.bundles or [BUNDLED_MODEL] for row in run_bundle(path, args, blurs)]
    keys = ["bundle", "photos", "n", "kornia_ms", "opencv_ms", "ratio", "largest_difference"]
    print(table(keys, [[row[k] for k in keys] for row in rows]))
    settings = {k: str(v) for k, v in vars(args).items()}
    write_json(args.out, {"environment": environment(), "args": settings, "rows": rows})


if __name__ == "__main__":
    main()
