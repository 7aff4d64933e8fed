"""A print aligned on its edges alone: the slow light subtracted from the photo and the template.

ECC (:mod:`~deepmorph_detect.refine`) matches the photo to the unmorphed drawing up to one
contrast and one brightness for the whole print. A colour drawing's fills can be little darker
than its paper in the gray it is read in, and then a hard light's gradient across the sheet, or
its fall-off to the corners, is as strong as the drawing: the pink heart of the colour panel,
photographed hard, correlated at 0.61 with its template at the pose the simulator drew, and ECC
slid from there to a bent outline that correlated better. The light moves slowly across a print
and the drawing's edges do not, so here both images lose their Gaussian blur (sigma
:data:`SLOW_LIGHT_SHARE` of the print's width): what is left is the edges. From the same pose
ECC then stays within 5 % of the print's width (at 0.83), and the print reads.

Only for a detector's outline whose print was aligned and not read in the photo's own light
(:meth:`Locator.decode_each <deepmorph_detect.locate.Locator.decode_each>`): on prints that light
aligns, the edges alone, with less of the drawing to go on, have the narrower basin.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from deepmorph_detect.camera import around_outline, outline_size
from deepmorph_detect.refine import Alignment, ImagePyramid, Template, refine

#: The Gaussian subtracted from each image, its sigma as a share of the print's width (of the
#: template's, for the template): 0.05, 0.08 and 0.12 read the same close-ups within one print.
SLOW_LIGHT_SHARE = 0.08
#: An alignment on the edges that correlates less than this is not tried: the bar of a blind
#: proposal's reading in the photo's own light (``BLIND_READ_CORRELATION``).
EDGE_ALIGNMENT = 0.7
#: The photo is filtered this many print widths around the outline (the rest is left at 0).
CONTEXT = 0.3


def without_slow_light(image: np.ndarray, sigma: float) -> np.ndarray:
    """``image`` (``(H, W)`` float) less its Gaussian blur of ``sigma`` pixels, float32: its
    edges, with the light that changes slowly across it gone."""
    image = np.asarray(image, dtype=np.float32)
    return image - cv2.GaussianBlur(image, (0, 0), max(float(sigma), 0.5))


def edge_template(template: Template) -> Template:
    """The template's levels without their slow light (:func:`without_slow_light`), each at
    :data:`SLOW_LIGHT_SHARE` of its own width."""
    levels = {w: without_slow_light(image, SLOW_LIGHT_SHARE * w) for w, image in template.images.items()}
    return Template(template.viewbox, levels)


def photo_edges(gray: np.ndarray, corners: np.ndarray) -> ImagePyramid:
    """The photo's edges around a detector's outline ``corners`` (``(4, 2)``): the region
    :data:`CONTEXT` of its size beyond it without its slow light, the rest 0."""
    x0, y0, x1, y1 = around_outline(corners, gray.shape, CONTEXT)
    edges = np.zeros(gray.shape, np.float32)
    if x1 > x0 and y1 > y0:
        edges[y0:y1, x0:x1] = without_slow_light(gray[y0:y1, x0:x1], SLOW_LIGHT_SHARE * outline_size(corners))
    return ImagePyramid(edges)


def align_on_edges(
    gray: np.ndarray, start: np.ndarray, corners: np.ndarray, edges: Template, sized: bool
) -> Alignment | None:
    """The print a detector outlined (``corners``; ``start`` the homography, SVG units ->
    pixels, that puts the drawing's frame there) aligned on its edges: ECC from every corner
    order of the outline, then the wider searches of :func:`~deepmorph_detect.refine.refine`
    (``sized``: an ink square's) but the starts from the print's ink, which need its paper.
    ``edges`` is :func:`edge_template` of the drawing's. ``None`` below :data:`EDGE_ALIGNMENT`.

    The alignment's correlation is the edges' (in the photo's own light the print did not align).
    Its ``width`` is 0: it was reached at no level of the photo itself, so the morph check aligns
    the unmorphed drawing there afresh."""
    found = refine(photo_edges(gray, corners), start, edges, orders=4, accept=EDGE_ALIGNMENT, sized=sized, ink=False)
    if found is None or found.correlation < EDGE_ALIGNMENT:
        return None
    return replace(found, width=0)


__all__ = ["CONTEXT", "EDGE_ALIGNMENT", "SLOW_LIGHT_SHARE", "align_on_edges", "edge_template", "photo_edges",
           "without_slow_light"]  # fmt: skip
