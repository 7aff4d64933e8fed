"""The light on a print, estimated from the drawing itself: a second chance for a print that
aligned but did not read.

A cast shadow across a print is an edge the drawing does not have. ECC bends the alignment to it,
and the decoder reads the shadow's edge as ink. :func:`~deepmorph_core.photo.flatten_illumination`
divides out the paper's brightness under a grey closing wider than the drawing's thickest ink, so
it cannot follow a shadow across a large fill (a chip's body, a face). Once the print is aligned,
though, the drawing says what every pixel should be: the photo divided by the drawing's
reflectance is the light, wherever the drawing is flat (away from its edges, where the morph
acts and the alignment may be off). :class:`TemplateLight` smooths that ratio over those pixels
(a normalised convolution), divides it out of the photo around the print, and aligns the print
again in the photo so lit: first with a wide margin around the edges (the alignment may be off by
a few pixels), then with a narrow one. The print is then read in that photo
(``docs/detection.md``).
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from deepmorph_detect.camera import project
from deepmorph_detect.refine import Alignment, ImagePyramid, Template, refine

#: Pixels within this share of the print's width of one of the drawing's edges are left out of
#: the light's estimate: first the wide margin (the first alignment may be off), then the narrow.
EDGE_MARGINS = (0.05, 0.015)
#: The light's smoothing (a Gaussian's sigma) as a share of the print's width in the photo: wide
#: enough to leave the morph's edges alone, narrow enough to follow a shadow's.
LIGHT_SMOOTHING = 0.06
#: Where the pixels left out are more than this share of the smoothing's weight, the light is
#: taken from four times as wide a neighbourhood.
MIN_WEIGHT = 0.05
#: The light is smoothed on a grid shrunk so its sigma spans at most this many of the grid's
#: pixels: the light is smooth at that scale by definition, and a blur as wide as a large print's
#: (sigma 70 px at 1181 px, 280 px for the wide one) took 23 s on the full crop, 0.1 s shrunk.
SMOOTHING_GRID_SIGMA = 8.0
EDGE_STEP = 0.03  # a reflectance step this large between neighbouring pixels is an edge
DARKEST_REFLECTANCE = 0.05  # the photo is divided by no reflectance darker than this


def far_from_edges(reflectance: np.ndarray, radius: int) -> np.ndarray:
    """``(h, w)`` float32 mask of the pixels of ``reflectance`` (``(h, w)``, or ``(C, h, w)``:
    an edge in any channel counts) farther than ``radius`` pixels from any of its edges (a step
    of :data:`EDGE_STEP` or more between neighbours): where a print's light can be read off it."""
    channels = reflectance.reshape(-1, *reflectance.shape[-2:]).astype(np.float32)
    kernel = np.ones((3, 3), np.uint8)
    step = np.max([cv2.morphologyEx(c, cv2.MORPH_GRADIENT, kernel) for c in channels], axis=0)
    edges = (step > EDGE_STEP).astype(np.uint8)
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    return (cv2.dilate(edges, disk) == 0).astype(np.float32)


