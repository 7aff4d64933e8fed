"""What the photo chain reports for each drawing it finds: :class:`Located`, with its :class:`Pose`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from deepmorph_core.codec import DecodeResult
from deepmorph_core.model import Detection
from deepmorph_detect.camera import Camera, project
from deepmorph_detect.check import MorphFit
from deepmorph_detect.synthesis import BitEvidence


def measure_width(corners: np.ndarray) -> float:
    """The printed width as seen: the mean length of the frame's top and bottom edges."""
    c = np.asarray(corners, dtype=np.float64)
    return float((np.linalg.norm(c[1] - c[0]) + np.linalg.norm(c[2] - c[3])) / 2)


def _centre_stretches(homography: np.ndarray, frame: np.ndarray) -> np.ndarray | None:
    """``(2,)`` how far ``homography`` stretches the print at its frame's centre, largest first
    (the singular values of its Jacobian there); ``None`` on the map's horizon."""
    H = np.asarray(homography, dtype=np.float64)
    cx, cy = np.asarray(frame, dtype=np.float64).mean(axis=0)
    x, y, w = H @ np.array([cx, cy, 1.0])
    with np.errstate(all="ignore"):
        jacobian = (H[:2, :2] * w - np.outer([x, y], H[2, :2])) / w**2
        if not np.isfinite(jacobian).all():
            return None
        return np.linalg.svd(jacobian, compute_uv=False)


def across_px(homography: np.ndarray, frame: np.ndarray) -> float:
    """A print's width in a photo as the project means it everywhere (``train --pixels``,
    ``capacity --print-mm --distance-cm``, the photo simulator): its width seen head-on at its
    distance. ``homography`` maps the print's own units (SVG units for a drawing) to image pixels
    and ``frame`` is its frame's corners (TL, TR, BR, BL) in those units.

    A tilt shortens a print in the photo along one direction only: along the tilt's axis it
    keeps its head-on scale, the largest stretch the homography makes at the drawing's centre.
    The mean of the top and bottom edges (:func:`measure_width`) is shortened by a tilt about
    the vertical axis and not by one about the horizontal axis: a close-up 201 px wide head-on
    and tilted 15° measured 196.5 px. A centre on the map's horizon has no such stretch: there
    the edges as seen are all there is."""
    frame = np.asarray(frame, dtype=np.float64)
    stretches = _centre_stretches(homography, frame)
    if stretches is not None and math.isfinite(across := float(stretches[0] * measure_width(frame))):
        return across
    return measure_width(project(homography, frame))


def along_tilt_px(homography: np.ndarray, frame: np.ndarray) -> float:
    """A print's width in a photo along its tilt: the width it would have if it were shortened
    every way as much as along the direction its tilt foreshortens most (the smallest stretch
    the homography makes at the drawing's centre), so the fewest photo pixels any direction of
    it gets. Head-on it is :func:`across_px`; a heart 135 px across seen nearly edge-on gets
    26 px. A centre on the map's horizon: the shorter of the frame's width and height as seen,
    the height taken at the frame's aspect."""
    frame = np.asarray(frame, dtype=np.float64)
    width = measure_width(frame)
    stretches = _centre_stretches(homography, frame)
    if stretches is not None and math.isfinite(along := float(stretches[1] * width)):
        return along
    seen = project(homography, frame)
    height = measure_width(frame[[1, 2, 3, 0]])  # the mean of the left and right edges
    return min(measure_width(seen), measure_width(seen[[1, 2, 3, 0]]) * width / max(height, 1e-12))


#: The side of :meth:`Pose.cube` in drawing widths.
CUBE_SIDE = 0.3


