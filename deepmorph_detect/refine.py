"""Sub-pixel alignment of a detected drawing, and its verification.

The detector's quadrilateral is good to a few pixels. Refinement aligns the photo to the
unmorphed drawing itself with OpenCV's ECC (enhanced correlation coefficient) maximisation
over a full homography, coarse to fine. Every ink pixel of the drawing acts as a keypoint,
so no point has to be singled out, and the correlation it reaches doubles as a check that
the thing found really is this drawing (another icon, a marker or clutter does not correlate).
A morph moves points by at most a few percent, so the unmorphed drawing is a faithful enough
template to find, verify and decode the drawing. It is not faithful enough for the pose: the
alignment absorbs part of the morph (about 2 px of corner error). Once the payload is read, the
locator aligns the photo once more, to the drawing morphed with that payload
(:func:`refine_at` with a template of the decoded morph), which brings the corners to a
fraction of a pixel.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from deepmorph_core.render import render_svg
from deepmorph_detect.camera import viewbox_corners

LEVELS = (48, 128)  # template widths, coarse to fine
COARSE_ITERATIONS = 15  # ECC iterations at the coarsest level (from the detector's rough outline)
FINE_ITERATIONS = 12  # at each finer level
ORDER_MARGIN = 0.15  # a corner order this far behind the best in plain correlation is not tried


@dataclass
class Template:
    """The unmorphed drawing rendered at each refinement level.

    Attributes:
        viewbox: ``(x, y, w, h)`` of the drawing in SVG units.
        images: template width -> ``(h, w)`` float32 render (1 = white).
    """

    viewbox: tuple[float, float, float, float]
    images: dict[int, np.ndarray]

    @classmethod
    def from_svg(
        cls, svg: str, viewbox: tuple[float, float, float, float], levels: tuple[int, ...] = LEVELS
    ) -> Template:
        """``svg`` rendered by the real renderer at each width in ``levels``."""
        return cls(viewbox, {w: render_svg(svg, w) for w in levels})

    @functools.cached_property
    def coarse_blurred(self) -> np.ndarray:
        """The coarsest level, blurred as candidates are before their corner order is scored."""
        return cv2.GaussianBlur(self.images[min(self.images)], (5, 5), 0)

    def shape(self, width: int) -> tuple[int, int]:
        """``(h, w)`` of the drawing's viewBox at ``width`` pixels."""
        _, _, vw, vh = self.viewbox
        return max(1, round(width * vh / vw)), width

    def to_svg_units(self, width: int) -> np.ndarray:
        """``(3, 3)`` map from template pixels (at ``width``) to SVG units."""
        x, y, vw, _ = self.viewbox
        s = vw / width
        return np.array([[s, 0, x], [0, s, y], [0, 0, 1]], dtype=np.float64)


@dataclass
class Alignment:
    """A refined homography (SVG units -> image pixels), the correlation it reached, and the
    template width it was reached at."""

    homography: np.ndarray
    correlation: float
    width: int = 0


class ImagePyramid:
    """Halvings of a grayscale photo, made on demand, so warps never alias."""

    def __init__(self, gray: np.ndarray) -> None:
        self.levels = [np.ascontiguousarray(gray, dtype=np.float32)]

    def at_most(self, factor: float) -> tuple[np.ndarray, float]:
        """The level whose downscaling leaves at most a 2x shrink to the warp; and its scale."""
        k = 0
        while factor / (2 ** (k + 1)) >= 1.5 and min(self.levels[-1].shape) > 16:
            k += 1
            if len(self.levels) <= k:
                self.levels.append(cv2.pyrDown(self.levels[-1]))
        return self.levels[k], 0.5**k


def warp_to_template(pyramid: ImagePyramid, homography: np.ndarray, template: Template, width: int) -> np.ndarray:
    """The photo resampled into the template's frame at ``width`` through ``homography``."""
    th, tw = template.shape(width)
    M = homography @ template.to_svg_units(width)  # template px -> image px
    corners = np.array([[0, 0, 1], [tw, 0, 1], [tw, th, 1], [0, th, 1]], dtype=np.float64) @ M.T
    xy = corners[:, :2] / corners[:, 2:3]
    span = max(np.linalg.norm(xy[1] - xy[0]), np.linalg.norm(xy[2] - xy[3]), 1e-6)
    img, scale = pyramid.at_most(span / tw)
    S = np.diag([scale, scale, 1.0])
    return cv2.warpPerspective(
        img, S @ M, (tw, th), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE
    )


