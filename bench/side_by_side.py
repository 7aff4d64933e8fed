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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", type=Path, default=None, help="first bundle (default: the bundled ghost)")
    ap.add_argument("--b", type=Path, required=True, help="second bundle (the same drawing and code)")
    ap.add_argument("--n", type=int, default=200, help="scenes per severity")
    ap.add_argument("--severities", default="medium,hard")
    ap.add_argument("--negatives", type=int, default=300, help="scenes without the drawing")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "side_by_side.json")
    args = ap.parse_args()
    set_threads(args.threads)
    import cv2
    import numpy as np

    from deepmorph_core.api import BUNDLED_MODEL
    from deepmorph_core.codemodel import DeepMorphModel
    from deepmorph_detect.benchmark import _corner_error, matched_detections
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.scenes import SceneMaker

    cv2.setNumThreads(args.threads)
    paths = {"a": args.a or BUNDLED_MODEL, "b": args.b}
    models = {k: DeepMorphModel.load(p) for k, p in paths.items()}
    a, b = models["a"], models["b"]
    if a.drawing.to_svg(a.drawing.neutral_values()[0]) != b.drawing.to_svg(b.drawing.neutral_values()[0]) or (
        a.codec.spec != b.codec.spec
    ):
        sys.exit("side_by_side: the two bundles must hold the same drawing and code")
    locators = {k: Locator(m) for k, m in models.items()}
    qr = cv2.QRCodeDetector()
    qr_frames = [
        SceneMaker(a, (640, 480), "medium", seed=99 + i).make(drawings=0, qr="https://deepmorph.example/0xA1B2C3").image
        for i in range(20)
    ]

    def timed(fn, *xs):  # noqa: ANN001, ANN202
        t0 = time.perf_counter()
        out = fn(*xs)
        return out, 1000 * (time.perf_counter() - t0)

    warm = SceneMaker(a, (640, 480), "medium", seed=args.seed + 500)
    for _ in range(3):  # first calls allocate and load; keep them out of the timings
        image = warm.make(drawings=1).image
        for loc in locators.values():
            loc.locate(image)
        qr.detectAndDecode(qr_frames[0])

    report: dict = {"bundles": {k: str(p) for k, p in paths.items()}, "severities": {}}
    rows = []
    for sev in args.severities.split(","):
        maker = SceneMaker(a, (640, 480), sev, seed=args.seed)
        stats = {k: {"found": 0, "read": 0, "wrong_ok": 0, "ms": [], "corner": []} for k in models}
        qr_ms = []
        for i in range(args.n):
            scene = maker.make(drawings=1, distractors=1, aruco=True)
            truth = [p for p in scene.placements if p.kind == "drawing"]
            for k in ("a", "b") if i % 2 == 0 else ("b", "a"):
                dets, ms = timed(locators[k].locate, scene.image, scene.camera)
                s = stats[k]
                s["ms"].append(ms)
                for d, p, right in matched_detections(dets, truth):
                    s["found"] += p is not None
                    s["read"] += bool(d.result.ok and right)
                    s["wrong_ok"] += bool(d.result.ok and not right)
                    if d.result.ok and right:
                        s["corner"].append(_corner_error(d.corners, p.corners))
            qr_ms.append(timed(qr.detectAndDecode, qr_frames[i % len(qr_frames)])[1])
        qr_med = float(np.median(qr_ms))
        sev_report = {"scenes": args.n, "qr_ms_median": round(qr_med, 2)}
        for k, s in stats.items():
            med = float(np.median(s["ms"]))
            sev_report[k] = {
                "found": s["found"],
                "read": s["read"],
                "wrong_ok": s["wrong_ok"],
                "corner_px_median": round(float(np.median(s["corner"])), 3) if s["corner"] else None,
                "ms_median": round(med, 2),
                "ms_mean": round(float(np.mean(s["ms"])), 2),
                "x_qr": round(med / qr_med, 3),
            }
            rows.append(
                (
                    sev,
                    k,
                    f"{s['found']}/{args.n}",
                    f"{s['read']}/{args.n}",
                    s["wrong_ok"],
                    sev_report[k]["corner_px_median"],
                    round(med, 1),
                    round(qr_med, 1),
                    f"{med / qr_med:.2f}x",
                    f"{med / float(np.median(stats['a']['ms'])):.2f}x",
                )
            )
        report["severities"][sev] = sev_report
        print(f"{sev}: done", flush=True)
    maker = SceneMaker(a, (640, 480), "medium", seed=args.seed + 1000)
    negatives = {k: {"images": args.negatives, "detections": 0, "wrong_ok": 0} for k in models}
    for i in range(args.negatives):
        scene = maker.make(drawings=0, distractors=1 + i % 3, aruco=i % 2 == 0)
        for k in models:
            dets = locators[k].locate(scene.image)
            negatives[k]["detections"] += len(dets)
            negatives[k]["wrong_ok"] += sum(bool(d.result.ok) for d in dets)
    report["negatives"] = negatives
    report["environment"] = environment()
    print(
        table(
            ["severity", "bundle", "found", "read", "wrong ok", "corner px", "ms", "QR ms", "x QR", "x a"],
            rows,
        )
    )
    for k in models:
        found = negatives[k]["detections"]
        print(f"{k} ({paths[k]}): {found} detections on {args.negatives} scenes without the drawing")
    print(f"wrote {write_json(args.out, report)}")


if __name__ == "__main__":
    main()