def smoothed_light(ratio: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """The light on a print from ``ratio`` (photo over reflectance, already multiplied by
    ``weight``, the mask of the pixels it is read at): their Gaussian-weighted mean within
    ``sigma`` pixels (a normalised convolution), or within four times that where the pixels read
    carry less than :data:`MIN_WEIGHT` of the weight; 1 where none is near at all. A ``sigma``
    over :data:`SMOOTHING_GRID_SIGMA` is applied on a grid shrunk (by area) to bring it there,
    and the light scaled back up."""
    shrink = SMOOTHING_GRID_SIGMA / sigma
    h, w = ratio.shape
    small = (max(1, round(w * shrink)), max(1, round(h * shrink)))
    if shrink >= 1.0 or small == (w, h):
        return _normalised_light(ratio, weight, sigma)
    ratio_small = cv2.resize(ratio, small, interpolation=cv2.INTER_AREA)
    weight_small = cv2.resize(weight, small, interpolation=cv2.INTER_AREA)
    light = _normalised_light(ratio_small, weight_small, SMOOTHING_GRID_SIGMA)
    return cv2.resize(light, (w, h), interpolation=cv2.INTER_LINEAR)


def _normalised_light(ratio: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """:func:`smoothed_light` at full resolution."""
    light = cv2.GaussianBlur(ratio, (0, 0), sigma)
    support = cv2.GaussianBlur(weight, (0, 0), sigma)
    wide_light = cv2.GaussianBlur(ratio, (0, 0), 4 * sigma)
    wide_support = cv2.GaussianBlur(weight, (0, 0), 4 * sigma)
    light = np.where(
        support > MIN_WEIGHT, light / np.maximum(support, 1e-6), wide_light / np.maximum(wide_support, 1e-6)
    )
    return np.where(wide_support > 1e-3, light, 1.0).astype(np.float32)


class TemplateLight:
    """Divides the light out of photos of one drawing, estimated from its unmorphed render.

    Args:
        template: the drawing's alignment template (its viewBox and levels).
        reflectance: the unmorphed drawing rendered over its viewBox, ``(h, w)`` float in
            ``[0, 1]``, 1 = white paper: what the print reflects in the channel the model reads.
    """

    def __init__(self, template: Template, reflectance: np.ndarray) -> None:
        self.template = template
        self.reflectance = np.ascontiguousarray(reflectance, dtype=np.float32)
        self._width = self.reflectance.shape[1]
        # every unread print asks for the same masks: made once
        self._flat = {margin: self._far_from_edges(margin) for margin in EDGE_MARGINS}

    def flat_pixels(self, margin: float) -> np.ndarray:
        """``(h, w)`` float32 mask of the render's pixels farther than ``margin`` (a share of
        its width) from any edge of the drawing."""
        return self._flat[margin] if margin in self._flat else self._far_from_edges(margin)

    def _far_from_edges(self, margin: float) -> np.ndarray:
        return far_from_edges(self.reflectance, max(1, round(margin * self._width)))

    def lit(self, gray: np.ndarray, homography: np.ndarray, margin: float) -> np.ndarray | None:
        """``gray`` with the light on the print at ``homography`` (SVG units -> pixels) divided
        out, estimated away from the drawing's edges by ``margin``; the photo elsewhere as it
        is. ``None`` when the print spans too few pixels."""
        M = homography @ self.template.to_svg_units(self._width)  # render px -> photo px
        th, tw = self.reflectance.shape
        quad = project(M, np.array([[0, 0], [tw, 0], [tw, th], [0, th]], np.float64))
        span = max(float(np.linalg.norm(quad[1] - quad[0])), float(np.linalg.norm(quad[2] - quad[1])))
        h, w = gray.shape
        x0, y0 = np.clip(np.floor(quad.min(0) - 2), 0, [w, h]).astype(int)
        x1, y1 = np.clip(np.ceil(quad.max(0) + 2), 0, [w, h]).astype(int)
        if min(x1 - x0, y1 - y0, span) < 8:
            return None
        to_crop = np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1]], np.float64) @ M
        size = (int(x1 - x0), int(y1 - y0))
        seen = cv2.warpPerspective(self.reflectance, to_crop, size, flags=cv2.INTER_LINEAR, borderValue=1.0)
        weight = cv2.warpPerspective(self.flat_pixels(margin), to_crop, size, flags=cv2.INTER_NEAREST)
        crop = gray[y0:y1, x0:x1].astype(np.float32)
        ratio = crop / np.maximum(seen, DARKEST_REFLECTANCE) * weight
        light = smoothed_light(ratio, weight, LIGHT_SMOOTHING * span)
        out = np.array(gray, dtype=np.float32, copy=True)
        out[y0:y1, x0:x1] = np.clip(crop / np.maximum(light, 1e-3), 0.0, 1.0)
        return out

    def align(
        self, gray: np.ndarray, homography: np.ndarray, accepts: Callable[[Alignment | None], bool]
    ) -> tuple[ImagePyramid, Alignment] | None:
        """The print at ``homography`` aligned again in the photo lit by :meth:`lit`, once per
        margin of :data:`EDGE_MARGINS`, each from the alignment before: the lit photo's pyramid
        and the last alignment, or ``None`` where ``accepts`` (the aligner's bar) refuses one."""
        found: tuple[ImagePyramid, Alignment] | None = None
        for margin in EDGE_MARGINS:
            lit = self.lit(gray, homography, margin)
            if lit is None:
                return None
            pyramid = ImagePyramid(lit)
            alignment = refine(pyramid, homography, self.template)
            if alignment is None or not accepts(alignment):
                return None
            found, homography = (pyramid, alignment), alignment.homography
        return found


__all__ = [
    "EDGE_MARGINS",
    "LIGHT_SMOOTHING",
    "SMOOTHING_GRID_SIGMA",
    "TemplateLight",
    "far_from_edges",
    "smoothed_light",
]
