"""Scoring the photo chain on a folder of labelled photos (``deepmorph bench-photos``).

The photos are a user's own pictures of their prints (or the synthetic scenes of
``deepmorph synth``), labelled in ``labels.csv`` (:mod:`deepmorph_detect.labels`). Each
labelled code ends as one of:

* ``read``: a verified payload equal to its label;
* ``wrong``: a verified payload that is not its label (a wrong label, or a false accept);
* ``not verified``: the chain found a drawing there but could not vouch for a payload;
* ``missed``: nothing was found for it.

A verified payload that no label of its photo accounts for (in a photo labelled without a
code, say) is a *false read*; wrong payloads are the ``wrong`` codes plus the false reads.
Where corners are labelled, each read is matched to the label whose frame it lies on and its
corner error is measured. Each code is also described by what decides whether a photo reads:
its printed width in pixels, its tilt to the camera and the sharpness of the photo over it,
from the labelled corners, else from the corners the chain found.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.image_io import read_image_bgr
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import format_payload
from deepmorph_detect.camera import DEFAULT_HFOV_DEG, Camera, solve_pose, viewbox_corners, viewbox_to_frame
from deepmorph_detect.camera import project as project_points
from deepmorph_detect.labels import Label, read_labels
from deepmorph_detect.locate import Locator
from deepmorph_detect.media import IMAGE_SUFFIXES
from deepmorph_detect.metrics import corner_error
from deepmorph_detect.results import Located, across_px

STATUSES = ("read", "wrong", "not verified", "missed")
MIN_BLUR_PIXELS = 16  # a frame covering fewer pixels than this has no sharpness to speak of


@dataclass
class CodeScore:
    """One labelled code in one photo, scored."""

    file: str
    line: int
    expected: str
    status: str = "missed"
    payload: str | None = None  # what the chain read or guessed there (hex), when it found it
    corner_error_px: float | None = None
    corners_from: str | None = None  # "label", "detection" or None (missed, unlabelled)
    width_px: float | None = None
    tilt_deg: float | None = None
    sharpness: float | None = None

    def to_json(self) -> dict[str, Any]:
        return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


@dataclass
class PhotoScore:
    """One photo: its labelled codes, the verified payloads no label accounts for, the time taken."""

    file: str
    time_ms: float
    detections: int
    codes: list[CodeScore] = field(default_factory=list)
    false_reads: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "file": self.file,
            "time_ms": round(self.time_ms, 2),
            "detections": self.detections,
            "codes": [p.to_json() for p in self.codes],
            "false_reads": self.false_reads,
        }


def photo_files(folder: Path) -> list[str]:
    """The image files directly in ``folder``, by name."""
    if not folder.is_dir():
        raise DeepMorphError(f"{folder}: not a folder of photos")
    return sorted(p.name for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def check_labels(folder: Path, labels_path: Path, labels: list[Label]) -> list[str]:
    """The photos to score, in order: every labelled file must exist, and every image of the
    folder must be labelled (a photo left out would silently not count).

    Raises:
        DeepMorphError: naming the first label without its file, or the first unlabelled photo.
    """
    for label in labels:
        if not (folder / label.file).is_file():
            raise DeepMorphError(f"{labels_path}:{label.line}: {folder / label.file}: no such photo")
    labelled = {label.file for label in labels}
    unlabelled = [name for name in photo_files(folder) if name not in labelled]
    if unlabelled:
        raise DeepMorphError(
            f"{folder / unlabelled[0]}: not in {labels_path} ({len(unlabelled)} photo(s) unlabelled); add a row"
            " per code it shows, or one with an empty payload when it shows none"
        )
    return list(dict.fromkeys(label.file for label in labels))


def _near(corners: np.ndarray, truth: np.ndarray) -> bool:
    """Whether a found frame lies on a labelled one (centres within a quarter of its diagonal)."""
    size = float(np.linalg.norm(truth[2] - truth[0]))
    return float(np.linalg.norm(corners.mean(0) - truth.mean(0))) < 0.25 * size


def _take(dets: list[Located], label: Label, want: Any) -> Located | None:
    """The first of ``dets`` satisfying ``want`` that lies on ``label``'s frame (any, when its
    corners are not labelled); removed from ``dets``."""
    for i, det in enumerate(dets):
        if want(det) and (label.corners is None or (det.corners is not None and _near(det.corners, label.corners))):
            return dets.pop(i)
    return None


def print_width(corners: np.ndarray, viewbox: tuple[float, float, float, float]) -> float:
    """The print's width in the photo, seen head-on at its distance, as the photo chain measures
    it for a model's smallest print (:func:`~deepmorph_detect.results.across_px`)."""
    frame = viewbox_corners(viewbox)
    H = cv2.getPerspectiveTransform(frame.astype(np.float32), np.asarray(corners, dtype=np.float32))
    return across_px(H, frame)


