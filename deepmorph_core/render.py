"""Hard rendering with a real SVG renderer (resvg), image files, and morph overlays.

resvg (through the ``resvg-py`` wheel) is the reference renderer: it is a self-contained Rust
library with no system dependencies (cairosvg needs a system Cairo), it follows the SVG spec
closely, never fetches anything, and renders the same bytes to the same pixels everywhere.

A render maps the drawing's viewBox onto the pixels asked for, as the soft rasterizer does: the
root's ``width`` and ``height`` (``50mm`` on a code made for print, fractions from editors) are
set to the viewBox's size first, because resvg rounds a document's own size to whole pixels
before scaling (a drawing 50 mm wide rendered 200 px wide came out up to 0.5 % off).
"""

from __future__ import annotations

import io

import numpy as np
import resvg_py
from lxml import etree
from PIL import Image

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, is_luma
from deepmorph_core.svg.plain_colours import plain_colours
from deepmorph_core.svg.secure import parse_svg_bytes
from deepmorph_core.svg.values import parse_numbers

#: The largest side of any raster DeepMorph makes, and the most pixels: what a print at 2400 dpi
#: and 17 cm takes; larger prints are what the SVG (or a PDF) is for.
MAX_RASTER_SIDE = 16_384
MAX_RASTER_PIXELS = 100_000_000
CSS_DPI = 96  # absolute lengths in a document without a viewBox (the wheel's default, 0, zeroes them)


def raster_size(viewbox: tuple[float, float, float, float], width: int) -> tuple[int, int]:
    """``(height, width)`` in pixels of a drawing rendered ``width`` pixels wide (its viewBox's
    aspect kept).

    Raises:
        DeepMorphError: a side over :data:`MAX_RASTER_SIDE` or more than :data:`MAX_RASTER_PIXELS`.
    """
    height = max(1, round(width * viewbox[3] / viewbox[2]))
    if max(width, height) > MAX_RASTER_SIDE or width * height > MAX_RASTER_PIXELS:
        raise DeepMorphError(
            f"a raster of {width} x {height} pixels is larger than DeepMorph makes "
            f"({MAX_RASTER_SIDE} pixels a side, {MAX_RASTER_PIXELS:,} in all); ask for fewer pixels"
        )
    return height, width


def sized_svg(svg_text: str, width: str, height: str) -> str:
    """``svg_text`` with its root's ``width`` and ``height`` set (lengths, with or without a
    unit); its viewBox and content unchanged.

    Raises:
        SvgError: not an SVG document (:func:`~deepmorph_core.svg.secure.parse_svg_bytes`).
    """
    root = parse_svg_bytes(svg_text.encode("utf-8"), "<svg>")
    root.set("width", width)
    root.set("height", height)
    return etree.tostring(root, encoding="unicode")


def at_viewbox_size(svg_text: str) -> str:
    """``svg_text`` with its root's ``width`` and ``height`` those of its viewBox (one pixel per
    user unit), or as it is without a viewBox (then the size is in user units already).

    Raises:
        SvgError: not an SVG document.
    """
    root = parse_svg_bytes(svg_text.encode("utf-8"), "<svg>")
    try:
        _, _, vw, vh = parse_numbers(root.get("viewBox") or "")
    except ValueError:
        return svg_text
    if vw <= 0 or vh <= 0 or (root.get("width"), root.get("height")) == (f"{vw:g}", f"{vh:g}"):
        return svg_text
    root.set("width", f"{vw:g}")
    root.set("height", f"{vh:g}")
    return etree.tostring(root, encoding="unicode")


def _render_png(svg_text: str, width: int) -> Image.Image:
    try:
        png = resvg_py.svg_to_bytes(
            svg_string=at_viewbox_size(plain_colours(svg_text)), width=width, background="#ffffff", dpi=CSS_DPI
        )
    except Exception as exc:  # the parser's SvgError; resvg's ValueError/RuntimeError
        raise DeepMorphError(f"the SVG renderer refused the drawing: {exc}") from None
    return Image.open(io.BytesIO(bytes(png)))


def render_svg(svg_text: str, width: int, channel: Channel = LUMA_WEIGHTS) -> np.ndarray:
    """Render SVG text with resvg on white paper, its viewBox ``width`` pixels across, as
    luminance (BT.601, PIL's ``L``: how the photo chain turns a colour photo to gray), or as
    the gray of another reading ``channel`` (red, green and blue weights).

    Returns:
        ``(H, W)`` float32 image intensity in ``[0, 1]`` (1 = white).

    Raises:
        DeepMorphError: a document resvg (or the secure parser before it) refuses.
    """
    if not is_luma(channel):
        return render_svg_rgb(svg_text, width) @ np.asarray(channel, dtype=np.float32)
    img = _render_png(svg_text, width).convert("RGB").convert("L")
    return np.asarray(img, dtype=np.float32) / 255.0


def render_svg_rgb(svg_text: str, width: int) -> np.ndarray:
    """Like :func:`render_svg`, in colour: ``(H, W, 3)`` float32 sRGB in ``[0, 1]``."""
    img = _render_png(svg_text, width).convert("RGB")
    return np.asarray(img, dtype=np.float32) / 255.0


def render_svg_ink(svg_text: str, width: int, channel: Channel = LUMA_WEIGHTS) -> np.ndarray:
    """Like :func:`render_svg` but as ink (1 = black), the rasterizer's convention."""
    return 1.0 - render_svg(svg_text, width, channel)


def overlay(base_ink: np.ndarray, morph_ink: np.ndarray) -> np.ndarray:
    """The morph drawn in black over the base drawn in red (the paper's Fig. 3 style).

    Args:
        base_ink, morph_ink: ``(H, W)`` ink in ``[0, 1]``.

    Returns:
        ``(H, W, 3)`` RGB in ``[0, 1]``.
    """
    rgb = np.ones(base_ink.shape + (3,), dtype=np.float32)
    red = np.array([0.9, 0.1, 0.1], dtype=np.float32)
    rgb = rgb * (1 - base_ink[..., None]) + red * base_ink[..., None]
    rgb = rgb * (1 - morph_ink[..., None])
    return rgb
