"""A sheet of codes: up to :data:`MAX_CODES` payloads of one model laid out in a grid on one
page, each labelled under it with its payload in hex (and a text, such as its registry entry),
as one SVG the page's size in millimetres, and as a PDF or a PNG made by the same code that
writes one code (:func:`~deepmorph_core.pdf.svg_to_pdf`, resvg).

Each code is the model's own SVG placed as a nested ``<svg>`` at its size in millimetres, so
what is printed is what the decoder was trained on. The labels are plain ``<text>`` in the SVG;
for the PDF and the PNG they are first turned into outlines (Skia's glyphs of
:data:`LABEL_FONT`), because the PDF writer's SVG module draws no text and the PDF is only
returned when it draws as resvg does::

    import deepmorph
    from deepmorph.sheet import batch_payloads, make_sheet

    model = deepmorph.load("ghost.dmm")
    payloads = batch_payloads(model.payload_bits, start="0x000100", count=24)
    sheet = make_sheet([model.encode(p) for p in payloads], code_mm=40)
    sheet.save("sheet.pdf")
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from lxml import etree

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.payload import Payload, PayloadLike, TextForm

if TYPE_CHECKING:
    from deepmorph_core.code import Code, FileFormat

SVG_NS = "http://www.w3.org/2000/svg"
#: The most codes one sheet holds.
MAX_CODES = 100
#: Page sizes by name, ``(width, height)`` in millimetres (portrait).
PAGES: dict[str, tuple[float, float]] = {
    "A3": (297.0, 420.0),
    "A4": (210.0, 297.0),
    "A5": (148.0, 210.0),
    "Letter": (215.9, 279.4),
}
#: The labels' font, as the SVG names it and as its outlines are drawn for PDF and PNG.
LABEL_FONT = "DejaVu Sans"
LABEL_FONT_MM = 3.2  # the payload's line under a code 29 mm wide or more; smaller under smaller codes
TEXT_SCALE = 0.8  # the registry text's line, relative to the payload's
LINE = 1.3  # line height, in font sizes
CHAR_WIDTH = 0.62  # an upper bound of a DejaVu Sans character's advance, in font sizes (digits: 0.64 for '0x')


@dataclass(frozen=True)
class Placed:
    """One code on a sheet.

    Attributes:
        payload: its payload in hex.
        x_mm, y_mm: its top-left corner on the page.
        width_mm, height_mm: its printed size.
        label: the lines under it (the payload, then the text if any, truncated to fit).
    """

    payload: str
    x_mm: float
    y_mm: float
    width_mm: float
    height_mm: float
    label: tuple[str, ...]


@dataclass(frozen=True)
class Sheet:
    """A page of labelled codes.

    Attributes:
        svg: the page as an SVG document, ``width`` and ``height`` in mm, its viewBox in mm.
        width_mm, height_mm: the page's size.
        placed: the codes, in the order given, row by row.
        columns, rows: the grid (``rows`` holds every code; the page may have room for more).
    """

    svg: str
    width_mm: float
    height_mm: float
    placed: tuple[Placed, ...]
    columns: int
    rows: int

    def pdf(self) -> bytes:
        """A one-page vector PDF the page's size (labels as outlines).

        Raises:
            DeepMorphError: the PDF writer cannot be loaded, or draws the page differently
                from resvg (:func:`~deepmorph_core.pdf.svg_to_pdf`).
        """
        from deepmorph_core.pdf import svg_to_pdf

        return svg_to_pdf(outlined(self.svg), (0.0, 0.0, self.width_mm, self.height_mm), self.width_mm)

    def png(self, dpi: int = 300) -> bytes:
        """The page rendered by resvg at ``dpi`` dots per inch (recorded in the file; labels as
        outlines), in the codes' colours (gray when every pixel is).

        Raises:
            DeepMorphError: a resolution that is not positive, or a raster larger than
                DeepMorph makes (:func:`~deepmorph_core.code.print_pixels`).
        """
        import numpy as np
        from PIL import Image

        from deepmorph_core.code import print_pixels
        from deepmorph_core.render import raster_size, render_svg_rgb

        px = print_pixels(self.width_mm, dpi)
        raster_size((0.0, 0.0, self.width_mm, self.height_mm), px)  # refused before rendering when too large
        pixels = np.clip(np.rint(render_svg_rgb(outlined(self.svg), px) * 255), 0, 255).astype(np.uint8)
        image = Image.fromarray(pixels, "RGB")
        if (pixels[..., 0] == pixels[..., 1]).all() and (pixels[..., 1] == pixels[..., 2]).all():
            image = image.convert("L")
        buf = io.BytesIO()
        image.save(buf, format="PNG", dpi=(dpi, dpi))
        return buf.getvalue()

    def file(self, fmt: FileFormat, dpi: int = 300) -> bytes:
        """The sheet as ``"SVG"`` (labels as ``<text>``), ``"PDF"`` or ``"PNG"`` (at ``dpi``)."""
        if fmt == "SVG":
            return self.svg.encode("utf-8")
        if fmt == "PDF":
            return self.pdf()
        if fmt == "PNG":
            return self.png(dpi)
        raise DeepMorphError(f"a sheet is written as SVG, PDF or PNG, not {fmt!r}")

    def save(self, path: str | Path, dpi: int = 300) -> Path:
        """Write the sheet to ``path`` as its extension says (``.svg``, ``.pdf`` or ``.png``)."""
        from deepmorph_core.code import file_format
        from deepmorph_core.fileio import atomic_write

        path = Path(path)
        atomic_write(path, self.file(file_format(path), dpi))
        return path


def batch_payloads(
    payload_bits: int,
    *,
    start: PayloadLike | None = None,
    count: int | None = None,
    lines: str | None = None,
    form: TextForm | None = None,
) -> list[Payload]:
    """The payloads of a sheet: ``count`` consecutive ones from ``start``, or one per non-empty
    line of ``lines``. Text is read as ``deepmorph encode`` reads it (``0x`` hex, ``0d`` a
    number, or bits), or as ``form`` says (``"hex"``, ``"number"``: what the Print tab's user
    chose to type; :func:`~deepmorph_core.payload.parse_payload_text`).

    Raises:
        DeepMorphError: both or neither way given, no payload, more than :data:`MAX_CODES`, a
            line that is not a payload of ``payload_bits`` bits (saying which), or a run that
            passes the model's largest payload.
    """
    if (lines is None) == (start is None):
        raise DeepMorphError("give a first payload and a count, or a list of payloads, not both")
    if lines is not None:
        rows = [(i, line.strip()) for i, line in enumerate(lines.splitlines(), 1) if line.strip()]
        _check_count(len(rows))
        out = []
        for number, text in rows:
            try:
                out.append(Payload.parse(text, payload_bits, form))
            except DeepMorphError as exc:
                raise DeepMorphError(f"line {number}: {exc}") from None
        return out
    n = _check_count(count if count is not None else 0)
    first = Payload.parse(start, payload_bits, form) if isinstance(start, str) else Payload.of(start, payload_bits)
    last = first.int + n - 1
    if last >= 2**payload_bits:
        largest = Payload.of(2**payload_bits - 1, payload_bits)
        raise DeepMorphError(
            f"{n} payloads from {first.hex} pass the model's largest payload, {largest.hex} "
            f"({payload_bits} bits): start lower or ask for fewer"
        )
    return [Payload.of(first.int + i, payload_bits) for i in range(n)]


def _check_count(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise DeepMorphError(f"no payloads: a sheet holds 1 to {MAX_CODES} codes (got {n})")
    if n > MAX_CODES:
        raise DeepMorphError(f"{n} payloads: a sheet holds at most {MAX_CODES} codes")
    return n


def page_size(page: str | tuple[float, float]) -> tuple[float, float]:
    """``(width, height)`` in mm of a page named in :data:`PAGES` (any case), or given as a pair."""
    if isinstance(page, str):
        for name, size in PAGES.items():
            if name.lower() == page.strip().lower():
                return size
        raise DeepMorphError(f"page {page!r}: expected one of {', '.join(PAGES)}, or a width and height in mm")
    width, height = (float(v) for v in page)
    if not (math.isfinite(width) and math.isfinite(height) and width > 0 and height > 0):
        raise DeepMorphError(f"a page's size must be positive millimetres, got {width:g} x {height:g}")
    return width, height


def make_sheet(
    codes: Sequence[Code],
    *,
    texts: Sequence[str | None] | None = None,
    page: str | tuple[float, float] = "A4",
    code_mm: float = 40.0,
    margin_mm: float = 10.0,
    gap_mm: float = 6.0,
) -> Sheet:
    """``codes`` in a grid on one page, each ``code_mm`` wide, labelled with its payload in hex
    and its entry of ``texts`` (``None``: the payload only), the grid centred between the
    margins.

    Args:
        codes: 1 to :data:`MAX_CODES` codes (of one model, usually).
        texts: one text or ``None`` per code, shown under its payload and truncated to the
            code's width.
        page: a name of :data:`PAGES` or ``(width, height)`` in mm.
        code_mm: each code's printed width (its height follows its viewBox).
        margin_mm: the empty border of the page.
        gap_mm: the space between neighbouring cells.

    Raises:
        DeepMorphError: no code or too many, sizes that are not positive, a page too small for
            one code, or more codes than the page holds at that size (saying how many fit).
    """
    from deepmorph_core.pdf import check_width_mm

    _check_count(len(codes))
    if texts is not None and len(texts) != len(codes):
        raise DeepMorphError(f"{len(texts)} texts for {len(codes)} codes")
    width, height = page_size(page)
    code_mm = check_width_mm(code_mm)
    if not (margin_mm >= 0 and gap_mm >= 0):
        raise DeepMorphError(f"margins and gaps are 0 mm or more, got {margin_mm:g} and {gap_mm:g}")
    code_h = max(c.height_mm(code_mm) for c in codes)
    longest = max(len(c.payload.hex) for c in codes)
    font = min(LABEL_FONT_MM, code_mm / 9, code_mm / (CHAR_WIDTH * longest))
    with_text = texts is not None and any(texts)
    label_h = font * 0.5 + font * LINE + (font * TEXT_SCALE * LINE if with_text else 0.0)
    cell_h = code_h + label_h
    free_w, free_h = width - 2 * margin_mm, height - 2 * margin_mm
    name = next((n for n, size in PAGES.items() if size == (width, height)), f"a {width:g} x {height:g} mm page")
    if free_w < code_mm or free_h < cell_h:
        raise DeepMorphError(
            f"a {code_mm:g} mm code ({cell_h:.0f} mm tall with its label) does not fit on {name} with "
            f"{margin_mm:g} mm margins ({max(free_w, 0):g} x {max(free_h, 0):g} mm inside): make the code smaller"
        )
    columns = int((free_w + gap_mm) // (code_mm + gap_mm))
    fits = columns * int((free_h + gap_mm) // (cell_h + gap_mm))
    if len(codes) > fits:
        raise DeepMorphError(
            f"{len(codes)} codes {code_mm:g} mm wide do not fit on {name} with {margin_mm:g} mm margins "
            f"({fits} do): make the codes smaller or the batch shorter"
        )
    columns = min(columns, len(codes))
    rows = math.ceil(len(codes) / columns)
    left = margin_mm + (free_w - (columns * code_mm + (columns - 1) * gap_mm)) / 2
    top = margin_mm

    root = etree.Element(f"{{{SVG_NS}}}svg", nsmap={None: SVG_NS})
    root.set("width", f"{width:g}mm")
    root.set("height", f"{height:g}mm")
    root.set("viewBox", f"0 0 {width:g} {height:g}")
    placed = []
    for i, code in enumerate(codes):
        x = left + (i % columns) * (code_mm + gap_mm)
        y = top + (i // columns) * (cell_h + gap_mm)
        h = code.height_mm(code_mm)
        nested = etree.fromstring(code.svg.encode("utf-8"))  # the model's own SVG, as DeepMorph wrote it
        for key, value in (("x", x), ("y", y), ("width", code_mm), ("height", h)):
            nested.set(key, f"{value:g}" if key in ("width", "height") else f"{value:.3f}")
        root.append(nested)
        label = [code.payload.hex]
        text = texts[i] if texts is not None else None
        if text:
            shown = "".join(c for c in " ".join(text.split()) if c.isprintable())  # XML takes no control characters
            label.append(truncate(shown, max(4, int(code_mm / (CHAR_WIDTH * font * TEXT_SCALE)))))
        baseline = y + code_h + font * 0.5 + font
        for line_no, line in enumerate(label):
            size = font if line_no == 0 else font * TEXT_SCALE
            element = etree.SubElement(root, f"{{{SVG_NS}}}text")
            for key, value in (
                ("x", f"{x + code_mm / 2:.3f}"),
                ("y", f"{baseline:.3f}"),
                ("font-family", f"{LABEL_FONT}, sans-serif"),
                ("font-size", f"{size:.3g}"),
                ("text-anchor", "middle"),
                ("fill", "#000"),
            ):
                element.set(key, value)
            element.text = line
            baseline += font * TEXT_SCALE * LINE
        placed.append(Placed(code.payload.hex, x, y, code_mm, h, tuple(label)))
    svg = etree.tostring(root, encoding="unicode")
    return Sheet(svg, width, height, tuple(placed), columns, rows)


def truncate(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters, an ellipsis last when cut."""
    return text if len(text) <= limit else text[: limit - 1].rstrip() + "…"


