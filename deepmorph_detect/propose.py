"""Proposing where a drawing may be in a photo: the detector's candidates, or the whole image.

The detector plugin (:class:`~deepmorph_core.protocols.Detector`) proposes a quadrilateral per
drawing. When it proposes none that aligns (or the model has no detector), the whole image is
tried as one candidate framed by its ink: a scan or a cropped photo in which the drawing fills
the frame. Alignment (:mod:`deepmorph_detect.align`) decides which candidates are the drawing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from deepmorph_core.photo import ink_mask, normalise_contrast
from deepmorph_core.protocols import Candidate
from deepmorph_detect.camera import project
from deepmorph_detect.refine import Template


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
    """

    centre: np.ndarray
    spread: float
    level: int

    @classmethod
    def of(cls, template: Template) -> InkFrame:
        finest = max(template.images)
        ys, xs = np.nonzero(template.images[finest] < 0.5)
        return cls(np.array([xs.mean(), ys.mean()]), float(xs.var() + ys.var()), finest)


def whole_frame(gray: np.ndarray, ink: InkFrame, template: Template, frame_corners: np.ndarray) -> list[Candidate]:
    """The ink of the whole image as one candidate, framed by its moments (no rotation):
    ``[]`` when the image shows no ink."""
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
    return [Candidate(project(H, frame_corners), 0.0, box, homography=H, source="whole-frame")]


__all__ = ["InkFrame", "quad_bbox", "whole_frame"]
