"""Scoring the whole chain on synthetic scenes, side by side with ArUco and QR codes.

:func:`write_scenes` stores scenes (PNG + JSON truth) as ``deepmorph synth`` does;
:func:`bench_scenes` reads such a folder back and measures, on the same images:

* detection recall and precision, whole-payload success, and wrong payloads reported as ok;
* pose: rotation and translation error and corner reprojection error, for our drawings and for
  the ArUco markers printed at the same size in the same scenes (found by ``cv2.aruco``);
* time per frame on the current thread count: our locate+decode, ArUco detection on the same
  frames, and ``cv2.QRCodeDetector().detectAndDecode`` on same-size frames holding a QR code,
  one QR call after each scene (:class:`QrClock`), so that both medians are taken over the
  same minutes: the machine's speed drifts by a fifth within a run.

:func:`tracking_rates` compares searching every frame of a filmed print with following it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from deepmorph_core.codec import DecodeResult
from deepmorph_core.codemodel import DeepMorphModel
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write, output_folder, refuse_non_folder
from deepmorph_core.imaging import read_image_bgr
from deepmorph_detect.camera import Camera, rotation_error_deg, solve_pose, translation_error
from deepmorph_detect.locate import Located, Locator
from deepmorph_detect.scenes import ARUCO_DICT, Placement, SceneMaker

QR_TEXT = "https://deepmorph.example/0xA1B2C3"  # what the QR frames of the speed baseline hold


def check_scene_folder(out: Path) -> None:
    """Refuse, before any work, a place :func:`write_scenes` cannot fill without loss: a file,
    or a folder that already holds scenes (a second set would replace some of the first and
    leave the rest stale)."""
    refuse_non_folder(out)
    if out.is_dir() and ((out / "index.json").exists() or next(out.glob("scene_*"), None) is not None):
        raise DeepMorphError(f"{out}: already holds scenes; write to a new folder, or remove them first")


def write_scenes(
    model: DeepMorphModel,
    out: Path,
    n: int,
    severity: str = "medium",
    seed: int = 0,
    size: tuple[int, int] = (640, 480),
    drawings: int = 1,
    distractors: int = 0,
    aruco: bool = True,
    empty_fraction: float = 0.0,
    on_scene: Any = None,
) -> Path:
    """Write ``n`` labelled scenes into ``out`` (``scene_00000.png`` + ``.json``, ``index.json``).

    ``empty_fraction`` of the scenes hold no drawing of the model (only distractors and
    markers): the negatives for false-accept counts.

    Raises:
        DeepMorphError: ``out`` is a file, or a folder that already holds scenes (checked before
            any work: a second set would replace some of the first and leave the rest stale).
    """
    check_scene_folder(Path(out))
    out = output_folder(out)
    maker = SceneMaker(model, size, severity, seed=seed)
    rng = np.random.default_rng([seed, 7])
    names = []
    for i in range(n):
        empty = rng.random() < empty_fraction
        scene = maker.make(
            drawings=0 if empty else drawings,
            distractors=max(distractors, 1) if empty else distractors,
            aruco=aruco,
        )
        name = f"scene_{i:05d}"
        ok, buf = cv2.imencode(".png", scene.image)
        if not ok:  # pragma: no cover
            raise DeepMorphError("PNG encoding failed")
        atomic_write(out / f"{name}.png", buf.tobytes())
        atomic_write(out / f"{name}.json", json.dumps(scene.truth_json(), indent=1).encode())
        names.append(name)
        if on_scene:
            on_scene(i + 1)
    index = {"format": "deepmorph-scenes/1", "model": model.meta.drawing_name, "severity": severity,
             "seed": seed, "size": list(size), "scenes": names}  # fmt: skip
    atomic_write(out / "index.json", json.dumps(index, indent=1).encode())
    return out


def read_scenes(folder: Path) -> tuple[dict[str, Any], list[tuple[Path, dict[str, Any]]]]:
    """The index and ``(image path, truth)`` pairs of a scene folder; clear errors otherwise."""
    index_path = folder / "index.json"
    if not index_path.is_file():
        raise DeepMorphError(f"{folder}: not a scene folder (no index.json; make one with `deepmorph synth`)")
    try:
        index = json.loads(index_path.read_text())
        names = list(index["scenes"])
    except (ValueError, KeyError, TypeError):
        raise DeepMorphError(f"{index_path}: not a scene index written by `deepmorph synth`") from None
    scenes = []
    for name in names:
        truth_path = folder / f"{name}.json"
        try:
            truth = json.loads(truth_path.read_text())
            truth["placements"] = [Placement.from_json(p) for p in truth["placements"]]
        except (OSError, ValueError, KeyError, TypeError):
            raise DeepMorphError(f"{truth_path}: missing or malformed scene truth") from None
        scenes.append((folder / f"{name}.png", truth))
    return index, scenes


def _corner_error(found: np.ndarray, truth: np.ndarray) -> float:
    return float(np.linalg.norm(np.asarray(found) - truth, axis=1).mean())


def _match(det_corners: np.ndarray, truths: list[Placement]) -> Placement | None:
    centre = det_corners.mean(0)
    for p in truths:
        size = float(np.linalg.norm(p.corners[2] - p.corners[0]))
        if np.linalg.norm(centre - p.corners.mean(0)) < 0.25 * size:
            return p
    return None


def matched_detections(
    dets: list[Located], drawings: list[Placement]
) -> Iterator[tuple[Located, Placement | None, bool]]:
    """Each detection with the drawing it found (``None``: a false detection, or a second one of
    a drawing already found) and whether its payload is that drawing's."""
    matched: set[int] = set()
    for det in dets:
        p = _match(det.corners, drawings)
        if p is None or id(p) in matched:
            yield det, None, False
            continue
        matched.add(id(p))
        yield det, p, p.payload is not None and np.array_equal(det.result.payload, p.payload)