def outlined(svg: str) -> str:
    """``svg`` with each ``<text>`` (the sheet's labels: ``x``, ``y``, ``font-size``,
    ``text-anchor="middle"``) replaced by a ``<path>`` of :data:`LABEL_FONT`'s glyphs, so that
    Skia's PDF and resvg draw the same label.

    Raises:
        DeepMorphError: Skia cannot be loaded.
    """
    try:
        import skia
    except (ImportError, OSError) as exc:  # the wheel loads the system's libGL and libEGL
        raise DeepMorphError(f"a PDF or PNG sheet needs skia-python, which cannot be loaded here ({exc})") from None
    root = etree.fromstring(svg.encode("utf-8"))
    size = 100.0  # glyph outlines at 100 units, scaled to the label's size: no hinting at small sizes
    font = skia.Font(skia.Typeface(LABEL_FONT), size)
    for element in list(root.iter(f"{{{SVG_NS}}}text")):
        text = element.text or ""
        glyphs = font.textToGlyphs(text)
        xs = font.getXPos(glyphs)
        advance = font.measureText(text)
        scale = float(element.get("font-size", "1")) / size
        data = []
        for glyph, x0 in zip(glyphs, xs):
            data.append(_path_data(skia, font.getPath(glyph), x0))
        path = etree.Element(f"{{{SVG_NS}}}path")
        x = float(element.get("x", "0")) - advance * scale / 2
        path.set("transform", f"translate({x:.3f} {float(element.get('y', '0')):.3f}) scale({scale:.5g})")
        path.set("d", " ".join(d for d in data if d))
        path.set("fill", element.get("fill", "#000"))
        element.getparent().replace(element, path)
    return etree.tostring(root, encoding="unicode")