def measure_tilt(corners: np.ndarray, viewbox: tuple[float, float, float, float], camera: Camera) -> float:
    """The angle between the print's normal and the camera's axis, from PnP on its frame."""
    frame = project_points(viewbox_to_frame(viewbox), viewbox_corners(viewbox))
    rvec, _ = solve_pose(camera, np.column_stack([frame, np.zeros(4)]), np.asarray(corners, dtype=np.float64))
    rotation, _ = cv2.Rodrigues(rvec.reshape(3, 1))
    return float(np.degrees(np.arccos(np.clip(abs(rotation[2, 2]), 0.0, 1.0))))


def measure_sharpness(gray: np.ndarray, corners: np.ndarray) -> float | None:
    """The variance of the Laplacian of ``gray`` (uint8) inside the frame: higher is sharper;
    ``None`` when the frame covers almost none of the photo."""
    mask = np.zeros(gray.shape, np.uint8)
    cv2.fillPoly(mask, [np.round(np.asarray(corners)).astype(np.int32).reshape(-1, 1, 2)], 1)
    inside = mask.astype(bool)
    if int(inside.sum()) < MIN_BLUR_PIXELS:
        return None
    return float(cv2.Laplacian(gray, cv2.CV_64F)[inside].var())


def score_photo(
    file: str, labels: list[Label], dets: list[Located], time_ms: float, gray: np.ndarray,
    viewbox: tuple[float, float, float, float], camera: Camera,
) -> PhotoScore:  # fmt: skip
    """Match one photo's detections to its labels (see the module) and describe each code."""
    prints = [label for label in labels if label.payload is not None]
    verified = [d for d in dets if d.result.ok]
    unverified = [d for d in dets if not d.result.ok]
    found: dict[int, tuple[str, Located]] = {}
    for i, label in enumerate(prints):  # right payloads first, on their own frames
        det = _take(verified, label, lambda d, want=label.payload: np.array_equal(d.result.payload, want))
        if det is not None:
            found[i] = ("read", det)
    for status, pool in (("wrong", verified), ("not verified", unverified)):
        for i, label in enumerate(prints):
            if i not in found:
                det = _take(pool, label, lambda d: True)
                if det is not None:
                    found[i] = (status, det)
    labelled = {format_payload(p.payload)["hex"] for p in prints}  # a second read of a labelled code is no false read
    score = PhotoScore(file, time_ms, len(dets))
    score.false_reads = [h for h in (format_payload(d.result.payload)["hex"] for d in verified) if h not in labelled]
    for i, label in enumerate(prints):
        status, det = found.get(i, ("missed", None))
        ps = CodeScore(file, label.line, format_payload(label.payload)["hex"], status)
        if det is not None:
            ps.payload = format_payload(det.result.payload)["hex"]
            if label.corners is not None and det.corners is not None:
                ps.corner_error_px = corner_error(det.corners, label.corners)
        corners = label.corners if label.corners is not None else (None if det is None else det.corners)
        if corners is not None:
            ps.corners_from = "label" if label.corners is not None else "detection"
            ps.width_px = print_width(corners, viewbox)
            ps.tilt_deg = measure_tilt(corners, viewbox, camera)
            ps.sharpness = measure_sharpness(gray, corners)
        score.codes.append(ps)
    return score