@dataclass(frozen=True)
class Pose:
    """Where the camera is, in the drawing's own frame (:mod:`deepmorph_detect.camera`): origin
    at the viewBox centre, x right, y down, z into the paper, in units of the printed width.

    Attributes:
        rvec: ``(3,)`` Rodrigues rotation, drawing frame -> camera.
        tvec: ``(3,)`` the drawing's centre in camera coordinates (drawing widths).
        camera: the intrinsics it was solved with (``assumed`` when none were given).
    """

    rvec: np.ndarray
    tvec: np.ndarray
    camera: Camera

    @property
    def rotation(self) -> np.ndarray:
        """``(3, 3)`` rotation matrix of :attr:`rvec`."""
        matrix, _ = cv2.Rodrigues(self.rvec)
        return matrix

    @property
    def distance(self) -> float:
        """How far the drawing's centre is from the camera, in drawing widths."""
        return float(np.linalg.norm(self.tvec))

    def project(self, points: np.ndarray) -> np.ndarray:
        """``(N, 2)`` image pixels of ``(N, 3)`` points in the drawing's frame (drawing widths),
        through the camera's lens distortion."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 1, 3)
        image, _ = cv2.projectPoints(pts, self.rvec, self.tvec, self.camera.matrix, self.camera.dist_coeffs)
        return image.reshape(-1, 2)

    def cube(self, side: float = CUBE_SIDE) -> np.ndarray:
        """``(8, 2)`` image pixels of the corners of a cube ``side`` drawing widths wide standing
        on the drawing's centre: its base on the paper (0-3, clockwise from top-left as the
        drawing is seen), then its top towards the camera (4-7, above 0-3). What AR shows."""
        h = side / 2
        base = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
        top = base + np.array([0.0, 0.0, -side])  # z points into the paper
        return self.project(np.vstack([base, top]))

    def to_json(self) -> dict[str, Any]:
        return {
            "rvec": [round(float(v), 6) for v in self.rvec],
            "tvec": [round(float(v), 6) for v in self.tvec],
            "units": "drawing widths",
            "camera": self.camera.to_json(),
        }


@dataclass
class Located(Detection):
    """A decoded drawing with where it is: corners, homography, keypoints and pose."""

    corners: np.ndarray | None = None
    homography: np.ndarray | None = None  # SVG units -> image pixels
    correlation: float = 0.0
    score: float = 0.0
    rvec: np.ndarray | None = None
    tvec: np.ndarray | None = None
    camera: Camera | None = None
    keypoints: dict[str, list[float]] = field(default_factory=dict)
    source: str = "detector"
    morph: MorphFit | None = None
    bits: BitEvidence | None = None  # the per-bit check, when it ran (Locator.check_payload)
    # "passed", "failed" (ok withdrawn), "contradicted" (the photo does not show its code bits,
    # BitEvidence.agrees: ok withdrawn), "not run" (CRC failed); from deepmorph_detect.track also
    # "tracked" (the payload its track confirmed in an earlier frame, read again from its morph)
    # and "track conflict" (another payload than the track's passed: ok withdrawn); from a drawing that
    # looks the same turned "turn conflict" (two turns passed with two payloads: ok withdrawn)
    morph_check: str = "not run"
    # the narrowest print (photo pixels) its model reads well: the decoder's frame width
    needs_px: float | None = None
    # whether needs_px holds along every direction of the print, its most foreshortened one too
    # (a colour drawing's: Locator.decode_each), not only across it head-on
    needs_every_way: bool = False

    @property
    def width_px(self) -> float | None:
        """The print's width in the photo, seen head-on at its distance (:func:`across_px`; the
        mean of its frame's top and bottom edges where no homography is known)."""
        frame = self._frame()
        if frame is None:
            return None if self.corners is None else measure_width(self.corners)
        return across_px(self.homography, frame)

    @property
    def along_tilt_px(self) -> float | None:
        """The print's width in the photo along its tilt (:func:`along_tilt_px`): what its most
        foreshortened direction gets; the width as seen where no homography is known."""
        frame = self._frame()
        if frame is None:
            return None if self.corners is None else measure_width(self.corners)
        return along_tilt_px(self.homography, frame)

    def _frame(self) -> np.ndarray | None:
        """The print's frame in SVG units, from where the homography put its corners; ``None``
        without corners and homography, or where the map is degenerate."""
        if self.corners is None or self.homography is None:
            return None
        try:
            return project(np.linalg.inv(self.homography), self.corners)
        except np.linalg.LinAlgError:  # a degenerate map: the edges as seen are all there is
            return None

    @property
    def too_narrow(self) -> bool:
        """Whether the print is narrower in the photo than :attr:`needs_px`: its width seen
        head-on, or, where :attr:`needs_every_way`, its width along its tilt."""
        if self.needs_px is None:
            return False
        width = self.along_tilt_px if self.needs_every_way else self.width_px
        return width is not None and width < self.needs_px

    def size_json(self) -> dict[str, Any]:
        """The print's width in the photo and the width its model needs (JSON's ``too_small``);
        where :attr:`needs_every_way`, also its width along its tilt."""
        out: dict[str, Any] = {"width_px": round(float(self.width_px or 0.0), 1), "needs_px": self.needs_px}
        if self.needs_every_way:
            out["along_tilt_px"] = round(float(self.along_tilt_px or 0.0), 1)
        return out

    @property
    def too_small(self) -> bool:
        """Whether the payload is not read and the print is narrower than :attr:`needs_px`: the
        reason to give is its size (move closer, or print larger), not the light."""
        return not self.result.ok and self.too_narrow

    @property
    def pose(self) -> Pose | None:
        """The camera's pose in the drawing's frame, when PnP gave one."""
        if self.rvec is None or self.tvec is None or self.camera is None:
            return None
        return Pose(np.asarray(self.rvec, np.float64), np.asarray(self.tvec, np.float64), self.camera)

    @property
    def confirmed(self) -> bool:
        """Whether the payload is read and confirmed on the print: ``ok``, and its morph check
        passed in this frame or in an earlier one of its track (what
        :func:`~deepmorph_detect.track.track` follows)."""
        return bool(self.result.ok) and self.aligned_to_morph

    @property
    def aligned_to_morph(self) -> bool:
        """Whether the homography (and so the pose) comes from the alignment to the decoded
        payload's morph: its check passed in this frame, or it was followed on its track."""
        return self.morph_check in ("passed", "tracked")

    def to_json(self) -> dict[str, Any]:
        out = super().to_json()
        out["score"] = round(self.score, 4)
        out["alignment"] = round(self.correlation, 4)
        out["found_by"] = self.source
        out["morph_check"] = self.morph_check
        if self.morph is not None:
            out["morph_fit"] = round(self.morph.gain, 4)
        if self.bits is not None:
            out.update(self.bits.to_json())
        out["pose_aligned_to"] = "decoded morph" if self.aligned_to_morph else "unmorphed drawing"
        if self.corners is not None:
            out["corners"] = np.round(self.corners, 2).tolist()
            out["width_px"] = round(float(self.width_px or 0.0), 1)
        if self.too_small:
            out["too_small"] = self.size_json()
        if self.homography is not None:
            inv = np.linalg.inv(self.homography)
            out["homography"] = (inv / inv[2, 2]).round(8).tolist()  # image -> drawing (SVG units)
        out["keypoints"] = self.keypoints
        if self.pose is not None:
            out["pose"] = self.pose.to_json()
        return out


def seen_too_steeply(size: dict[str, Any]) -> bool:
    """Whether a print's ``too_small`` entry (:meth:`Located.size_json`) says it is wide enough
    head-on and too narrow only along its tilt."""
    return "along_tilt_px" in size and size["width_px"] >= size["needs_px"]


def too_small_reason(size: dict[str, Any]) -> str:
    """Why a print is not read, in words, from its ``too_small`` entry (:meth:`Located.size_json`):
    too small across, or seen so steeply that its tilt leaves it too few pixels
    (:func:`seen_too_steeply`)."""
    across, needs = size["width_px"], size["needs_px"]
    if seen_too_steeply(size):
        along = size["along_tilt_px"]
        return f"seen too steeply to read ({along:.0f} px along its tilt, {across:.0f} px across; needs {needs:.0f})"
    return f"too small to read ({across:.0f} px across, needs {needs:.0f})"


def refused_result(read: DecodeResult) -> DecodeResult:
    """``read`` refused for the print's size: no payload, not ok, so the print is reported
    :attr:`Located.too_small` (``Locator.refuses_reading``)."""
    return replace(read, payload=np.zeros_like(read.payload), ok=False, corrected_bits=-1)
