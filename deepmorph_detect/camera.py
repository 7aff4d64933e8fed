"""Camera intrinsics and planar pose (PnP).

Pose is expressed in the drawing's own frame: origin at the centre of the drawing's viewBox,
x to the right, y down (as in the SVG), z into the paper, in units of the drawing's printed
width. So ``tvec`` of ``(0, 0, 4)`` means the drawing is straight ahead at four drawing-widths.

Without a calibration, :meth:`Camera.default` assumes a horizontal field of view of
:data:`DEFAULT_HFOV_DEG` (a typical phone main camera) with the principal point at the image
centre; every pose computed that way says so (``camera.assumed``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.print_size import PHONE_FOV_DEG

#: The phone camera assumed without a calibration: the one ``deepmorph capacity`` plans prints for.
DEFAULT_HFOV_DEG = PHONE_FOV_DEG
#: the horizontal fields of view (degrees) of the cameras :func:`rigid_misfit` tries: phones'
#: main and wide cameras
PHONE_FOV_RANGE_DEG = (50.0, 57.5, 65.0, 72.5, 80.0)
ASPECT_TOLERANCE = 0.01  # a calibration's image shape and the photo's may differ this much (rounding)


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics (pixels) and optional OpenCV distortion coefficients."""

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = ()
    assumed: bool = False
    size: tuple[int, int] | None = None  # (width, height) of the images it was calibrated on, when known

    @property
    def matrix(self) -> np.ndarray:
        """The ``(3, 3)`` camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        return np.asarray(self.dist, dtype=np.float64) if self.dist else np.zeros(5)

    @classmethod
    def default(cls, width: int, height: int, hfov_deg: float = DEFAULT_HFOV_DEG) -> Camera:
        """The assumed camera for an image without calibration."""
        f = (width / 2) / math.tan(math.radians(hfov_deg) / 2)
        return cls(f, f, width / 2, height / 2, assumed=True)

    def for_image(self, width: int, height: int) -> Camera:
        """These intrinsics for a ``width`` x ``height`` image.

        A calibration made at another resolution of the same frame (a video's full-size frames,
        say, and a downscaled photo) is scaled to it; one of another aspect ratio (a crop, or a
        photo turned a quarter) is an error, as is a principal point outside the image: either
        way the pose would be silently wrong.

        Raises:
            DeepMorphError: the intrinsics cannot describe this image.
        """
        cam = self
        if self.size is not None and self.size != (width, height):
            cw, ch = self.size
            if abs(width / height - cw / ch) > ASPECT_TOLERANCE * cw / ch:
                raise DeepMorphError(
                    f"the camera calibration is for {cw}x{ch} images, this one is {width}x{height}"
                    " (another shape: a crop, or turned a quarter?); calibrate for this frame"
                )
            s = width / cw
            cam = replace(self, fx=self.fx * s, fy=self.fy * s, cx=self.cx * s, cy=self.cy * s, size=(width, height))
        if not (0 <= cam.cx <= width and 0 <= cam.cy <= height):
            raise DeepMorphError(
                f"the camera's principal point ({cam.cx:g}, {cam.cy:g}) lies outside this {width}x{height}"
                " image: intrinsics for another image size? (a calibration file that records"
                " image_width and image_height is scaled to the image)"
            )
        return cam

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy, "assumed": self.assumed}
        if self.assumed:
            out["note"] = f"no calibration given: assumed {DEFAULT_HFOV_DEG:g} deg horizontal field of view"
        if self.dist:
            out["dist"] = list(self.dist)
        if self.size is not None:
            out["image_size"] = list(self.size)
        return out


def viewbox_corners(viewbox: tuple[float, float, float, float]) -> np.ndarray:
    """``(4, 2)`` corners of a viewBox in SVG units: top-left, top-right, bottom-right, bottom-left."""
    x, y, w, h = viewbox
    return np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]], dtype=np.float64)


def viewbox_to_frame(viewbox: tuple[float, float, float, float]) -> np.ndarray:
    """``(3, 3)`` map from SVG units to the pose frame (viewBox centre origin, width units)."""
    x, y, w, h = viewbox
    return np.array([[1 / w, 0, -x / w - 0.5], [0, 1 / w, -(y + h / 2) / w], [0, 0, 1]])


def parse_camera(spec: str) -> Camera:
    """``fx,fy,cx,cy`` (pixels), or the path of an OpenCV calibration file (YAML/XML/JSON).

    A calibration file holds ``camera_matrix`` (or ``K``) and optionally
    ``distortion_coefficients`` (or ``dist_coeffs``/``D``), as ``cv2.FileStorage`` writes them.

    Raises:
        DeepMorphError: anything else, naming what is wrong.
    """
    text = spec.strip()
    path = Path(text)
    if path.suffix.lower() in (".yml", ".yaml", ".xml", ".json") or path.is_file():
        return load_calibration(path)
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 4:
        raise DeepMorphError(f"--camera {spec!r}: expected fx,fy,cx,cy (four numbers in pixels) or a calibration file")
    try:
        fx, fy, cx, cy = (float(p) for p in parts)
    except ValueError:
        raise DeepMorphError(f"--camera {spec!r}: fx,fy,cx,cy must be numbers") from None
    if not all(math.isfinite(v) for v in (fx, fy, cx, cy)) or fx <= 0 or fy <= 0:
        raise DeepMorphError(f"--camera {spec!r}: focal lengths must be positive and all values finite")
    return Camera(fx, fy, cx, cy)


def _read_matrix(node: cv2.FileNode, path: Path, key: str) -> np.ndarray | None:
    """A matrix node of a calibration file; OpenCV asserts on a malformed one (its data not
    ``rows x cols`` numbers), which becomes one clear error."""
    try:
        return node.mat()
    except (cv2.error, SystemError):
        raise DeepMorphError(
            f"{path}: {key} is not a well-formed matrix (its data must be rows x cols numbers)"
        ) from None


def load_calibration(path: str | Path) -> Camera:
    """Read an OpenCV calibration file (see :func:`parse_camera`)."""
    path = Path(path)
    if not path.is_file():
        raise DeepMorphError(f"{path}: no such calibration file")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError):  # a parse error surfaces as either, by OpenCV version
        raise DeepMorphError(f"{path}: not a calibration file OpenCV can read") from None
    try:
        if not fs.isOpened():
            raise DeepMorphError(f"{path}: not a calibration file OpenCV can read")
        matrix = None
        for key in ("camera_matrix", "K", "cameraMatrix"):
            node = fs.getNode(key)
            if not node.empty():
                matrix = _read_matrix(node, path, key)
                break
        if matrix is None or matrix.shape != (3, 3):
            raise DeepMorphError(f"{path}: no 3x3 camera_matrix in the calibration file")
        size = _image_size(fs, path)
        dist: tuple[float, ...] = ()
        for key in ("distortion_coefficients", "dist_coeffs", "D", "distCoeffs"):
            node = fs.getNode(key)
            if not node.empty():
                d = _read_matrix(node, path, key)
                if d is not None:
                    dist = tuple(float(v) for v in np.asarray(d).ravel())
                break
    finally:
        fs.release()
    m = np.asarray(matrix, dtype=np.float64)
    if not np.isfinite(m).all() or m[0, 0] <= 0 or m[1, 1] <= 0 or not all(math.isfinite(v) for v in dist):
        raise DeepMorphError(f"{path}: camera_matrix must have positive focal lengths and finite values")
    if dist and len(dist) not in (4, 5, 8, 12, 14):
        raise DeepMorphError(f"{path}: {len(dist)} distortion coefficients (OpenCV takes 4, 5, 8, 12 or 14)")
    return Camera(float(m[0, 0]), float(m[1, 1]), float(m[0, 2]), float(m[1, 2]), dist, size=size)


def _image_size(fs: cv2.FileStorage, path: Path) -> tuple[int, int] | None:
    """``(image_width, image_height)`` as OpenCV's calibration tools record them, if present."""
    w, h = fs.getNode("image_width"), fs.getNode("image_height")
    if w.empty() or h.empty():
        return None
    width, height = w.real(), h.real()
    if not (width >= 1 and height >= 1 and float(width).is_integer() and float(height).is_integer()):
        raise DeepMorphError(f"{path}: image_width and image_height must be whole numbers of pixels")
    return int(width), int(height)