def _stats(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    v = np.asarray(values, dtype=np.float64)
    return {"n": len(values), "mean": round(float(v.mean()), 3), "median": round(float(np.median(v)), 3),
            "p90": round(float(np.percentile(v, 90)), 3), "max": round(float(v.max()), 3)}  # fmt: skip


def summarise(photos: list[PhotoScore], skipped: list[dict[str, str]]) -> dict[str, Any]:
    """The counts and rates of scored photos (the report's top level). The corner error is
    taken over the codes read (the others' corners may come from the unmorphed drawing)."""
    codes = [p for photo in photos for p in photo.codes]
    counts = {s: sum(p.status == s for p in codes) for s in STATUSES}
    false_reads = sum(len(photo.false_reads) for photo in photos)
    return {
        "photos": len(photos),
        "skipped": skipped,
        "codes": len(codes),
        "photos_without_code": sum(not photo.codes for photo in photos),
        "read": counts["read"],
        "wrong": counts["wrong"],
        "not_verified": counts["not verified"],
        "missed": counts["missed"],
        "false_reads": false_reads,
        "wrong_payloads": counts["wrong"] + false_reads,
        "read_rate": round(counts["read"] / len(codes), 4) if codes else None,
        "corner_error_px": _stats(
            [p.corner_error_px for p in codes if p.status == "read" and p.corner_error_px is not None]
        ),
        "time_ms": _stats([photo.time_ms for photo in photos]),
    }


def bench_photos(
    model: DeepMorphModel,
    folder: Path,
    labels_path: Path,
    camera: Camera | None = None,
    detector: str | None = None,
    soft: bool = True,
    on_photo: Any = None,
    on_skip: Any = None,
) -> dict[str, Any]:
    """Score the chain on a folder of labelled photos; the report as a dict (see the module).

    Args:
        camera: the intrinsics of the photos (scaled to each), or ``None`` for the assumed one.
        on_photo: called with ``(photos done, photos in all)``, skipped ones included.
        on_skip: called with ``(file, error text)`` for a photo that cannot be read (it is
            listed under ``skipped`` and does not count).

    Raises:
        DeepMorphError: bad labels, a labelled file missing or an unlabelled photo (before any
            work; see :func:`check_labels`).
    """
    labels = read_labels(labels_path, model.codec.spec.payload_bits)
    files = check_labels(folder, labels_path, labels)
    by_file: dict[str, list[Label]] = {}
    for label in labels:
        by_file.setdefault(label.file, []).append(label)
    locator = Locator(model, detector=detector)
    photos: list[PhotoScore] = []
    skipped: list[dict[str, str]] = []
    warm = False
    for n, name in enumerate(files, 1):
        if on_photo:
            on_photo(n - 1, len(files))
        try:
            image = read_image_bgr(folder / name)
            cam = camera.for_image(image.shape[1], image.shape[0]) if camera is not None else None
        except DeepMorphError as exc:
            skipped.append({"file": name, "error": str(exc)})
            if on_skip:
                on_skip(name, str(exc))
            continue
        if not warm:  # first calls allocate and load: keep them out of the timings
            locator.locate(image, camera=cam, soft=soft)
            warm = True
        t0 = time.perf_counter()
        dets = locator.locate(image, camera=cam, soft=soft)
        elapsed = (time.perf_counter() - t0) * 1000
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        pose_camera = cam or Camera.default(image.shape[1], image.shape[0])
        photos.append(score_photo(name, by_file[name], dets, elapsed, gray, locator.viewbox, pose_camera))
    if on_photo:
        on_photo(len(files), len(files))
    return {
        "format": "deepmorph-bench-photos/1",
        "model": str(model.meta.drawing_name),
        "folder": str(folder),
        "labels": str(labels_path),
        "camera": "given" if camera is not None else f"assumed ({DEFAULT_HFOV_DEG:g} deg horizontal field of view)",
        **summarise(photos, skipped),
        "results": [photo.to_json() for photo in photos],
    }


__all__ = ["STATUSES", "PhotoScore", "CodeScore", "bench_photos", "check_labels", "measure_sharpness", "measure_tilt",
           "photo_files", "print_width", "score_photo", "summarise"]  # fmt: skip
