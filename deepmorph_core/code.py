"""A code: a payload hidden in a drawing, as the morphed SVG and as files made for print.

:meth:`DeepMorphModel.code <deepmorph_core.model.DeepMorphModel.code>` makes one. Its SVG is
the drawing with the payload's morph written in. For print, :meth:`Code.svg_at` gives that SVG
with its size in millimetres, :meth:`Code.pdf` a vector PDF page of that size
(:mod:`deepmorph_core.pdf`), and :meth:`Code.png` a render by the real renderer at a printed
size and resolution, the resolution recorded in the file so that printing it gives that size.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from PIL import Image

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write
from deepmorph_core.payload import Payload
from deepmorph_core.pdf import MM_PER_INCH, check_width_mm, svg_to_pdf
from deepmorph_core.render import raster_size, render_svg, render_svg_rgb, sized_svg

MAX_RASTER_SIDE = 16_384  # pixels: a larger print is what the SVG (or a PDF) is for

FileFormat = Literal["SVG", "PDF", "PNG"]

#: The files a code is written as, by the file name's extension.
FILE_FORMATS: dict[str, FileFormat] = {".svg": "SVG", ".pdf": "PDF", ".png": "PNG"}


def file_format(path: str | Path) -> FileFormat:
    """``"SVG"``, ``"PDF"`` or ``"PNG"``: what a code is written as at ``path``.

    Raises:
        DeepMorphError: another extension.
    """
    fmt = FILE_FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise DeepMorphError(f"{path}: a code is written as .svg, .pdf or .png; name it so")
    return fmt


def print_pixels(width_mm: float, dpi: int) -> int:
    """Pixels across a print ``width_mm`` wide at ``dpi`` dots per inch.

    Raises:
        DeepMorphError: a size or resolution that is not positive, or a raster wider than
            :data:`MAX_RASTER_SIDE` pixels.
    """
    check_width_mm(width_mm)
    if not dpi > 0:
        raise DeepMorphError(f"a print needs a positive resolution, got {dpi} dpi")
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

    def height_mm(self, width_mm: float) -> float:
        """The printed height of the code ``width_mm`` wide (the viewBox's aspect)."""
        return check_width_mm(width_mm) * self.viewbox[3] / self.viewbox[2]

    def svg_at(self, width_mm: float) -> str:
        """The SVG with its ``width`` and ``height`` in millimetres, ``width_mm`` wide (viewBox
        and content unchanged): what a browser, an editor or a print dialog sizes it by.

        Raises:
            DeepMorphError: a width that is not a positive number.
        """
        width_mm = check_width_mm(width_mm)
        return sized_svg(self.svg, f"{width_mm:g}mm", f"{self.height_mm(width_mm):g}mm")

    def pdf(self, width_mm: float = 50.0) -> bytes:
        """A one-page vector PDF, the page exactly ``width_mm`` wide (``width_mm / 25.4 * 72``
        points) and the drawing filling it.

        Raises:
            DeepMorphError: a width that is not positive or makes a page larger than PDF allows,
                or a PDF that would not draw as the reference renderer does
                (:func:`~deepmorph_core.pdf.svg_to_pdf`).
        """
        return svg_to_pdf(self.svg, self.viewbox, width_mm)

    def png(self, width_mm: float = 50.0, dpi: int = 300) -> bytes:
        """A PNG of the code ``width_mm`` wide at ``dpi`` dots per inch (recorded in the file), in
        the drawing's colours (gray when every pixel is)."""
        px = print_pixels(width_mm, dpi)
        raster_size(self.viewbox, px)  # refused before rendering when too large
        rgb = render_svg_rgb(self.svg, px)
        pixels = np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8)
        image = Image.fromarray(pixels, "RGB")
        if (pixels[..., 0] == pixels[..., 1]).all() and (pixels[..., 1] == pixels[..., 2]).all():
            image = image.convert("L")  # a black-and-white drawing stays a gray PNG
        buf = io.BytesIO()
        image.save(buf, format="PNG", dpi=(dpi, dpi))
        return buf.getvalue()

    def file(self, fmt: FileFormat, width_mm: float = 50.0, dpi: int = 300) -> bytes:
        """The code as a file for print, ``width_mm`` wide: ``fmt`` is ``"SVG"``
        (:meth:`svg_at`), ``"PDF"`` (:meth:`pdf`) or ``"PNG"`` (:meth:`png`, at ``dpi``)."""
        if fmt == "SVG":
            return self.svg_at(width_mm).encode("utf-8")
        if fmt == "PDF":
            return self.pdf(width_mm)
        if fmt == "PNG":
            return self.png(width_mm, dpi)
        raise DeepMorphError(f"a code is written as SVG, PDF or PNG, not {fmt!r}")

    def save(self, path: str | Path, width_mm: float = 50.0, dpi: int = 300) -> Path:
        """Write the code to ``path`` as its extension says (``.svg``, ``.pdf`` or ``.png``),
        ``width_mm`` wide, whole or not at all.

        Returns:
            ``path`` as a :class:`~pathlib.Path`.

        Raises:
            DeepMorphError: another extension, a size out of range, or a file that cannot be
                written.
        """
        path = Path(path)
        atomic_write(path, self.file(file_format(path), width_mm, dpi))
        return path

    def __repr__(self) -> str:
        return f"Code({self.payload.hex}, {len(self.svg)} characters of SVG)"


__all__ = ["FILE_FORMATS", "MAX_RASTER_SIDE", "MM_PER_INCH", "Code", "FileFormat", "file_format", "print_pixels"]
