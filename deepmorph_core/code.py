"""A code: a payload hidden in a drawing, as the morphed SVG and as images made for print.

:meth:`DeepMorphModel.code <deepmorph_core.model.DeepMorphModel.code>` makes one. Its SVG is
the drawing with the payload's morph written in; :meth:`Code.png` renders it with the real
renderer at a printed size and resolution, and records that resolution in the file so that
printing it gives the intended size.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from PIL import Image

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.payload import Payload
from deepmorph_core.render import raster_size, render_svg

MM_PER_INCH = 25.4
MAX_RASTER_SIDE = 16_384  # pixels: a larger print is what the SVG (or a PDF) is for


def print_pixels(width_mm: float, dpi: int) -> int:
    """Pixels across a print ``width_mm`` wide at ``dpi`` dots per inch.

    Raises:
        DeepMorphError: a size or resolution that is not positive, or a raster wider than
            :data:`MAX_RASTER_SIDE` pixels.
    """
    if not (width_mm > 0 and dpi > 0):
        raise DeepMorphError(f"a print needs a positive width and resolution, got {width_mm:g} mm at {dpi} dpi")
    px = round(width_mm / MM_PER_INCH * dpi)
    if px > MAX_RASTER_SIDE:
        raise DeepMorphError(
            f"{width_mm:g} mm at {dpi} dpi is {px} pixels across, more than {MAX_RASTER_SIDE}; "
            "print the SVG (it has no resolution) or lower the resolution"
        )
    return max(16, px)


@dataclass(frozen=True)
class Code:
    """A payload hidden in a drawing.

    Attributes:
        payload: what it carries.
        svg: the morphed drawing as an SVG document.
        viewbox: ``(x, y, width, height)`` of the drawing, in its user units.
    """

    payload: Payload
    svg: str
    viewbox: tuple[float, float, float, float]

    def render(self, width_px: int) -> np.ndarray:
        """``(H, W)`` float32 intensity in ``[0, 1]`` (1 = white paper), ``width_px`` wide."""
        return render_svg(self.svg, width_px)

    def png(self, width_mm: float = 50.0, dpi: int = 300) -> bytes:
        """A PNG of the code ``width_mm`` wide at ``dpi`` dots per inch (recorded in the file)."""
        px = print_pixels(width_mm, dpi)
        raster_size(self.viewbox, px)  # refused before rendering when too large
        gray = np.clip(np.rint(self.render(px) * 255), 0, 255).astype(np.uint8)
        buf = io.BytesIO()
        Image.fromarray(gray, "L").save(buf, format="PNG", dpi=(dpi, dpi))
        return buf.getvalue()

    def __repr__(self) -> str:
        return f"Code({self.payload.hex}, {len(self.svg)} characters of SVG)"


__all__ = ["MAX_RASTER_SIDE", "MM_PER_INCH", "Code", "print_pixels"]
