"""Scoring the whole chain on synthetic scenes, side by side with ArUco and QR codes.

:func:`bench_scenes` reads a scene folder (:mod:`deepmorph_detect.scene_folders`) and
measures, on the same images:

* detection recall and precision, whole-payload success, and wrong payloads reported as ok;
* pose: rotation and translation error and corner reprojection error, for our drawings and for
  the ArUco markers printed at the same size in the same scenes (found by ``cv2.aruco``);
* time per frame on the current thread count: our locate+decode, ArUco detection on the same
  frames, and ``cv2.QRCodeDetector().detectAndDecode`` on same-size frames holding a QR code,
  one QR call after each scene (:class:`~deepmorph_detect.baselines.QrClock`), so that both
  medians are taken over the same minutes: a machine's speed can drift by a fifth within a run.

:func:`tracking_rates` compares searching every frame of a filmed print with following it.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from deepmorph_core.codec import DecodeResult
from deepmorph_core.image_io import read_image_bgr
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.baselines import QrClock, aruco_detector
from deepmorph_detect.camera import Camera, rotation_error_deg, solve_pose, translation_error
from deepmorph_detect.locate import Locator
from deepmorph_detect.metrics import SceneTally, corner_error, match_placement
from deepmorph_detect.results import Located
from deepmorph_detect.scene_folders import read_scenes
from deepmorph_detect.scenes import SceneMaker


def bench_scenes(model: DeepMorphModel, folder: Path, on_scene: Any = None, first: bool = False) -> dict[str, Any]:
    """Run the chain and the baselines over a scene folder; the report as a dict. ``first``:
    each scene located as ``decode --first`` does (the first print read, alone: one code per
    frame, as QR's ``detectAndDecode`` reads), so a scene of two prints finds one."""
    index, scenes = read_scenes(folder)
    locator = Locator(model)
    aruco = aruco_detector()
    square = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], dtype=np.float64)
    tally = SceneTally()
    stats: dict[str, Any] = {"detections": 0, "negative_images": 0, "aruco_markers": 0, "aruco_found": 0}
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
        stats["negative_images"] += not drawings
        t0 = time.perf_counter()
        dets: list[Located] = locator.locate(image, camera=cam, first=first)
        t_ours.append(time.perf_counter() - t0)
        stats["detections"] += len(dets)
        for det, p, _ in tally.add(dets, drawings):
            if p is None:
                continue
            rot.append(rotation_error_deg(det.rvec, p.rvec))
            trans.append(translation_error(det.tvec, p.tvec))
            corner.append(corner_error(det.corners, p.corners))
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
            a_corner.append(corner_error(cc, p.corners))
        qr.tick()
        if on_scene:
            on_scene(i + 1)
    qr_ms = qr.median_ms()

    def med(v: list[float]) -> float | None:
        return round(float(np.median(v)), 4) if v else None

    n_dr = max(tally.prints, 1)
    report = {
        "scenes": len(scenes),
        "severity": index.get("severity"),
        "first": first,
        "drawings": tally.prints,
        "found": tally.found,
        "decoded": tally.read,
        "false_detections": tally.false,
        "wrong_ok": tally.wrong,
        **stats,
        "recall": round(tally.found / n_dr, 4),
        "precision": round(tally.found / max(stats["detections"], 1), 4),
        "payload_success": round(tally.read / n_dr, 4),
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
            p = match_placement(det.corners, drawings)
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
    drawings followed (:class:`~deepmorph_detect.track.SequenceLocator`), on the same frames.

    Each sequence films one print for ``frames`` frames; between frames the camera moves the
    image corners by about ``shake_px`` pixels (:meth:`SceneMaker.make`). Per mode: median ms
    per frame, frames whose payload was read right, wrong payloads reported ok, and the median
    corner error against the moved truth; plus QR's detect-and-decode on same-size frames.
    """
    from deepmorph_detect.track import SequenceLocator

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
                    errors.append(corner_error(right[0].corners, scene.corners_in_frame(truth, k)))
        out[mode] = {
            "ms_median": round(1000 * float(np.median(times)), 2),
            "ms_mean": round(1000 * float(np.mean(times)), 2),
            "read": read,
            "wrong_ok": wrong,
            "corner_px_median": round(float(np.median(errors)), 3) if errors else None,
        }
    out["qr_detect_and_decode_median"] = qr.median_ms()
    return out


__all__ = ["bench_scenes", "morph_check_rates", "tracking_rates"]
