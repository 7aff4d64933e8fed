"""Alignment starts from the ink of a print, for outlines of the wrong shape.

A print seen steeply from the side is a thin parallelogram in the photo. The detector sometimes
outlines it as another parallelogram: the right centre and size, the wrong shear. No turn or
scale of that outline (:func:`~deepmorph_detect.refine.outline_sweep`) brings ECC into its
basin then. The ink says more than the outline. Its mean and second moments in the photo,
matched with the drawing's own, fix the affine map from drawing to photo up to one rotation
(the shear and the unequal stretch included), so a sweep of that rotation alone covers it.

The ink is found on the print's paper: the bright region (Otsu, around the outline) that
covers most of the outline, with its holes filled; the dark pixels inside it are ink. Clutter
outside the paper, and text that runs on under a print of the same brightness as the page, are
kept out by also staying within the outline grown by :data:`INK_REACH`.
"""

from __future__ import annotations

import cv2
import numpy as np

from deepmorph_detect.camera import around_outline

INK_REACH = 1.3  # ink is looked for within the outline grown by this about its centre
CONTEXT = 0.5  # the region thresholded reaches this many outline sizes beyond the outline
MIN_INK_PIXELS = 30  # fewer ink pixels than this give no moments worth matching
MIN_REGION = 16  # a region narrower than this (pixels) is not searched


def _matrix_sqrt(cov: np.ndarray) -> np.ndarray | None:
    """The symmetric square root of a ``(2, 2)`` covariance, or ``None`` when it is flat."""
    w, v = np.linalg.eigh(cov)
    if w.min() <= 1e-6 * max(w.max(), 1e-12):
        return None
    return v @ np.diag(np.sqrt(w)) @ v.T


def point_moments(points: np.ndarray, min_points: int = MIN_INK_PIXELS) -> tuple[np.ndarray, np.ndarray] | None:
    """Mean ``(2,)`` and covariance ``(2, 2)`` of ``(N, 2)`` points; ``None`` when fewer than
    ``min_points`` (too few ink pixels give no moments worth matching)."""
    if len(points) < max(min_points, 2):
        return None
    return points.mean(0), np.cov(points.T)


def print_ink(gray: np.ndarray, quad: np.ndarray) -> np.ndarray | None:
    """``(N, 2)`` pixel positions (x, y) of the ink on the print that ``quad`` (``(4, 2)``, an
    outline in the photo ``gray``) roughly covers; ``None`` when no paper or too little ink is
    found there."""
    quad = np.asarray(quad, dtype=np.float64)
    x0, y0, x1, y1 = around_outline(quad, gray.shape, CONTEXT)
    if x1 - x0 < MIN_REGION or y1 - y0 < MIN_REGION:
        return None
    region = gray[y0:y1, x0:x1]
    lo, hi = float(region.min()), float(region.max())
    if hi - lo < 1e-3:
        return None
    u8 = ((region - lo) * (255.0 / (hi - lo))).astype(np.uint8)
    _, bright = cv2.threshold(cv2.GaussianBlur(u8, (3, 3), 0.95), 0, 1, cv2.THRESH_BINARY | cv2.THRESH_OTSU)

    def inside(grow: float) -> np.ndarray:
        centre = quad.mean(0)
        poly = np.round((quad - centre) * grow + centre - [x0, y0]).astype(np.int32)
        mask = np.zeros_like(bright)
        cv2.fillConvexPoly(mask, poly, 1)
        return mask > 0

    n, labels = cv2.connectedComponents(bright, connectivity=4)
    counts = np.bincount(labels[inside(1.0)], minlength=n)
    counts[0] = 0  # the dark label
    if n <= 1 or counts.max() == 0:
        return None
    paper = (labels == counts.argmax()).astype(np.uint8)
    contours, _ = cv2.findContours(paper, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    filled = np.zeros_like(paper)
    cv2.drawContours(filled, contours, -1, 1, thickness=-1)
    ys, xs = np.nonzero((filled > 0) & (bright == 0) & inside(INK_REACH))
    if len(xs) < MIN_INK_PIXELS:
        return None
    return np.stack([xs + x0, ys + y0], 1).astype(np.float64)


def ink_starts(
    gray: np.ndarray, quad: np.ndarray, drawing_ink: tuple[np.ndarray, np.ndarray], turns: int
) -> list[np.ndarray]:
    """Homographies (SVG units -> image pixels) that map the drawing's ink moments
    (``drawing_ink``: mean and covariance in SVG units) onto those of the print's ink near
    ``quad``, one per turn in ``turns`` equal steps; empty when no ink moments are found."""
    points = print_ink(gray, quad)
    found = None if points is None else point_moments(points)
    if found is None:
        return []
    mean, cov = found
    mean_d, cov_d = drawing_ink
    to_photo, from_drawing = _matrix_sqrt(cov), _matrix_sqrt(cov_d)
    if to_photo is None or from_drawing is None:
        return []
    whiten = np.linalg.inv(from_drawing)
    starts = []
    for k in range(turns):
        a = 2 * np.pi * k / turns
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        A = to_photo @ rot @ whiten
        H = np.eye(3)
        H[:2, :2] = A
        H[:2, 2] = mean - A @ mean_d
        starts.append(H)
    return starts


__all__ = ["INK_REACH", "ink_starts", "point_moments", "print_ink"]
