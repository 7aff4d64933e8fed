"""Codes at a printed size: the SVG in millimetres, the vector PDF (its page, its drawing against
resvg, its refusals) and ``deepmorph encode``'s files, written all or none."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pypdfium2
import pytest
from lxml import etree
from PIL import Image
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.code import Code
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import Payload
from deepmorph_core.pdf import MAX_MEAN_DIFFERENCE, page_size_points, render_pdf
from deepmorph_core.render import render_svg

runner = CliRunner()
app = application()

# a drawing twice as wide as it is tall, with a viewBox that does not start at 0
WIDE = """<svg xmlns="http://www.w3.org/2000/svg" viewBox="-10 5 48 24" width="48" height="24"
  fill="none" stroke="#000" stroke-width="2" stroke-linecap="round">
  <rect x="-8" y="7" width="44" height="20" rx="3"/><circle cx="14" cy="17" r="6" fill="#000"/>
  <path d="M-4 11 L4 23 A 6 6 0 0 1 10 11"/></svg>"""


@pytest.fixture(scope="module")
def ghost_code() -> Code:
    return DeepMorphModel.load(BUNDLED_MODEL).code(0xA1B2C3)


@pytest.fixture
def wide_code() -> Code:
    return Code(Payload(np.zeros(4, np.uint8)), WIDE, (-10.0, 5.0, 48.0, 24.0))


def points(mm: float) -> float:
    return mm / 25.4 * 72


def test_svg_at_sets_millimetres_and_keeps_the_drawing(ghost_code: Code, wide_code: Code) -> None:
    for code, width_mm, height_mm in ((ghost_code, 50, "50mm"), (wide_code, 37.5, "18.75mm")):
        sized = code.svg_at(width_mm)
        root, base = etree.fromstring(sized.encode()), etree.fromstring(code.svg.encode())
        assert (root.get("width"), root.get("height")) == (f"{width_mm:g}mm", height_mm)
        assert root.get("viewBox") == base.get("viewBox")
        assert [etree.tostring(c) for c in root] == [etree.tostring(c) for c in base]
        # the same drawing: resvg renders both alike at the same pixel width
        assert np.abs(render_svg(sized, 200) - render_svg(code.svg, 200)).mean() < 1e-3


@pytest.mark.parametrize("width_mm", [0, -5, math.nan, math.inf, "50", None, True])
def test_a_print_width_must_be_a_positive_number(ghost_code: Code, width_mm: object) -> None:
    for make in (ghost_code.svg_at, ghost_code.pdf, ghost_code.png):
        with pytest.raises(DeepMorphError, match="print width"):
            make(width_mm)  # type: ignore[arg-type]


def test_pdf_page_is_the_print_size_and_draws_as_resvg(ghost_code: Code, wide_code: Code) -> None:
    for code, width_mm in ((ghost_code, 50.0), (ghost_code, 23.7), (wide_code, 80.0)):
        data = code.pdf(width_mm)
        assert data.startswith(b"%PDF-")
        pdf = pypdfium2.PdfDocument(data)
        assert len(pdf) == 1
        w, h = pdf[0].get_size()
        assert w == pytest.approx(points(width_mm), abs=1e-3)
        assert h == pytest.approx(points(width_mm) * code.viewbox[3] / code.viewbox[2], abs=1e-3)
        assert page_size_points(data) == (w, h)
        pdf.close()
        assert b"/XObject" not in data and b"/Subtype/Image" not in data  # vector: paths, no raster
        for px in (96, 300):
            printed, reference = render_pdf(data, px), render_svg(code.svg, px)
            rows = min(len(printed), len(reference))
            assert np.abs(printed[:rows] - reference[:rows]).mean() < MAX_MEAN_DIFFERENCE


def test_pdf_is_refused_when_it_would_not_draw_as_resvg() -> None:
    # transform-origin: resvg turns the square about its centre, Skia about the origin
    svg = (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 24 24" width="24" height="24">'
        '<rect x="4" y="4" width="10" height="10" transform="rotate(45)" transform-origin="12 12"/></svg>'
    )
    code = Code(Payload(np.zeros(4, np.uint8)), svg, (0.0, 0.0, 24.0, 24.0))
    with pytest.raises(DeepMorphError, match="draws this drawing differently from the reference renderer"):
        code.pdf(40)


def test_save_writes_the_format_its_extension_names(ghost_code: Code, tmp_path: Path) -> None:
    assert ghost_code.save(tmp_path / "c.PDF", width_mm=30).read_bytes().startswith(b"%PDF-")
    assert 'width="30mm"' in ghost_code.save(tmp_path / "c.svg", 30).read_text()
    with Image.open(ghost_code.save(tmp_path / "c.png", width_mm=30, dpi=200)) as img:
        assert img.width == round(30 / 25.4 * 200)
    with pytest.raises(DeepMorphError, match="written as .svg, .pdf or .png"):
        ghost_code.save(tmp_path / "c.txt")
    assert not (tmp_path / "c.txt").exists()


def run(*args: object):
    return runner.invoke(app, [str(a) for a in args])


def test_encode_writes_every_format_at_the_print_size(tmp_path: Path) -> None:
    svg, pdf, png = tmp_path / "code.svg", tmp_path / "code.pdf", tmp_path / "code.png"
    res = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", svg, "--pdf", pdf, "--png", png,
              "--width-mm", "40", "--dpi", "150")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "40 x 40 mm" in res.stdout
    assert re.search(r'width="40mm" height="40mm"', svg.read_text())
    assert page_size_points(pdf.read_bytes()) == pytest.approx((points(40), points(40)), abs=1e-3)
    with Image.open(png) as img:
        assert img.width == round(40 / 25.4 * 150)
    # --out's extension chooses: a .pdf is a PDF, never SVG text
    only = tmp_path / "only.pdf"
    res = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", only, "--width-mm", "25")
    assert res.exit_code == 0, res.output
    assert only.read_bytes().startswith(b"%PDF-") and b"<svg" not in only.read_bytes()
    assert page_size_points(only.read_bytes())[0] == pytest.approx(points(25), abs=1e-3)


def test_encode_writes_all_or_none(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    svg, pdf, png = tmp_path / "code.svg", tmp_path / "code.pdf", tmp_path / "code.png"
    svg.write_text("old")

    def refuse(self: Code, width_mm: float = 50.0) -> bytes:
        raise DeepMorphError("the PDF draws this drawing differently from the reference renderer")

    monkeypatch.setattr(Code, "pdf", refuse)
    res = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", svg, "--png", png, "--pdf", pdf)
    assert res.exit_code == 1 and res.stderr.startswith("error: ") and "Traceback" not in res.output
    assert svg.read_text() == "old" and not png.exists() and not pdf.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["code.svg"]
