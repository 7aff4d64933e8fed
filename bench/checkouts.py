"""Two checkouts of the photo chain side by side: the same scenes, the same run, alternating order.

``bench/side_by_side.py`` compares two *bundles* under one checkout. A change to the chain's
code needs the other comparison: the code before the change (a ``git worktree`` of an earlier
commit, say) against the code after it, each with the same bundle, on the same scenes. Each
checkout runs in a worker process of its own that imports the packages from that checkout
(``--a`` and ``--b``: repository roots); this process makes the scenes (with the current
checkout's ``deepmorph synth`` generator), hands each to both workers in alternating order, and
times OpenCV's QR ``detectAndDecode`` on a same-size frame between them. The times are taken
inside the workers, around ``Locator.locate`` alone, so the transfer is not counted. Then
``--negatives`` scenes without the drawing go to both.

The table gives prints found and read, wrong payloads reported ok, corner error, scenes where
the two checkouts differ (found, payload or ok), and the median time per frame with its ratio
to QR's and to the first checkout's. The machine is noisy: the ratios, taken in one run, are
what to read.

    git worktree add /tmp/before HEAD~1
    .venv/bin/python bench/checkouts.py --a /tmp/before --b . --n 300 --negatives 300
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402


def _worker(root: str, bundle: str | None, threads: int, conn: Any) -> None:
    """Serve ``locate`` requests with the packages of the checkout at ``root``."""
    # the editable install's finder would hand out the installed checkout: take it away (the
    # plugins' finders stay), so that every ``deepmorph_*`` import comes from ``root``
    sys.meta_path[:] = [f for f in sys.meta_path if "deepmorph_core" not in _editable_mapping(f)]
    sys.path.insert(0, root)
    import cv2
    import torch

    torch.set_num_threads(threads)
    cv2.setNumThreads(threads)
    import deepmorph_detect
    from deepmorph_core.api import BUNDLED_MODEL
    from deepmorph_core.codemodel import DeepMorphModel
    from deepmorph_detect.locate import Locator

    locator = Locator(DeepMorphModel.load(Path(bundle) if bundle else BUNDLED_MODEL))
    conn.send(str(Path(deepmorph_detect.__file__).resolve().parent.parent))
    while True:
        job = conn.recv()
        if job is None:
            return
        image, camera = job
        t0 = time.perf_counter()
        found = locator.locate(image, camera)
        ms = 1000 * (time.perf_counter() - t0)
        conn.send((ms, [{"corners": d.corners, "payload": d.result.payload, "ok": bool(d.result.ok)} for d in found]))


def _editable_mapping(finder: Any) -> dict[str, str]:
    """The packages a setuptools editable-install finder maps to source folders (else empty)."""
    module = sys.modules.get(getattr(finder, "__module__", ""), None)
    return getattr(module, "MAPPING", {}) if "editable" in getattr(finder, "__module__", "") else {}


def _as_detections(found: list[dict[str, Any]]) -> list[Any]:
    """Worker answers in the shape :func:`~deepmorph_detect.benchmark.matched_detections` reads."""
    return [
        SimpleNamespace(corners=f["corners"], result=SimpleNamespace(payload=f["payload"], ok=f["ok"])) for f in found
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", type=Path, required=True, help="first checkout (repository root): the code before")
    ap.add_argument("--b", type=Path, default=Path("."), help="second checkout: the code after (default: this one)")
    ap.add_argument("--bundle", type=Path, default=None, help="bundle both decode with (default: the bundled ghost)")
    ap.add_argument("--n", type=int, default=200, help="scenes per severity")
    ap.add_argument("--severities", default="medium,hard")
    ap.add_argument("--negatives", type=int, default=300, help="scenes without the drawing")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "checkouts.json")
    args = ap.parse_args()
    set_threads(args.threads)
    import cv2
    import numpy as np

    from deepmorph_core.api import BUNDLED_MODEL
    from deepmorph_core.codemodel import DeepMorphModel
    from deepmorph_detect.benchmark import _corner_error, matched_detections
    from deepmorph_detect.scenes import SceneMaker

    cv2.setNumThreads(args.threads)
    model = DeepMorphModel.load(args.bundle or BUNDLED_MODEL)
    ctx = mp.get_context("spawn")
    roots = {"a": str(args.a.resolve()), "b": str(args.b.resolve())}
    conns, procs = {}, []
    for k, root in roots.items():
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_worker, args=(root, str(args.bundle) if args.bundle else None, args.threads, child))
        proc.start()
        procs.append(proc)
        conns[k] = parent
    for k, conn in conns.items():
        loaded = conn.recv()
        if Path(loaded) != Path(roots[k]):
            sys.exit(f"checkouts: worker {k} imported the packages from {loaded}, not {roots[k]}")

    def locate(k: str, image: np.ndarray, camera: Any) -> tuple[float, list[dict[str, Any]]]:
        conns[k].send((image, camera))
        return conns[k].recv()

    qr = cv2.QRCodeDetector()
    qr_frames = [
        SceneMaker(model, (640, 480), "medium", seed=99 + i)
        .make(drawings=0, qr="https://deepmorph.example/0xA1B2C3")
        .image
        for i in range(20)
    ]
    warm = SceneMaker(model, (640, 480), "medium", seed=args.seed + 500)
    for _ in range(3):  # first calls allocate and load; keep them out of the timings
        scene = warm.make(drawings=1)
        for k in conns:
            locate(k, scene.image, scene.camera)
        qr.detectAndDecode(qr_frames[0])

    report: dict[str, Any] = {"checkouts": roots, "severities": {}}
    rows = []
    for sev in args.severities.split(","):
        maker = SceneMaker(model, (640, 480), sev, seed=args.seed)
        stats = {k: {"found": 0, "read": 0, "wrong_ok": 0, "ms": [], "corner": []} for k in conns}
        differ, qr_ms = 0, []
        for i in range(args.n):
            scene = maker.make(drawings=1, distractors=1, aruco=True)
            truth = [p for p in scene.placements if p.kind == "drawing"]
            outcome = {}
            for k in ("a", "b") if i % 2 == 0 else ("b", "a"):
                ms, found = locate(k, scene.image, scene.camera)
                s = stats[k]
                s["ms"].append(ms)
                seen = []
                for d, p, right in matched_detections(_as_detections(found), truth):
                    s["found"] += p is not None
                    s["read"] += bool(d.result.ok and right)
                    s["wrong_ok"] += bool(d.result.ok and not right)
                    if d.result.ok and right:
                        s["corner"].append(_corner_error(d.corners, p.corners))
                    seen.append((p is not None, bool(d.result.ok), bytes(np.asarray(d.result.payload, np.uint8))))
                outcome[k] = sorted(seen)
            differ += outcome["a"] != outcome["b"]
            t0 = time.perf_counter()
            qr.detectAndDecode(qr_frames[i % len(qr_frames)])
            qr_ms.append(1000 * (time.perf_counter() - t0))
        qr_med = float(np.median(qr_ms))
        a_med = float(np.median(stats["a"]["ms"]))
        sev_report: dict[str, Any] = {"scenes": args.n, "qr_ms_median": round(qr_med, 2), "scenes_differing": differ}
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
                "x_a": round(med / a_med, 3),
            }
            rows.append(
                (
                    sev,
                    k,
                    f"{s['found']}/{args.n}",
                    f"{s['read']}/{args.n}",
                    s["wrong_ok"],
                    sev_report[k]["corner_px_median"],
                    round(med, 2),
                    round(float(np.mean(s["ms"])), 1),
                    round(qr_med, 2),
                    f"{med / qr_med:.2f}x",
                    f"{med / a_med:.2f}x",
                    differ if k == "b" else "",
                )
            )
        report["severities"][sev] = sev_report
        print(f"{sev}: done", flush=True)
    maker = SceneMaker(model, (640, 480), "medium", seed=args.seed + 1000)
    negatives = {k: {"images": args.negatives, "detections": 0, "wrong_ok": 0} for k in conns}
    for i in range(args.negatives):
        scene = maker.make(drawings=0, distractors=1 + i % 3, aruco=i % 2 == 0)
        for k in conns:
            _, found = locate(k, scene.image, scene.camera)
            negatives[k]["detections"] += len(found)
            negatives[k]["wrong_ok"] += sum(f["ok"] for f in found)
    for conn in conns.values():
        conn.send(None)
    for proc in procs:
        proc.join()
    report["negatives"] = negatives
    report["environment"] = environment()
    headers = ["severity", "checkout", "found", "read", "wrong ok", "corner px", "ms median", "ms mean", "QR ms"]
    print(table(headers + ["x QR", "x a", "scenes differing"], rows))
    for k in conns:
        print(
            f"{k} ({roots[k]}): {negatives[k]['detections']} detections on {args.negatives} scenes without the drawing"
        )
    print(f"wrote {write_json(args.out, report)}")


if __name__ == "__main__":
    main()