def _ecc_step(
    pyramid: ImagePyramid,
    H: np.ndarray,
    template: Template,
    width: int,
    iterations: int,
    smooth: int,
    crop: np.ndarray | None = None,
) -> tuple[np.ndarray, float] | None:
    """One ECC solve at one template width: the improved homography and its correlation
    (``crop``: the photo already warped through ``H`` at ``width``, when the caller has it)."""
    if crop is None:
        crop = warp_to_template(pyramid, H, template, width)
    W = np.eye(3, dtype=np.float32)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, 1e-5)
    try:
        rho, W = cv2.findTransformECC(template.images[width], crop, W, cv2.MOTION_HOMOGRAPHY, criteria, None, smooth)
    except cv2.error:  # diverged, or a degenerate warp
        return None
    S = template.to_svg_units(width)
    out = H @ S @ W.astype(np.float64) @ np.linalg.inv(S)
    return out / out[2, 2], float(rho)


def refine_at(
    pyramid: ImagePyramid, homography: np.ndarray, template: Template, width: int, iterations: int = 10
) -> Alignment | None:
    """One ECC solve against ``template`` at ``width`` (which it must hold), from ``homography``;
    ``None`` when ECC diverges."""
    step = _ecc_step(pyramid, np.asarray(homography, np.float64), template, width, iterations, 3)
    return None if step is None else Alignment(*step, width)


def corner_orders(homography: np.ndarray, template: Template) -> list[np.ndarray]:
    """The homography with the frame's corners taken in each of the four cyclic orders
    (the drawing turned by 0, 90, 180 and 270 degrees within the same outline)."""
    frame = viewbox_corners(template.viewbox).astype(np.float32)
    pts = np.column_stack([frame, np.ones(4)]) @ np.asarray(homography, dtype=np.float64).T
    quad = (pts[:, :2] / pts[:, 2:3]).astype(np.float32)
    return [cv2.getPerspectiveTransform(frame, np.roll(quad, k, axis=0)).astype(np.float64) for k in range(4)]


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Zero-mean normalised cross-correlation of two same-size images (ECC's own measure)."""
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 1e-12 else 0.0


def refine(
    pyramid: ImagePyramid,
    homography: np.ndarray,
    template: Template,
    iterations: tuple[int, ...] | None = None,
    orders: int = 1,
    min_start: float = 0.1,
) -> Alignment | None:
    """Refine ``homography`` (SVG units -> image pixels) by ECC, coarse to fine over the
    template's levels.

    Args:
        iterations: ECC iterations at each level (most converge in fewer); by default
            :data:`COARSE_ITERATIONS` at the coarsest and :data:`FINE_ITERATIONS` at the others.
        orders: 4 to also try the frame's corners in the other cyclic orders (the detector
            outlines a drawing but may miss its turn); the order that correlates best with the
            template before any iteration is kept.
        min_start: candidates correlating less than this before refinement are dropped at
            once (clutter and other drawings: no iterations spent on them).

    Returns:
        The refined alignment, or ``None`` when the candidate is rejected or ECC diverges at the
        coarsest level.
    """
    levels = sorted(template.images)
    its = iterations or (COARSE_ITERATIONS,) + (FINE_ITERATIONS,) * (len(levels) - 1)
    starts = corner_orders(homography, template)[:orders] if orders > 1 else [np.asarray(homography, np.float64)]
    scored = []
    for H in starts:
        crop = warp_to_template(pyramid, H, template, levels[0])
        scored.append((correlation(template.coarse_blurred, cv2.GaussianBlur(crop, (5, 5), 0)), H, crop))
    scored.sort(key=lambda r: -r[0])
    if scored[0][0] < min_start:
        return None
    # the best two orders by plain correlation hold the right one almost always; ECC decides
    # between them unless the best is ahead by a clear margin
    close = [r for r in scored[:2] if scored[0][0] - r[0] < ORDER_MARGIN]
    tries = [_ecc_step(pyramid, H, template, levels[0], its[0], 5, crop) for _, H, crop in close]
    found = [t for t in tries if t is not None]
    if not found:
        return None
    H, rho = max(found, key=lambda r: r[1])
    reached = levels[0]
    for width, n in zip(levels[1:], its[1:]):
        step = _ecc_step(pyramid, H, template, width, n, 3)
        if step is None:
            break
        (H, rho), reached = step, width
    return Alignment(H, rho, reached)


__all__ = [
    "LEVELS",
    "Alignment",
    "ImagePyramid",
    "Template",
    "corner_orders",
    "correlation",
    "refine",
    "refine_at",
    "warp_to_template",
]