def aruco_detector() -> cv2.aruco.ArucoDetector:
    """OpenCV's ArUco detector for DICT_6X6_250 with sub-pixel corner refinement."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(ARUCO_DICT), params)


def bench_scenes(model: DeepMorphModel, folder: Path, on_scene: Any = None) -> dict[str, Any]:
    """Run the chain and the baselines over a scene folder; the report as a dict."""
    index, scenes = read_scenes(folder)
    locator = Locator(model)
    aruco = aruco_detector()
    square = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], dtype=np.float64)
    stats: dict[str, Any] = {"drawings": 0, "found": 0, "decoded": 0, "false_detections": 0, "wrong_ok": 0,
                             "detections": 0, "negative_images": 0, "aruco_markers": 0, "aruco_found": 0}  # fmt: skip
    rot, trans, corner, a_rot, a_trans, a_corner = [], [], [], [], [], []
    t_ours, t_aruco = [], []
    qr = QrClock(model, tuple(index.get("size", (640, 480))), frames=min(30, max(5, len(scenes))))
    if scenes:  # first calls allocate and load: keep them out of the timings, ours and QR's
        locator.locate(read_image_bgr(scenes[0][0]))
        qr.warm()
    for i, (path, truth) in enumerate(scenes):
        image = read_image_bgr(path)
        c = truth["camera"]
        cam = Camera(c["fx"], c["fy"], c["cx"], c["cy"])
        drawings = [p for p in truth["placements"] if p.kind == "drawing"]
        markers = [p for p in truth["placements"] if p.kind == "aruco"]
        stats["drawings"] += len(drawings)
        stats["negative_images"] += not drawings
        t0 = time.perf_counter()
        dets: list[Located] = locator.locate(image, camera=cam)
        t_ours.append(time.perf_counter() - t0)
        stats["detections"] += len(dets)
        for det, p, right in matched_detections(dets, drawings):
            if p is None:
                stats["false_detections"] += 1
                stats["wrong_ok"] += bool(det.result.ok)
                continue
            stats["found"] += 1
            stats["decoded"] += bool(det.result.ok and right)
            stats["wrong_ok"] += bool(det.result.ok and not right)
            rot.append(rotation_error_deg(det.rvec, p.rvec))
            trans.append(translation_error(det.tvec, p.tvec))
            corner.append(_corner_error(det.corners, p.corners))
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        t0 = time.perf_counter()
        m_corners, ids, _ = aruco.detectMarkers(gray)
        t_aruco.append(time.perf_counter() - t0)
        stats["aruco_markers"] += len(markers)
        found_ids = {} if ids is None else {int(k): cc.reshape(4, 2) for k, cc in zip(ids.ravel(), m_corners)}
        for p in markers:
            if int(p.label) not in found_ids:
                continue
            cc = found_ids[int(p.label)]
            stats["aruco_found"] += 1
            rvec, tvec = solve_pose(cam, square, cc)
            a_rot.append(rotation_error_deg(rvec, p.rvec))
            a_trans.append(translation_error(tvec, p.tvec))
            a_corner.append(_corner_error(cc, p.corners))
        qr.tick()
        if on_scene:
            on_scene(i + 1)
    qr_ms = qr.median_ms()

    def med(v: list[float]) -> float | None:
        return round(float(np.median(v)), 4) if v else None

    n_dr = max(stats["drawings"], 1)
    report = {
        "scenes": len(scenes),
        "severity": index.get("severity"),
        **stats,
        "recall": round(stats["found"] / n_dr, 4),
        "precision": round(stats["found"] / max(stats["detections"], 1), 4),
        "payload_success": round(stats["decoded"] / n_dr, 4),
        "pose": {
            "deepmorph": {
                "rotation_deg_median": med(rot),
                "translation_rel_median": med(trans),
                "corner_px_median": med(corner),
                "n": len(rot),
            },
            "aruco": {
                "rotation_deg_median": med(a_rot),
                "translation_rel_median": med(a_trans),
                "corner_px_median": med(a_corner),
                "n": len(a_rot),
            },
        },  # fmt: skip
        "speed_ms": {
            "deepmorph_locate_decode_median": round(1000 * float(np.median(t_ours)), 2),
            # the last looks (docs/detection.md) make a few frames much slower than the median
            "deepmorph_locate_decode_mean": round(1000 * float(np.mean(t_ours)), 2),
            "aruco_detect_median": round(1000 * float(np.median(t_aruco)), 2),
            "qr_detect_and_decode_median": qr_ms,
        },
        "aruco_recall": round(stats["aruco_found"] / max(stats["aruco_markers"], 1), 4),
    }
    return report


def morph_check_rates(model: DeepMorphModel, folder: Path, seed: int = 0) -> dict[str, Any]:
    """How the morph check treats right and wrong payloads on the drawings found in a folder.

    For every drawing found, the photo is aligned to three morphs from the same start: the true
    payload's, a random payload's (what a drawing-less photo would decode to), and the morph of
    the true payload with one bit flipped (a near miss, like a CRC collision next to the truth).
    Reports, for each, how many the check rejects and the spread of the correlation gain; and
    how many the whole check of a payload read with corrections rejects (``rejected_with_bits``:
    the morph check, then the per-bit check of ``deepmorph_detect.synthesis``).
    """
    _, scenes = read_scenes(folder)
    locator = Locator(model)
    rng = np.random.default_rng(seed)
    gains: dict[str, list[float]] = {"right": [], "random": [], "one_bit_off": []}
    with_bits: dict[str, int] = {name: 0 for name in gains}
    for path, truth in scenes:
        image = read_image_bgr(path)
        drawings = [p for p in truth["placements"] if p.kind == "drawing"]
        for det in locator.locate(image):
            p = _match(det.corners, drawings)
            if p is None or p.payload is None:
                continue
            near = p.payload.copy()
            near[rng.integers(len(near))] ^= 1
            random = rng.integers(0, 2, len(p.payload)).astype(np.uint8)
            for name, payload in (("right", p.payload), ("random", random), ("one_bit_off", near)):
                # as a payload read with corrections: the morph check (its fit and gain), then the bits
                read = DecodeResult(payload, ok=True, corrected_bits=1, confidence=1.0)
                checked = locator.check_payload(image, det.homography, read, bitwise=True)
                gains[name].append(np.nan if checked.fit is None else checked.fit.gain)
                with_bits[name] += not checked.result.ok
    out: dict[str, Any] = {}
    for name, values in gains.items():
        v = np.asarray(values, dtype=np.float64)
        fitted = v[np.isfinite(v)]
        out[name] = {
            "n": len(v),
            "rejected": int(len(v) - np.sum(fitted > 0)),
            "rejected_with_bits": with_bits[name],
            "gain_p5": round(float(np.percentile(fitted, 5)), 4) if len(fitted) else None,
            "gain_median": round(float(np.median(fitted)), 4) if len(fitted) else None,
        }
    return out


def tracking_rates(
    model: DeepMorphModel, severity: str, sequences: int, frames: int = 10, shake_px: float = 8.0, seed: int = 0
) -> dict[str, Any]:
    """Videos of a hand-held camera, every frame searched (:meth:`Locator.locate`) against
    drawings followed (:class:`~deepmorph_detect.tracking.SequenceLocator`), on the same frames.

    Each sequence films one print for ``frames`` frames; between frames the camera moves the
    image corners by about ``shake_px`` pixels (:meth:`SceneMaker.make`). Per mode: median ms
    per frame, frames whose payload was read right, wrong payloads reported ok, and the median
    corner error against the moved truth; plus QR's detect-and-decode on same-size frames.
    """
    from deepmorph_detect.tracking import SequenceLocator

    maker = SceneMaker(model, (640, 480), severity, seed=seed)
    scenes = [maker.make(drawings=1, frames=frames, shake_px=shake_px) for _ in range(sequences)]
    locator = Locator(model)
    qr = QrClock(model, (640, 480), frames=30)
    qr.warm()
    out: dict[str, Any] = {"severity": severity, "sequences": sequences, "frames": sequences * frames}
    for mode in ("every frame searched", "tracked"):
        times: list[float] = []
        read = wrong = 0
        errors: list[float] = []
        for scene in scenes:
            follow = SequenceLocator(locator)
            truth = scene.placements[0]
            for k, frame in enumerate(scene.frames):
                t0 = time.perf_counter()
                found = locator.locate(frame, scene.camera) if mode != "tracked" else follow(frame, scene.camera)
                times.append(time.perf_counter() - t0)
                qr.tick()
                right = [d for d in found if d.result.ok and np.array_equal(d.result.payload, truth.payload)]
                wrong += sum(bool(d.result.ok) for d in found) - len(right)
                read += bool(right)
                if right:
                    errors.append(_corner_error(right[0].corners, scene.corners_in_frame(truth, k)))
        out[mode] = {
            "ms_median": round(1000 * float(np.median(times)), 2),
            "ms_mean": round(1000 * float(np.mean(times)), 2),
            "read": read,
            "wrong_ok": wrong,
            "corner_px_median": round(float(np.median(errors)), 3) if errors else None,
        }
    out["qr_detect_and_decode_median"] = qr.median_ms()
    return out


class QrClock:
    """OpenCV's QR ``detectAndDecode`` timed on ``frames`` same-size scenes (medium severity)
    holding one QR code, one call per :meth:`tick`, taking the frames in turn.

    A benchmark ticks it after each of its own frames, so that QR's median is taken over the
    same stretch of the run as the chain's. Timed in a block after the chain's frames instead,
    four runs in one process on the same 100 hard scenes put the chain at 1.08x (the first,
    without a warm-up call), 0.78x, 0.87x and 0.82x QR's time: the machine's speed drifts
    within a minute.
    """

    def __init__(self, model: DeepMorphModel, size: tuple[int, int], frames: int) -> None:
        maker = SceneMaker(model, size, "medium", seed=99)
        self.frames = [maker.make(drawings=0, qr=QR_TEXT).image for _ in range(max(1, frames))]
        self.detector = cv2.QRCodeDetector()
        self.times: list[float] = []

    def warm(self) -> None:
        """One call left out of the timings (the first allocates)."""
        self.detector.detectAndDecode(self.frames[0])

    def tick(self) -> float:
        """Time one call on the next frame; its seconds."""
        frame = self.frames[len(self.times) % len(self.frames)]
        t0 = time.perf_counter()
        self.detector.detectAndDecode(frame)
        self.times.append(time.perf_counter() - t0)
        return self.times[-1]

    def median_ms(self) -> float | None:
        """The median call in milliseconds (``None`` before the first tick)."""
        return round(1000 * float(np.median(self.times)), 2) if self.times else None


def format_report(report: dict[str, Any]) -> str:
    """The report as a plain-text table."""
    p, s = report["pose"], report["speed_ms"]
    rows = [
        ("scenes", report["scenes"], ""),
        ("drawings / found (recall)", f"{report['drawings']} / {report['found']} ({report['recall']:.1%})", ""),
        ("precision", f"{report['precision']:.1%}", ""),
        ("whole-payload success", f"{report['payload_success']:.1%}", ""),
        ("wrong payloads reported ok", report["wrong_ok"], f"over {report['scenes']} images"),
        ("", "DeepMorph", "ArUco 6x6"),
        ("found", report["found"], f"{report['aruco_found']}/{report['aruco_markers']}"),
        ("rotation error, median (deg)", p["deepmorph"]["rotation_deg_median"], p["aruco"]["rotation_deg_median"]),
        (
            "translation error, median (rel)",
            p["deepmorph"]["translation_rel_median"],
            p["aruco"]["translation_rel_median"],
        ),
        ("corner error, median (px)", p["deepmorph"]["corner_px_median"], p["aruco"]["corner_px_median"]),
        ("time per frame, median (ms)", s["deepmorph_locate_decode_median"], s["aruco_detect_median"]),
        ("time per frame, mean (ms)", s["deepmorph_locate_decode_mean"], ""),
        ("QR detectAndDecode (ms)", s["qr_detect_and_decode_median"], ""),
    ]
    width = max(len(r[0]) for r in rows)
    return "\n".join(f"{a:<{width}}  {b!s:>20}  {c!s:>16}" for a, b, c in rows)


__all__ = [
    "QR_TEXT",
    "QrClock",
    "aruco_detector",
    "bench_scenes",
    "format_report",
    "matched_detections",
    "morph_check_rates",
    "read_scenes",
    "tracking_rates",
    "check_scene_folder",
    "write_scenes",
]
