"""The proposal verifier: the same scenes located with and without it, reads and frame times.

For each bundle holding a verifier (``deepmorph train-verifier``), ``--n`` medium and ``--n``
hard scenes at ``--frame`` pixels (one print, one other drawing, an ArUco marker: the scenes of
``bench/export_speed.py``) and ``--negatives`` scenes without the print (two other drawings and a
marker) are each located twice by the same model, once with its verifier and once without
(``Locator(use_verifier=False)``), alternating which goes first. OpenCV's QR ``detectAndDecode``
runs once per scene on a same-size frame holding a QR code, so every median is taken over the
same minutes.

Per bundle and severity: prints read without and with, wrong payloads, scenes whose reports
differ (found, payload or ok), the median frame with its ratio to QR's, and how many proposals
the verifier was asked about and turned away. The seed is not one the verifier was trained or
checked on (its scenes are seeded by ``(seed, part, severity, index)``).

    .venv/bin/python bench/verifier.py panel/coffee.dmm panel/codepen.dmm --n 150 --negatives 50
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, frame_size, set_threads, table, write_json  # noqa: E402


class Counted:
    """Wraps a verifier's ``turns_away``: how often it was asked and said yes."""

    def __init__(self, verifier: Any) -> None:
        self.asked, self.turned = 0, 0
        self.real = verifier.turns_away
        verifier.turns_away = self

    def __call__(self, gray: np.ndarray, corners: np.ndarray) -> bool:
        self.asked += 1
        away = self.real(gray, corners)
        self.turned += away
        return away


def reports(found: list[Any]) -> tuple:
    """What a frame reported, to compare: each drawing's payload, whether it read, its place."""
    places = [() if d.corners is None else tuple(np.round(d.corners).ravel()) for d in found]
    return tuple(sorted((d.result.payload.tobytes(), bool(d.result.ok), at) for d, at in zip(found, places)))


def _shown(report: tuple) -> list[dict[str, Any]]:
    return [{"payload": payload.hex(), "ok": ok, "corners": [float(v) for v in at]} for payload, ok, at in report]


def run_bundle(path: Path, args: argparse.Namespace) -> dict[str, Any]:
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.baselines import QrClock
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.scenes import SceneMaker

    model = DeepMorphModel.load(path)
    if model.meta.verifier is None:
        raise SystemExit(f"{path}: holds no verifier (deepmorph train-verifier)")
    chains = {"without": Locator(model, use_verifier=False), "with": Locator(model)}
    counter = Counted(chains["with"].aligner.verifier)
    qr = QrClock(model, args.frame, frames=20)
    qr.warm()
    rows: dict[str, Any] = {"threshold": model.meta.verifier.threshold}
    plans = [(sev, args.n, 1) for sev in ("medium", "hard")] + [("none", args.negatives, 0)]
    for sev, n, drawings in plans:
        maker = SceneMaker(model, args.frame, "medium" if sev == "none" else sev, seed=args.seed + (sev == "none"))
        scenes = [maker.make(drawings=drawings, distractors=1 if drawings else 2, aruco=True) for _ in range(n)]
        for scene in scenes[:2]:  # warm-up, not timed
            for chain in chains.values():
                chain.locate(scene.image, scene.camera)
        counter.asked = counter.turned = 0
        ms: dict[str, list[float]] = {k: [] for k in chains}
        read: dict[str, int] = dict.fromkeys(chains, 0)
        wrong: dict[str, int] = dict.fromkeys(chains, 0)
        seen: dict[str, list[tuple]] = {k: [] for k in chains}
        for i, scene in enumerate(scenes):
            truth = {p.payload.tobytes() for p in scene.placements if p.kind == "drawing"}
            for name in list(chains) if i % 2 == 0 else list(chains)[::-1]:
                t0 = time.perf_counter()
                found = chains[name].locate(scene.image, scene.camera)
                ms[name].append(1000 * (time.perf_counter() - t0))
                ok = {d.result.payload.tobytes() for d in found if d.result.ok}
                read[name] += len(ok & truth)
                wrong[name] += len(ok - truth)
                seen[name].append(reports(found))
            qr.tick()
        qr_ms = qr.median_ms() or float("nan")
        rows[sev] = {
            "scenes": n,
            "read without": read["without"],
            "read with": read["with"],
            "wrong without": wrong["without"],
            "wrong with": wrong["with"],
            "scenes differing": sum(a != b for a, b in zip(seen["without"], seen["with"], strict=True)),
            "differing": [
                {"scene": i, "without": _shown(a), "with": _shown(b)}
                for i, (a, b) in enumerate(zip(seen["without"], seen["with"], strict=True))
                if a != b
            ],
            "ms median without": round(float(np.median(ms["without"])), 2),
            "ms median with": round(float(np.median(ms["with"])), 2),
            "ms mean without": round(float(np.mean(ms["without"])), 2),
            "ms mean with": round(float(np.mean(ms["with"])), 2),
            "qr ms": qr_ms,
            "x qr without": round(float(np.median(ms["without"])) / qr_ms, 2),
            "x qr with": round(float(np.median(ms["with"])) / qr_ms, 2),
            "asked": counter.asked,
            "turned away": counter.turned,
        }
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", type=Path, nargs="+", help="bundles holding a verifier")
    ap.add_argument("--n", type=int, default=150, help="scenes per severity")
    ap.add_argument("--negatives", type=int, default=50, help="scenes without the print")
    ap.add_argument("--frame", type=frame_size, default=(1280, 720))
    ap.add_argument("--seed", type=int, default=41)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "verifier.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)
    import cv2

    cv2.setNumThreads(args.threads)
    results = {path.stem: run_bundle(path, args) for path in args.bundles}
    headers = ["bundle", "scenes", "read without / with", "wrong", "differing", "ms median without → with",
               "× QR without → with", "turned away / asked"]  # fmt: skip
    lines = []
    for name, res in results.items():
        for sev in ("medium", "hard", "none"):
            r = res[sev]
            lines.append([
                name, f"{sev} {r['scenes']}", f"{r['read without']} / {r['read with']}",
                f"{r['wrong without']} / {r['wrong with']}", r["scenes differing"],
                f"{r['ms median without']:.1f} → {r['ms median with']:.1f}",
                f"{r['x qr without']:.2f} → {r['x qr with']:.2f}", f"{r['turned away']} / {r['asked']}",
            ])  # fmt: skip
    print(table(headers, lines))
    write_json(args.out, {"environment": {**environment(), "threads": threads}, "results": results})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