def _path_data(skia: object, path: object, dx: float) -> str:
    """A Skia path as SVG path data, moved ``dx`` along x."""
    if path is None:
        return ""
    verbs = skia.Path.Verb  # type: ignore[attr-defined]
    it = skia.Path.Iter(path, False)  # type: ignore[attr-defined]
    out = []

    def pt(p: object) -> str:
        return f"{p.fX + dx:.2f} {p.fY:.2f}"  # type: ignore[attr-defined]

    while True:
        verb, points = it.next()
        if verb == verbs.kDone_Verb:
            break
        if verb == verbs.kMove_Verb:
            out.append(f"M{pt(points[0])}")
        elif verb == verbs.kLine_Verb:
            out.append(f"L{pt(points[1])}")
        elif verb == verbs.kQuad_Verb:
            out.append(f"Q{pt(points[1])} {pt(points[2])}")
        elif verb == verbs.kConic_Verb:  # none in TrueType glyphs; as quadratics if a font has them
            quads = skia.Path.ConvertConicToQuads(points[0], points[1], points[2], it.conicWeight(), 2)  # type: ignore[attr-defined]
            out.extend(f"Q{pt(quads[k])} {pt(quads[k + 1])}" for k in range(1, len(quads) - 1, 2))
        elif verb == verbs.kCubic_Verb:
            out.append(f"C{pt(points[1])} {pt(points[2])} {pt(points[3])}")
        elif verb == verbs.kClose_Verb:
            out.append("Z")
    return "".join(out)


__all__ = [
    "MAX_CODES",
    "PAGES",
    "Placed",
    "Sheet",
    "batch_payloads",
    "make_sheet",
    "outlined",
    "page_size",
    "truncate",
]
