"""Proposing where a drawing may be in a photo: the detector's candidates, or the whole image.

The detector plugin (:class:`~deepmorph_core.protocols.Detector`) proposes a quadrilateral per
drawing. When it proposes none that aligns and is read (or the model has no detector), the
whole image is tried as one candidate framed by its ink: a scan or a cropped photo in which the
drawing fills the frame; when that does not align either, the whole image again in flat light
(:func:`whole_frame_in_flat_light`: a sharp shadow across the print is not ink). Alignment
(:mod:`deepmorph_detect.align`) decides which candidates are the drawing.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from deepmorph_core.photo import divided_by_paper, ink_mask, normalise_contrast, paper_light
from deepmorph_core.protocols import Candidate
from deepmorph_detect.camera import project
from deepmorph_detect.refine import Template

# the longest side a whole image's paper light is estimated and its ink framed at: the closing
# must be wider than the ink, and its cost grows with that width (640x480 at full size 0.3 s;
# shrunk to 240, 2.6 ms); the ink's moments need no finer image
FLAT_LIGHT_SIDE = 240
# ... and the longest side its ink is framed at in the photo's own light (and its paper sheet
# found at): a 1280x720 photo's ink mask took 11 ms at full size, and a photo without the
# drawing frames its whole image twice; ECC refines the framing from there
WHOLE_FRAME_SIDE = 640

#: the source of the candidate that frames the whole image by its ink
WHOLE_FRAME = "whole-frame"


def quad_bbox(quad: np.ndarray, width: int, height: int) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)``: the pixel box around ``(4, 2)`` corners, clipped to the image."""
    x0, y0 = np.floor(quad.min(0)).astype(int)
    x1, y1 = np.ceil(quad.max(0)).astype(int)
    return int(max(0, x0)), int(max(0, y0)), int(min(width, x1)), int(min(height, y1))


@dataclass(frozen=True)
class InkFrame:
    """Where the unmorphed drawing's ink lies in its finest template: what a whole image's ink
    is matched to.

    Attributes:
        centre: ``(2,)`` mean ink position, template pixels.
        spread: summed variance of the ink positions, template pixels squared.
        level: the template width they were measured at.
        box: ``(4, 2)`` corners (TL, TR, BR, BL, SVG units) of the box around the ink.
    """

    centre: np.ndarray
    spread: float
    level: int
    box: np.ndarray

    @classmethod
    def of(cls, template: Template) -> InkFrame:
        finest = max(template.images)
        ys, xs = np.nonzero(template.images[finest] < 0.5)
        x0, y0, x1, y1 = xs.min(), ys.min(), xs.max() + 1, ys.max() + 1
        box = project(template.to_svg_units(finest), np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64))
        return cls(np.array([xs.mean(), ys.mean()]), float(xs.var() + ys.var()), finest, box)


def whole_frame(gray: np.ndarray, ink: InkFrame, template: Template, frame_corners: np.ndarray) -> list[Candidate]:
    """The ink of the whole image as one candidate, framed by its moments (no rotation):
    ``[]`` when the image shows no ink. The ink is found on the image shrunk to at most
    :data:`WHOLE_FRAME_SIDE` pixels (:func:`at_most`)."""
    small, to_photo = at_most(gray, WHOLE_FRAME_SIDE)
    return in_photo_pixels(_framed_by_ink(small, ink, template, frame_corners), to_photo, gray.shape)


def _framed_by_ink(gray: np.ndarray, ink: InkFrame, template: Template, frame_corners: np.ndarray) -> list[Candidate]:
    """:func:`whole_frame` at ``gray``'s own size."""
    norm = normalise_contrast(gray)
    found = None if norm is None else ink_mask(norm)
    if found is None:
        return []
    mask, box = found
    ys, xs = np.nonzero(mask)
    if len(xs) < 10:
        return []
    s = float(np.sqrt((xs.var() + ys.var()) / max(ink.spread, 1e-9)))
    cx, cy = ink.centre
    # template px -> image px: scale s about the centroids
    T = np.array([[s, 0, xs.mean() - s * cx], [0, s, ys.mean() - s * cy], [0, 0, 1]])
    H = T @ np.linalg.inv(template.to_svg_units(ink.level))
    return [Candidate(project(H, frame_corners), 0.0, box, homography=H, source=WHOLE_FRAME)]


def at_most(gray: np.ndarray, side: int) -> tuple[np.ndarray, np.ndarray]:
    """``gray`` shrunk (area averaging) so that its longer side is at most ``side`` pixels, and
    the ``(3, 3)`` map from its pixels back to ``gray``'s (pixel centres to pixel centres; the
    identity where nothing was shrunk)."""
    h, w = gray.shape
    scale = min(1.0, side / max(h, w))
    if scale == 1.0:
        return gray, np.eye(3)
    small = cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    sx, sy = w / small.shape[1], h / small.shape[0]
    return small, np.array([[sx, 0, (sx - 1) / 2], [0, sy, (sy - 1) / 2], [0, 0, 1]])