def solve_pose(camera: Camera, object_points: np.ndarray, image_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Iterative PnP (Levenberg-Marquardt from a planar initialisation).

    Args:
        object_points: ``(N, 3)`` points in the drawing frame (drawing-width units, z = 0).
        image_points: ``(N, 2)`` their pixel positions.

    Returns:
        ``rvec`` and ``tvec``, each ``(3,)``.
    """
    obj = np.ascontiguousarray(object_points, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(image_points, dtype=np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.matrix, camera.dist_coeffs, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(obj, img, camera.matrix, camera.dist_coeffs, flags=cv2.SOLVEPNP_ITERATIVE)
    else:
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera.matrix, camera.dist_coeffs, rvec, tvec)
    return rvec.reshape(3), tvec.reshape(3)


def homography_from_pose(camera: Camera, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """``(3, 3)`` map from drawing-frame plane coordinates ``(X, Y, 1)`` to pixels (no distortion)."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    return camera.matrix @ np.column_stack([R[:, 0], R[:, 1], np.asarray(tvec, dtype=np.float64).reshape(3)])


def rigid_misfit(homography: np.ndarray, corners: np.ndarray, image_size: tuple[int, int]) -> float:
    """How far an alignment's outline is from any outline a flat print can have in the photo.

    ``homography`` (SVG units -> pixels) puts the drawing's frame ``corners`` (``(4, 2)`` SVG
    units, TL, TR, BR, BL) somewhere in a ``(width, height)`` photo. A flat sheet seen by a
    pinhole camera makes only some of the quadrilaterals a homography can: its pose has six
    degrees of freedom, a homography eight. The outline is fitted by a pose (PnP) for cameras
    centred in the photo with each field of view in :data:`PHONE_FOV_RANGE_DEG`; the answer is
    the least mean corner distance, as a share of the outline's top edge. An alignment bent by a
    cast shadow's edge is far from every such outline. A cropped photo moves the principal
    point, so a large misfit says "look again", never "not a print".
    """
    quad = project(homography, corners)
    width = max(float(np.linalg.norm(quad[1] - quad[0])), 1.0)
    frame = np.asarray(corners, dtype=np.float64)
    span = max(float(np.ptp(frame[:, 0])), 1e-9)
    plane = (frame - frame.mean(0)) / span  # the pose frame: centred, in drawing widths
    sheet = np.column_stack([plane, np.zeros(len(plane))])
    best = math.inf
    for fov in PHONE_FOV_RANGE_DEG:
        camera = Camera.default(*image_size, fov)
        seen = project(homography_from_pose(camera, *solve_pose(camera, sheet, quad)), plane)
        best = min(best, float(np.linalg.norm(seen - quad, axis=1).mean()) / width)
    return best


def rotation_error_deg(rvec_a: np.ndarray, rvec_b: np.ndarray) -> float:
    """Angle (degrees) of the rotation taking pose a to pose b."""
    Ra, _ = cv2.Rodrigues(np.asarray(rvec_a, dtype=np.float64).reshape(3, 1))
    Rb, _ = cv2.Rodrigues(np.asarray(rvec_b, dtype=np.float64).reshape(3, 1))
    cos = (np.trace(Ra.T @ Rb) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def translation_error(tvec_a: np.ndarray, tvec_b: np.ndarray) -> float:
    """Relative translation error ``|a - b| / |b|``."""
    b = np.asarray(tvec_b, dtype=np.float64)
    return float(np.linalg.norm(np.asarray(tvec_a, dtype=np.float64) - b) / max(np.linalg.norm(b), 1e-9))


def project(homography: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a ``(3, 3)`` homography to ``(N, 2)`` points."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    h = np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(homography, dtype=np.float64).T
    return h[:, :2] / h[:, 2:3]


def outline_size(quad: np.ndarray) -> float:
    """A ``(4, 2)`` outline's size in pixels: the longer of its first two sides, at least 1."""
    q = np.asarray(quad, dtype=np.float64)
    return max(float(np.linalg.norm(q[1] - q[0])), float(np.linalg.norm(q[2] - q[1])), 1.0)


def around_outline(quad: np.ndarray, image_shape: tuple[int, ...], reach: float) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)``: the box around a ``(4, 2)`` outline reaching ``reach`` of its size
    (:func:`outline_size`) beyond its bounds, in whole pixels, clipped to an image of
    ``image_shape`` ``(h, w, ...)``: the region a search or a filter around a print works in."""
    q = np.asarray(quad, dtype=np.float64)
    margin = reach * outline_size(q)
    h, w = image_shape[:2]
    x0, y0 = np.clip(np.floor(q.min(0) - margin), 0, [w, h]).astype(int)
    x1, y1 = np.clip(np.ceil(q.max(0) + margin), 0, [w, h]).astype(int)
    return int(x0), int(y0), int(x1), int(y1)


__all__ = [
    "DEFAULT_HFOV_DEG",
    "PHONE_FOV_RANGE_DEG",
    "Camera",
    "around_outline",
    "homography_from_pose",
    "load_calibration",
    "outline_size",
    "parse_camera",
    "project",
    "rigid_misfit",
    "rotation_error_deg",
    "solve_pose",
    "translation_error",
    "viewbox_corners",
    "viewbox_to_frame",
]
