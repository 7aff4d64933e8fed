"""Frame time of a freshly trained model beside the bundled ghost's, QR's and ArUco's, and where it goes.

For each bundle (the bundled ghost and ``--fresh``), ``--n`` scenes at ``--severity`` (``--frame``
pixels, 640x480 by default, one print, one other drawing, an ArUco marker of the same printed
size) are made from the same seed. A model trained with ``--pixels 200`` is timed on frames where
most of its prints are that wide: on ``--frame 1280x720`` ``medium``'s prints measured 110-400 px
(a fifth under 200, refused as too small). Each frame is located three times per bundle,
alternating the order: with the networks run by ONNX Runtime from the bundle's graphs (what
``decode`` does), the same stopping at the first print read (``decode --first``: one code, as
QR's ``detectAndDecode`` reads), and with both networks in PyTorch (what a bundle without
usable graphs got before graphs were stored). ArUco's ``detectMarkers`` runs on the same frame, and OpenCV's QR
``detectAndDecode`` once per frame on a same-size frame holding a QR code, so that every median
is taken over the same minutes.

Where the time goes, per frame: the detector, the decoder (calls and milliseconds), the payload
check and how many frames it checked bit by bit (a reading that needed corrections or is less
confident than 0.97: ``deepmorph_detect/check.py``), and the frames that needed the second
looks or the last look by synthesis: the slow paths a weaker first reading takes. The medians
of the frames without them say what each costs.

    .venv/bin/python bench/export_speed.py --fresh /work/onnx-fresh/codesandbox.dmm --n 60
    .venv/bin/python bench/export_speed.py --fresh panel/cpu.dmm --frame 1280x720 --n 60
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, frame_size, set_threads, table, write_json  # noqa: E402

#: how each bundle's frames are located: the networks (ONNX Runtime from the bundle's graphs, or
#: PyTorch) and whether the search stops at the first print read (``locate(first=True)``)
MODES = {"onnx": ("onnx", False), "onnx/first": ("onnx", True), "torch": ("torch", False)}
# what is recorded per frame
FIELDS = ("ms", "read", "detector_ms", "decoder_calls", "decoder_ms", "second", "synthesis", "synthesis_ms",
          "bitwise", "check_ms")  # fmt: skip


class Clock:
    """Wraps a callable; adds up its calls and seconds (reset per frame by the caller)."""

    def __init__(self, fn: Any) -> None:
        self.fn, self.calls, self.seconds = fn, 0, 0.0

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - t0
            self.calls += 1

    def take(self) -> tuple[int, float]:
        out = (self.calls, self.seconds)
        self.calls, self.seconds = 0, 0.0
        return out


class CheckClock(Clock):
    """A :class:`Clock` on the payload check that also counts the checks that went bit by bit
    (``calls`` then counts those; ``seconds`` is every check's time)."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        checked = self.fn(*args, **kwargs)
        self.seconds += time.perf_counter() - t0
        self.calls += checked.bits is not None
        return checked


def instrumented(model: Any, networks: str) -> tuple[Any, dict[str, Clock]]:
    """A locator with its networks in ``networks`` (``onnx`` or ``torch``) and clocks on the
    networks and the slow paths."""
    import torch

    from deepmorph_core.graphs import OnnxNetwork
    from deepmorph_core.networks import fused_for_inference
    from deepmorph_detect.centrenet import TorchDetector, stored_net
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.universal import UNIVERSAL_PATH, load_universal

    locator = Locator(model)
    reader = locator.reader
    if networks == "torch":
        reader.decoder = fused_for_inference(model.decoder)
        if locator.detector is not None:  # the bundle's own network, else the shipped universal one
            own = stored_net(model)
            net = own if own is not None else load_universal(UNIVERSAL_PATH)[0]
            locator.detector.net = TorchDetector(fused_for_inference(net).to(memory_format=torch.channels_last))
    else:
        assert isinstance(reader.decoder, OnnxNetwork), "the decoder does not run from an ONNX graph"
    clocks = {
        "decoder": Clock(reader.decoder),
        "second": Clock(reader.second_looks),
        "synthesis": Clock(reader.read_by_synthesis),
    }
    reader.decoder, reader.second_looks = clocks["decoder"], clocks["second"]
    reader.read_by_synthesis = clocks["synthesis"]
    clocks["check"] = CheckClock(locator.checker.check)
    locator.checker.check = clocks["check"]
    if locator.detector is not None:
        clocks["detector"] = Clock(locator.detector.net)
        locator.detector.net = clocks["detector"]
    return locator, clocks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fresh", type=Path, required=True, help="a freshly trained bundle")
    ap.add_argument("--n", type=int, default=60, help="scenes per bundle")
    ap.add_argument("--severity", default="medium")
    ap.add_argument("--frame", type=frame_size, default=(640, 480), help="the photos' size, WxH (640x480)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "export_speed.json")
    args = ap.parse_args()
    set_threads(args.threads)
    import cv2
    import numpy as np

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.baselines import QrClock, aruco_detector
    from deepmorph_detect.metrics import matched_detections
    from deepmorph_detect.scenes import SceneMaker

    cv2.setNumThreads(args.threads)
    paths = {"ghost": BUNDLED_MODEL, "fresh": args.fresh}
    models = {k: DeepMorphModel.load(p) for k, p in paths.items()}
    scenes: dict[str, list[Any]] = {}
    for k, m in models.items():  # one maker per bundle: its frames follow the same random draws
        maker = SceneMaker(m, args.frame, args.severity, seed=args.seed)
        scenes[k] = [maker.make(drawings=1, distractors=1, aruco=True) for _ in range(args.n)]
    chains = {(k, mode): instrumented(m, MODES[mode][0]) for k, m in models.items() for mode in MODES}
    aruco = aruco_detector()
    qr = QrClock(models["ghost"], args.frame, frames=20)
    qr.warm()
    for (k, _), (locator, clocks) in chains.items():  # first calls allocate: keep them out
        locator.locate(scenes[k][0].image, scenes[k][0].camera)
        for clock in clocks.values():
            clock.take()
    rows: dict[tuple[str, str], dict[str, list[float]]] = {key: {f: [] for f in FIELDS} for key in chains}
    aruco_ms: dict[str, list[float]] = {k: [] for k in models}
    for i in range(args.n):
        order = list(chains) if i % 2 == 0 else list(chains)[::-1]
        for key in order:
            k, mode = key
            locator, clocks = chains[key]
            scene = scenes[k][i]
            t0 = time.perf_counter()
            found = locator.locate(scene.image, scene.camera, first=MODES[mode][1])
            ms = 1000 * (time.perf_counter() - t0)
            truth = [p for p in scene.placements if p.kind == "drawing"]
            r = rows[key]
            r["ms"].append(ms)
            r["read"].append(any(d.result.ok and right for d, _, right in matched_detections(found, truth)))
            r["detector_ms"].append(1000 * clocks["detector"].take()[1] if "detector" in clocks else 0.0)
            calls, seconds = clocks["decoder"].take()
            r["decoder_calls"].append(calls)
            r["decoder_ms"].append(1000 * seconds)
            r["second"].append(clocks["second"].take()[0] > 0)
            n_syn, syn_s = clocks["synthesis"].take()
            r["synthesis"].append(n_syn > 0)
            r["synthesis_ms"].append(1000 * syn_s)
            n_bitwise, check_s = clocks["check"].take()
            r["bitwise"].append(n_bitwise > 0)
            r["check_ms"].append(1000 * check_s)
        for k in models:
            gray = cv2.cvtColor(scenes[k][i].image, cv2.COLOR_BGR2GRAY)
            t0 = time.perf_counter()
            aruco.detectMarkers(gray)
            aruco_ms[k].append(1000 * (time.perf_counter() - t0))
        qr.tick()
    qr_ms = qr.median_ms() or float("nan")
    report: dict[str, Any] = {
        "environment": environment(),
        "scenes": args.n,
        "severity": args.severity,
        "frame": list(args.frame),
        "threads": args.threads,
        "bundles": {k: str(p) for k, p in paths.items()},
        "qr_ms_median": qr_ms,
        "chains": {},
    }
    lines = []
    for (k, mode), r in rows.items():
        ms = np.asarray(r["ms"])
        slow = np.asarray(r["second"]) | np.asarray(r["synthesis"])
        entry = {
            "read": int(sum(r["read"])),
            "ms_median": round(float(np.median(ms)), 2),
            "ms_mean": round(float(np.mean(ms)), 2),
            "x_qr_median": round(float(np.median(ms)) / qr_ms, 2),
            "aruco_ms_median": round(float(np.median(aruco_ms[k])), 2),
            "detector_ms_mean": round(float(np.mean(r["detector_ms"])), 2),
            "decoder_calls_mean": round(float(np.mean(r["decoder_calls"])), 2),
            "decoder_ms_mean": round(float(np.mean(r["decoder_ms"])), 2),
            "frames_second_looks": int(sum(r["second"])),
            "frames_synthesis": int(sum(r["synthesis"])),
            "synthesis_ms_mean": round(float(np.mean(r["synthesis_ms"])), 2),
            "ms_median_without_slow_paths": round(float(np.median(ms[~slow])), 2) if (~slow).any() else None,
            "share_of_time_in_slow_frames": round(float(ms[slow].sum() / ms.sum()), 3),
            "frames_checked_bit_by_bit": int(sum(r["bitwise"])),
            "check_ms_mean": round(float(np.mean(r["check_ms"])), 2),
            "ms_median_without_bitwise_check": round(float(np.median(ms[~np.asarray(r["bitwise"])])), 2)
            if not all(r["bitwise"])
            else None,
        }
        report["chains"][f"{k}/{mode}"] = entry
        lines.append([k, mode, f"{entry['read']}/{args.n}", entry["ms_median"], entry["ms_mean"],
                      f"{entry['x_qr_median']:.2f}", entry["aruco_ms_median"], entry["detector_ms_mean"],
                      entry["decoder_calls_mean"], entry["decoder_ms_mean"],
                      f"{entry['frames_checked_bit_by_bit']}/{args.n}", entry["check_ms_mean"],
                      f"{entry['frames_second_looks']}/{args.n}", f"{entry['frames_synthesis']}/{args.n}",
                      entry["ms_median_without_slow_paths"], entry["ms_median_without_bitwise_check"]])  # fmt: skip
    print(table(["bundle", "chain", "read", "ms median", "ms mean", "x QR", "ArUco ms", "detector ms",
                 "decoder calls", "decoder ms", "checked bit by bit", "check ms", "second looks", "last look",
                 "ms median w/o 2nd/last looks", "ms median w/o bit check"], lines))  # fmt: skip
    print(f"QR detectAndDecode median {qr_ms:.2f} ms; {args.threads} thread(s), {args.severity}, {args.n} scenes "
          f"of {args.frame[0]}x{args.frame[1]}")  # fmt: skip
    print(f"wrote {write_json(args.out, report)}")


if __name__ == "__main__":
    main()
