"""Two photo chains on the same scenes, in one run: the loop shared by ``side_by_side.py`` (two
bundles) and ``checkouts.py`` (two checkouts of the code).

Each script supplies ``locate(k, image, camera) -> (ms, detections)`` for ``k`` in ``"a"``,
``"b"`` (detections with ``corners`` and ``result.payload``/``result.ok``, as
:func:`~deepmorph_detect.metrics.matched_detections` reads them); this module makes the
scenes, calls both in alternating order with QR's ``detectAndDecode`` timed between them,
scores them, runs the scenes without the drawing, and prints and writes the report.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from _common import RESULTS, environment, frame_size, table, write_json

Locate = Callable[[str, Any, Any], tuple[float, list[Any]]]
CHAINS = ("a", "b")


def add_scene_arguments(ap: argparse.ArgumentParser, out_name: str) -> None:
    """The options both scripts take: scenes per severity, negatives, threads, seed, output."""
    ap.add_argument("--n", type=int, default=200, help="scenes per severity")
    ap.add_argument("--severities", default="medium,hard")
    ap.add_argument("--negatives", type=int, default=300, help="scenes without the drawing")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--frame", type=frame_size, default=(640, 480), help="the scenes' size, WxH (640x480)")
    ap.add_argument("--out", type=Path, default=RESULTS / out_name)


def compare(model: Any, locate: Locate, args: argparse.Namespace) -> tuple[dict[str, Any], list[tuple]]:
    """Both chains on ``args.n`` scenes per severity and ``args.negatives`` without the drawing.

    Returns:
        The report (``severities`` and ``negatives``) and the table's rows.
    """
    import numpy as np

    from deepmorph_detect.baselines import QrClock
    from deepmorph_detect.metrics import SceneTally, corner_error
    from deepmorph_detect.scenes import SceneMaker

    qr = QrClock(model, args.frame, frames=20)  # the QR frames bench-scenes times too
    warm = SceneMaker(model, args.frame, "medium", seed=args.seed + 500)
    for _ in range(3):  # first calls allocate and load; keep them out of the timings
        scene = warm.make(drawings=1)
        for k in CHAINS:
            locate(k, scene.image, scene.camera)
        qr.warm()

    report: dict[str, Any] = {"severities": {}}
    rows: list[tuple] = []
    for sev in args.severities.split(","):
        maker = SceneMaker(model, args.frame, sev, seed=args.seed)
        stats = {k: {"tally": SceneTally(), "ms": [], "corner": []} for k in CHAINS}
        differ = 0
        qr.times.clear()  # this severity's series, from the first QR frame again
        for i in range(args.n):
            scene = maker.make(drawings=1, distractors=1, aruco=True)
            truth = [p for p in scene.placements if p.kind == "drawing"]
            outcome = {}
            for k in CHAINS if i % 2 == 0 else CHAINS[::-1]:
                ms, found = locate(k, scene.image, scene.camera)
                s = stats[k]
                s["ms"].append(ms)
                seen = []
                for d, p, right in s["tally"].add(found, truth):
                    if d.result.ok and right:
                        s["corner"].append(corner_error(d.corners, p.corners))
                    seen.append((p is not None, bool(d.result.ok), bytes(np.asarray(d.result.payload, np.uint8))))
                outcome[k] = sorted(seen)
            differ += outcome["a"] != outcome["b"]
            qr.tick()
        qr_med = 1000 * float(np.median(qr.times))
        a_med = float(np.median(stats["a"]["ms"]))
        sev_report: dict[str, Any] = {"scenes": args.n, "qr_ms_median": round(qr_med, 2), "scenes_differing": differ}
        for k, s in stats.items():
            med, mean = float(np.median(s["ms"])), float(np.mean(s["ms"]))
            corner = round(float(np.median(s["corner"])), 3) if s["corner"] else None
            tally = s["tally"]
            sev_report[k] = {
                "found": tally.found,
                "read": tally.read,
                "wrong_ok": tally.wrong,
                "corner_px_median": corner,
                "ms_median": round(med, 2),
                "ms_mean": round(mean, 2),
                "x_qr": round(med / qr_med, 3),
                "x_a": round(med / a_med, 3),
            }
            found, read = f"{tally.found}/{args.n}", f"{tally.read}/{args.n}"
            rows.append((sev, k, found, read, tally.wrong, corner, round(med, 2), round(mean, 1), round(qr_med, 2),
                         f"{med / qr_med:.2f}x", f"{med / a_med:.2f}x", differ if k == "b" else ""))  # fmt: skip
        report["severities"][sev] = sev_report
        print(f"{sev}: done", flush=True)

    maker = SceneMaker(model, args.frame, "medium", seed=args.seed + 1000)
    negatives = {k: {"images": args.negatives, "detections": 0, "wrong_ok": 0} for k in CHAINS}
    negative_ms: dict[str, list[float]] = {k: [] for k in CHAINS}
    for i in range(args.negatives):
        scene = maker.make(drawings=0, distractors=1 + i % 3, aruco=i % 2 == 0)
        for k in CHAINS if i % 2 == 0 else CHAINS[::-1]:
            ms, found = locate(k, scene.image, scene.camera)
            negative_ms[k].append(ms)
            negatives[k]["detections"] += len(found)
            negatives[k]["wrong_ok"] += sum(bool(d.result.ok) for d in found)
    for k, times in negative_ms.items():
        if times:
            negatives[k]["ms_median"] = round(float(np.median(times)), 2)
            negatives[k]["ms_mean"] = round(float(np.mean(times)), 2)
    report["negatives"] = negatives
    return report, rows


def print_report(report: dict[str, Any], rows: list[tuple], names: dict[str, str], label: str, out: Path) -> None:
    """The table, the negatives per chain (``names``: what each chain is), and the JSON at ``out``."""
    report["environment"] = environment()
    headers = ["severity", label, "found", "read", "wrong ok", "corner px", "ms median", "ms mean", "QR ms"]
    print(table(headers + ["x QR", "x a", "scenes differing"], rows))
    for k in CHAINS:
        negatives = report["negatives"][k]
        found, images = negatives["detections"], negatives["images"]
        times = ""
        if "ms_median" in negatives:
            times = f", median {negatives['ms_median']} ms (mean {negatives['ms_mean']})"
        print(f"{k} ({names[k]}): {found} detections on {images} scenes without the drawing{times}")
    print(f"wrote {write_json(out, report)}")
