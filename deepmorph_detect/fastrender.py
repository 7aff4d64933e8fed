"""A second real renderer, Skia, for the renders that decoding makes on every photo.

resvg (:mod:`deepmorph_core.render`) is the reference renderer: scenes are printed with it and
the tests check against it. Through its Python wheel every render comes back PNG-encoded, and
encoding and decoding the PNG is most of the cost. Decoding a photo renders the drawing
morphed with the payload it read (the morph check,
:meth:`~deepmorph_detect.check.PayloadChecker.fit_morph`), one of the largest stages of a
decoded frame. Skia (``skia-python``: Chrome's 2D engine and its SVG module) draws the same
document straight into memory, in 8-bit gray at 4x the size and averaged down: about 5x faster.

A renderer that draws a document differently from resvg would shift what the photo is
compared with. :func:`template_renderer` therefore renders the drawing itself with both at
load, and keeps Skia only when the two agree (:data:`MAX_MEAN_DIFFERENCE`); otherwise resvg
renders every template. The morph check compares two renders by one renderer, so either way
it compares like with like. The ``skia-python`` wheel loads the system's libGL and libEGL;
where they are missing (a minimal container image), resvg renders everything.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, is_luma, stretch_ink
from deepmorph_core.render import render_svg
from deepmorph_core.svg.plain_colours import plain_colours

try:
    import skia
except (ImportError, OSError) as _missing:  # the wheel loads the system's libGL and libEGL
    skia = None
    SKIA_UNAVAILABLE: str | None = f"skia-python cannot be loaded ({_missing})"
else:
    SKIA_UNAVAILABLE = None

# (svg text, width in pixels, viewBox (x, y, w, h)) -> (h, w) float32, 1 = white paper
Renderer = Callable[[str, int, tuple[float, float, float, float]], np.ndarray]

# Skia is kept for a drawing when its renders differ from resvg's by at most this much on
# average (intensity in [0, 1]), at every width checked: above what anti-aliasing along the
# edges gives, below a document Skia draws differently (markers, transform-origin: 0.04 and more)
MAX_MEAN_DIFFERENCE = 0.015
SUPERSAMPLE = 4  # Skia draws at this many times the size, then averages (see render_svg_skia)


def render_svg_skia(
    svg_text: str, width: int, viewbox: tuple[float, float, float, float], supersample: int = SUPERSAMPLE
) -> np.ndarray:
    """Render SVG text with Skia on white paper, ``width`` pixels across its viewBox.

    Drawn in 8-bit gray at ``supersample`` times the size, then area-averaged: Skia's own
    anti-aliasing at the final size puts edges up to 0.09 px off where an exact coverage puts
    them, which makes the poses aligned to such a template worse; supersampled, they are as
    good as with resvg's.

    Returns:
        ``(H, W)`` float32 intensity in ``[0, 1]`` (1 = white), ``H`` from the viewBox's aspect.

    Raises:
        DeepMorphError: Skia cannot read the document, or cannot be loaded.
    """
    if skia is None:
        raise DeepMorphError(f"the SVG renderer Skia is not available: {SKIA_UNAVAILABLE}")
    dom = skia.SVGDOM.MakeFromStream(skia.MemoryStream(plain_colours(svg_text).encode("utf-8"), True))
    if dom is None:
        raise DeepMorphError("the SVG renderer (Skia) refused the drawing")
    _, _, vw, vh = viewbox
    size = dom.containerSize()
    if size.width() <= 0 or size.height() <= 0:  # no width/height: the viewBox is the size
        dom.setContainerSize(skia.Size(vw, vh))
        size = dom.containerSize()
    height = max(1, round(width * vh / vw))
    k = max(1, int(supersample))
    gray = np.full((height * k, width * k), 255, dtype=np.uint8)
    canvas = skia.Surface(gray, colorType=skia.kGray_8_ColorType).getCanvas()
    canvas.scale(width * k / size.width(), width * k / size.width())
    dom.render(canvas)
    del canvas
    return _area_average(gray, k) if k > 1 else gray.astype(np.float32) / 255.0


def _area_average(gray: np.ndarray, k: int) -> np.ndarray:
    """``(H * k, W * k)`` uint8 gray averaged over ``k x k`` blocks to ``(H, W)`` float32 in
    ``[0, 1]``: halved once in 8 bits where the factor is even and above 2 (OpenCV's quickest
    path), the rest averaged in float. One 8-bit rounding, as a single 8-bit average has, in
    about a third of its time."""
    h, w = gray.shape[0] // k, gray.shape[1] // k
    if k > 2 and k % 2 == 0:
        gray = cv2.resize(gray, (gray.shape[1] // 2, gray.shape[0] // 2), interpolation=cv2.INTER_AREA)
        k //= 2
    out = gray.astype(np.float32)
    if k > 1:
        out = cv2.resize(out, (w, h), interpolation=cv2.INTER_AREA)
    out *= np.float32(1.0 / 255.0)
    return out


def render_svg_resvg(svg_text: str, width: int, viewbox: tuple[float, float, float, float]) -> np.ndarray:
    """:func:`~deepmorph_core.render.render_svg` with the :data:`Renderer` signature."""
    return render_svg(svg_text, width)


def channel_renderer(channel: Channel) -> Renderer:
    """resvg rendering in a model's reading ``channel`` (its colour render, weighted), with the
    :data:`Renderer` signature."""

    def render(svg_text: str, width: int, viewbox: tuple[float, float, float, float]) -> np.ndarray:
        return render_svg(svg_text, width, channel)

    return render


def renders_alike(svg_text: str, viewbox: tuple[float, float, float, float], widths: tuple[int, ...]) -> float:
    """The largest mean absolute difference between Skia's and resvg's renders of ``svg_text``
    over ``widths`` (``inf`` when Skia cannot read it or the sizes differ)."""
    worst = 0.0
    for width in widths:
        reference = render_svg(svg_text, width)
        try:
            fast = render_svg_skia(svg_text, width, viewbox)
        except DeepMorphError:
            return float("inf")
        if fast.shape != reference.shape:
            return float("inf")
        worst = max(worst, float(np.abs(fast - reference).mean()))
    return worst


def stretched_renderer(renderer: Renderer, level: float) -> Renderer:
    """``renderer`` with its renders' contrast stretched (:func:`~deepmorph_core.luminance.stretch_ink`):
    ``level``, the drawing's darkest paint, to black; ``renderer`` itself at level 0."""
    if level <= 0:
        return renderer

    def render(svg_text: str, width: int, viewbox: tuple[float, float, float, float]) -> np.ndarray:
        return stretch_ink(renderer(svg_text, width, viewbox), level)

    return render


def template_renderer(
    svg_text: str,
    viewbox: tuple[float, float, float, float],
    widths: tuple[int, ...],
    channel: Channel = LUMA_WEIGHTS,
) -> tuple[str, Renderer]:
    """The renderer for a drawing's templates and its name: Skia when it renders ``svg_text``
    like resvg at each of ``widths`` (:data:`MAX_MEAN_DIFFERENCE`), else resvg (also where
    Skia cannot be loaded: the same results, a few milliseconds slower per decoded drawing).
    A drawing read in another channel than luminance is rendered by resvg in that channel
    (Skia draws gray as luminance)."""
    if not is_luma(channel):
        return "resvg", channel_renderer(channel)
    if skia is not None and renders_alike(svg_text, viewbox, widths) <= MAX_MEAN_DIFFERENCE:
        return "skia", render_svg_skia
    return "resvg", render_svg_resvg


__all__ = [
    "MAX_MEAN_DIFFERENCE",
    "SKIA_UNAVAILABLE",
    "SUPERSAMPLE",
    "Renderer",
    "channel_renderer",
    "render_svg_resvg",
    "render_svg_skia",
    "renders_alike",
    "stretched_renderer",
    "template_renderer",
]
