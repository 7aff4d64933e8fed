"""Vector PDFs of a drawing at a printed size, checked against the reference renderer.

Skia (``skia-python``, already the photo chain's second renderer) draws the SVG with its SVG
module onto a PDF canvas, so the PDF holds the drawing's paths, not pixels. Skia rounds a PDF
page to whole points, up to 0.18 mm off; PDFium (``pypdfium2``) then sets the page to the exact
size (``width_mm / 25.4 * 72`` points) and renders the finished file, and that render is
compared with resvg's render of the same SVG: a PDF is returned only when the two agree
(:data:`MAX_MEAN_DIFFERENCE`), so a printed PDF carries the code the decoder was trained on.
"""

from __future__ import annotations

import io
import math
from types import ModuleType

import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.render import render_svg, sized_svg
from deepmorph_core.svg.plain_colours import plain_colours

MM_PER_INCH = 25.4
POINTS_PER_INCH = 72.0

#: The largest side of a PDF page in points (200 inches, PDF's own limit).
MAX_PAGE_POINTS = 14_400.0

#: The PDF's render and resvg's may differ by this much on average (intensity in ``[0, 1]``) at
#: :data:`CHECK_WIDTH` pixels: anti-aliasing along the edges gives at most 0.003 over the
#: Feather icons (unmorphed and morphed); a document Skia draws differently gives far more (a
#: ``transform-origin`` it ignores: 0.26; a Feather icon's smallest element left out: 0.037 at
#: the median).
MAX_MEAN_DIFFERENCE = 0.01
CHECK_WIDTH = 256  # pixels across for the check


def points(width_mm: float) -> float:
    """A length in millimetres as PDF points (1/72 inch)."""
    return width_mm / MM_PER_INCH * POINTS_PER_INCH


def check_width_mm(width_mm: float) -> float:
    """``width_mm`` as a print width.

    Raises:
        DeepMorphError: not a finite number above 0.
    """
    if isinstance(width_mm, bool) or not isinstance(width_mm, (int, float)):
        raise DeepMorphError(f"a print width is a number of millimetres, not a {type(width_mm).__name__}")
    if not (math.isfinite(width_mm) and width_mm > 0):
        raise DeepMorphError(f"a print width must be a positive number of millimetres, got {width_mm:g}")
    return float(width_mm)


def svg_to_pdf(svg: str, viewbox: tuple[float, float, float, float], width_mm: float) -> bytes:
    """A one-page vector PDF of ``svg``, its page exactly ``width_mm`` wide (the height from the
    viewBox's aspect), the drawing filling it.

    Raises:
        DeepMorphError: a width that is not positive, a page larger than PDF allows
            (:data:`MAX_PAGE_POINTS`), Skia or PDFium not loadable, or a PDF whose render
            differs from resvg's (see the module).
    """
    width_mm = check_width_mm(width_mm)
    _, _, vw, vh = viewbox
    w_pt = points(width_mm)
    h_pt = w_pt * vh / vw
    if max(w_pt, h_pt) > MAX_PAGE_POINTS:
        raise DeepMorphError(
            f"a page {width_mm:g} mm wide is {w_pt:.0f} x {h_pt:.0f} points, more than PDF's "
            f"{MAX_PAGE_POINTS:.0f} a side; print the SVG"
        )
    skia, pdfium = _skia(), _pdfium()
    user_svg = sized_svg(plain_colours(svg), f"{vw:g}", f"{vh:g}")  # Skia's container: one unit per viewBox unit
    dom = skia.SVGDOM.MakeFromStream(skia.MemoryStream(user_svg.encode("utf-8"), True))
    if dom is None:
        raise DeepMorphError("the PDF renderer (Skia) refused the drawing")
    dom.setContainerSize(skia.Size(vw, vh))
    stream = skia.DynamicMemoryWStream()
    document = skia.PDF.MakeDocument(stream)
    page_w, page_h = math.ceil(w_pt), math.ceil(h_pt)  # Skia's page: whole points, at least the size
    canvas = document.beginPage(page_w, page_h)
    canvas.translate(0, page_h - h_pt)  # the drawing at the page's bottom left, where the exact box goes
    canvas.scale(w_pt / vw, w_pt / vw)
    dom.render(canvas)
    document.endPage()
    document.close()
    pdf = pdfium.PdfDocument(stream.detachAsData().bytes())
    try:
        page = pdf[0]
        page.set_mediabox(0, 0, w_pt, h_pt)
        page.set_cropbox(0, 0, w_pt, h_pt)
        buf = io.BytesIO()
        pdf.save(buf)
    finally:
        pdf.close()
    data = buf.getvalue()
    printed, reference = render_pdf(data, CHECK_WIDTH), render_svg(user_svg, CHECK_WIDTH)
    rows = min(printed.shape[0], reference.shape[0])  # the two may round the height apart by a pixel
    difference = float(np.abs(printed[:rows] - reference[:rows]).mean())
    if not difference <= MAX_MEAN_DIFFERENCE:
        raise DeepMorphError(
            f"the PDF draws this drawing differently from the reference renderer (mean difference "
            f"{difference:.3f} > {MAX_MEAN_DIFFERENCE}); print the SVG or a PNG instead"
        )
    return data


def render_pdf(data: bytes, width: int, page: int = 0) -> np.ndarray:
    """A page of a PDF rendered by PDFium on white, ``width`` pixels across.

    Returns:
        ``(H, width)`` float32 intensity in ``[0, 1]`` (1 = white), ``H`` from the page's aspect.

    Raises:
        DeepMorphError: not a PDF PDFium reads, or no such page.
    """
    pdfium = _pdfium()
    try:
        pdf = pdfium.PdfDocument(data)
    except pdfium.PdfiumError as exc:
        raise DeepMorphError(f"not a PDF PDFium can read: {exc}") from None
    try:
        if not 0 <= page < len(pdf):
            raise DeepMorphError(f"the PDF has {len(pdf)} pages; no page {page + 1}")
        sheet = pdf[page]
        bitmap = sheet.render(scale=width / sheet.get_width(), fill_color=(255, 255, 255, 255))
        # luminance with BT.601's weights, as render_svg makes it
        gray = np.asarray(bitmap.to_pil().convert("RGB").convert("L"), dtype=np.float32) / 255.0
    finally:
        pdf.close()
    return gray[:, :width]  # PDFium rounds a fractional size up


def page_size_points(data: bytes, page: int = 0) -> tuple[float, float]:
    """``(width, height)`` of a PDF page in points, as PDFium reads it."""
    pdfium = _pdfium()
    pdf = pdfium.PdfDocument(data)
    try:
        w, h = pdf[page].get_size()
    finally:
        pdf.close()
    return float(w), float(h)


def _skia() -> ModuleType:
    try:
        import skia
    except (ImportError, OSError) as exc:  # the wheel loads the system's libGL and libEGL
        raise DeepMorphError(f"PDF output needs skia-python, which cannot be loaded here ({exc})") from None
    return skia


def _pdfium() -> ModuleType:
    try:
        import pypdfium2
    except ImportError as exc:
        raise DeepMorphError(f"PDF output needs pypdfium2, which cannot be loaded here ({exc})") from None
    return pypdfium2


__all__ = [
    "CHECK_WIDTH",
    "MAX_MEAN_DIFFERENCE",
    "MAX_PAGE_POINTS",
    "MM_PER_INCH",
    "check_width_mm",
    "page_size_points",
    "points",
    "render_pdf",
    "svg_to_pdf",
]
