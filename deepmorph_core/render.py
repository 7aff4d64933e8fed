"""Hard rendering with a real SVG renderer (resvg), image files, and morph overlays.

resvg (through the ``resvg-py`` wheel) is the reference renderer: it is a self-contained Rust
library with no system dependencies (cairosvg needs a system Cairo), it follows the SVG spec
closely, never fetches anything, and renders the same bytes to the same pixels everywhere.
"""

from __future__ import annotations

import io

import numpy as np
import resvg_py
from PIL import Image

from deepmorph_core.errors import DeepMorphError

#: The largest side of any raster DeepMorph makes, and the most pixels: what a print at 2400 dpi
#: and 17 cm takes; larger prints are what the SVG (or a PDF) is for.
MAX_RASTER_SIDE = 16_384
MAX_RASTER_PIXELS = 100_000_000


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


def render_svg(svg_text: str, width: int) -> np.ndarray:
    """Render SVG text with resvg on white paper.

    Returns:
        ``(H, W)`` float32 image intensity in ``[0, 1]`` (1 = white).
    """
    try:
        png = resvg_py.svg_to_bytes(svg_string=svg_text, width=width, background="#ffffff")
    except Exception as exc:  # resvg raises ValueError/RuntimeError on bad documents
        raise DeepMorphError(f"the SVG renderer refused the drawing: {exc}") from None
    img = Image.open(io.BytesIO(bytes(png))).convert("L")
    return np.asarray(img, dtype=np.float32) / 255.0


def render_svg_ink(svg_text: str, width: int) -> np.ndarray:
    """Like :func:`render_svg` but as ink (1 = black), the rasterizer's convention."""
    return 1.0 - render_svg(svg_text, width)


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