def in_photo_pixels(candidates: list[Candidate], to_photo: np.ndarray, shape: tuple[int, int]) -> list[Candidate]:
    """``candidates`` found on a shrunk image (:func:`at_most`) in the pixels of the photo of
    ``shape`` (``(H, W)``), through ``to_photo``."""
    if np.array_equal(to_photo, np.eye(3)):
        return candidates
    h, w = shape
    return [
        Candidate(
            project(to_photo, cand.corners),
            cand.score,
            quad_bbox(np.reshape(cand.bbox, (2, 2)) * np.diagonal(to_photo)[:2], w, h),  # pixel edges scale
            homography=None if cand.homography is None else to_photo @ cand.homography,
            source=cand.source,
        )
        for cand in candidates
    ]


#: The paper sheet of a close-up fills at least this share of the photo.
MIN_SHEET_SHARE = 0.1


def whole_frame_on_paper(
    gray: np.ndarray, ink: InkFrame, template: Template, frame_corners: np.ndarray
) -> list[Candidate]:
    """:func:`whole_frame` within the paper sheet: the photo's largest bright region (Otsu),
    its holes (the drawing) filled, everything around it painted paper-white.

    A desk as dark as the drawing's ink (a print in light colours on a dark table) sets the
    photo's black point and takes the ink's place in the whole image's ink mask; on the sheet
    alone the drawing's own ink is the darkest. ``[]`` when no sheet fills
    :data:`MIN_SHEET_SHARE` of the photo, or it shows no ink. The sheet and its ink are found on
    the photo shrunk to at most :data:`WHOLE_FRAME_SIDE` pixels, as :func:`whole_frame` finds ink.
    """
    photo_shape = gray.shape
    gray, to_photo = at_most(gray, WHOLE_FRAME_SIDE)
    u8 = np.clip(gray * 255 if gray.dtype != np.uint8 else gray, 0, 255).astype(np.uint8)
    _, bright = cv2.threshold(cv2.GaussianBlur(u8, (5, 5), 0), 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(bright, connectivity=8)
    if n <= 1:
        return []
    sheet = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[sheet, cv2.CC_STAT_AREA] < MIN_SHEET_SHARE * gray.size:
        return []
    contours, _ = cv2.findContours((labels == sheet).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    filled = np.zeros(u8.shape, np.uint8)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    paper = float(np.median(gray[labels == sheet]))
    on_paper = np.where(filled > 0, gray, np.asarray(paper, dtype=gray.dtype))
    return in_photo_pixels(_framed_by_ink(on_paper, ink, template, frame_corners), to_photo, photo_shape)


def whole_frame_in_flat_light(
    gray: np.ndarray, ink: InkFrame, template: Template, frame_corners: np.ndarray, ink_share: float
) -> tuple[np.ndarray, list[Candidate]]:
    """:func:`whole_frame` with shadows and light gradients divided out, and the photo in that
    light to align and read in.

    Otsu takes a sharp shadow across a print (or the desk beside it) for ink, and the ink's
    moments then frame the shadow too; ECC in the photo itself bends to the shadow's edge. In
    flat light both see the drawing alone. The paper's light is estimated and the ink framed on
    the photo shrunk to at most :data:`FLAT_LIGHT_SIDE` pixels (a photo without the drawing
    costs only that); the candidate is scaled back, and the light enlarged and divided out of
    the whole photo only when something was framed.

    Args:
        ink_share: the drawing's thickest ink feature as a share of its frame's width; the
            drawing is at most as wide as the image, so that share of the image's longer side
            bounds its ink's width in pixels.

    Returns:
        The photo in flat light (``gray`` itself when nothing was framed) and the candidates.
    """
    small, to_photo = at_most(gray, FLAT_LIGHT_SIDE)
    paper = paper_light(small, max(ink_share * max(small.shape), 1.0))
    framed = _framed_by_ink(divided_by_paper(small, paper), ink, template, frame_corners)
    framed = in_photo_pixels(framed, to_photo, gray.shape)
    if not framed:
        return gray, []
    if small is not gray:
        paper = cv2.resize(paper, gray.shape[::-1], interpolation=cv2.INTER_LINEAR)
    return divided_by_paper(gray, paper), framed


__all__ = [
    "FLAT_LIGHT_SIDE",
    "MIN_SHEET_SHARE",
    "WHOLE_FRAME",
    "WHOLE_FRAME_SIDE",
    "at_most",
    "in_photo_pixels",
    "InkFrame",
    "quad_bbox",
    "whole_frame",
    "whole_frame_in_flat_light",
    "whole_frame_on_paper",
]
