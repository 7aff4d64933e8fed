"""A sheet of labelled codes (:mod:`deepmorph.sheet`): the payloads of a batch, the grid on the
page, the labels (as text in the SVG, as outlines in the PDF and PNG), the errors, and a code
cropped from the sheet's PNG decoded by the model to its payload."""

from __future__ import annotations

import io

import numpy as np
import pytest
from lxml import etree
from PIL import Image

import deepmorph
from deepmorph.sheet import MAX_CODES, batch_payloads, make_sheet, outlined, truncate
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphError

SVG = "{http://www.w3.org/2000/svg}"


@pytest.fixture(scope="module")
def model() -> deepmorph.Model:
    return deepmorph.load(BUNDLED_MODEL)


def test_a_batch_is_consecutive_payloads_or_a_list() -> None:
    run = batch_payloads(24, start="0x0000FE", count=3)
    assert [p.hex for p in run] == ["0x0000FE", "0x0000FF", "0x000100"]
    listed = batch_payloads(24, lines="0xA1B2C3\n\n  0x000001  \n")
    assert [p.hex for p in listed] == ["0xA1B2C3", "0x000001"]
    assert len(batch_payloads(24, start="0x000000", count=MAX_CODES)) == MAX_CODES
    # numbers, after 0d or where the user chose to type numbers
    assert batch_payloads(24, start="0d254", count=3) == run
    assert batch_payloads(24, start="254", count=3, form="number") == run
    assert [p.int for p in batch_payloads(24, lines="10\n0101\n", form="number")] == [10, 101]
    assert [p.int for p in batch_payloads(24, lines="00000A\n000101", form="hex")] == [10, 0x101]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"start": "0x000001", "count": 0}, "no payloads: a sheet holds 1 to 100 codes"),
        ({"start": "0x000001", "count": 101}, "101 payloads: a sheet holds at most 100 codes"),
        ({"lines": "\n".join(f"0x{i:06X}" for i in range(101))}, "a sheet holds at most 100"),
        ({"lines": "  \n"}, "no payloads"),
        ({"start": "0xFFFFFE", "count": 3}, "3 payloads from 0xFFFFFE pass the model's largest payload, 0xFFFFFF"),
        ({"start": "0x1000000", "count": 1}, "0x1000000"),
        ({"lines": "0x000001\n0x12"}, "line 2: "),
        ({"lines": "1\n16777216", "form": "number"}, "line 2: payload '16777216' is too large for 24 bits"),
        ({"start": "16777215", "count": 2, "form": "number"}, "2 payloads from 0xFFFFFF pass the model's largest"),
        ({"start": "0x000001", "count": 2, "lines": "0x000001"}, "not both"),
    ],
)
def test_a_bad_batch_is_one_clear_line(kwargs: dict, message: str) -> None:
    with pytest.raises(DeepMorphError, match=message) as info:
        batch_payloads(24, **kwargs)
    assert "\n" not in str(info.value)


def test_the_grid_fills_the_page_centred_and_labelled(model: deepmorph.Model) -> None:
    codes = [model.encode(p) for p in batch_payloads(24, start="0x5A3C96", count=7)]
    texts = [None] * 7
    texts[2] = "https://example.com/a-long-address-that-cannot-fit-under-one-code"
    texts[6] = "a note\x07 with\ta bell"
    sheet = make_sheet(codes, texts=texts, page="A4", code_mm=40, margin_mm=10, gap_mm=6)
    # 190 mm inside the margins: 4 columns of 40 mm with 6 mm gaps (178 mm), centred
    assert (sheet.width_mm, sheet.height_mm, sheet.columns, sheet.rows) == (210.0, 297.0, 4, 2)
    assert sheet.placed[0].x_mm == pytest.approx(16.0) and sheet.placed[0].y_mm == pytest.approx(10.0)
    assert sheet.placed[5].x_mm == pytest.approx(62.0) and sheet.placed[5].y_mm > 50.0
    assert sheet.placed[2].label[0] == "0x5A3C98"
    assert sheet.placed[2].label[1].endswith("…") and len(sheet.placed[2].label[1]) < len(texts[2])
    assert sheet.placed[3].label == ("0x5A3C99",)
    assert sheet.placed[6].label == ("0x5A3C9C", "a note with a bell")
    root = etree.fromstring(sheet.svg.encode())
    assert (root.get("width"), root.get("height"), root.get("viewBox")) == ("210mm", "297mm", "0 0 210 297")
    nested = root.findall(f"{SVG}svg")
    assert len(nested) == 7 and {(n.get("width"), n.get("height")) for n in nested} == {("40", "40")}
    assert [t.text for t in root.findall(f"{SVG}text")][:4] == ["0x5A3C96", "0x5A3C97", "0x5A3C98", texts[2][:24] + "…"]
    # the nested SVGs are the model's own codes
    assert etree.tostring(nested[4]).count(b"<path") == codes[4].svg.count("<path")
    # for PDF and PNG every label is drawn as outlines
    flat = etree.fromstring(outlined(sheet.svg).encode())
    assert not flat.findall(f".//{SVG}text") and len(flat.findall(f"{SVG}path")) == 9


def test_the_pdf_is_the_page_with_its_labels(model: deepmorph.Model) -> None:
    from deepmorph_core.pdf import page_size_points, render_pdf

    codes = [model.encode(p) for p in batch_payloads(24, start="0x000010", count=2)]
    sheet = make_sheet(codes, page="A5", code_mm=50)
    pdf = sheet.file("PDF")
    assert page_size_points(pdf) == pytest.approx((148 / 25.4 * 72, 210 / 25.4 * 72), abs=0.01)
    page = render_pdf(pdf, 592)  # 4 px a mm
    placed = sheet.placed[0]
    below = page[round(4 * (placed.y_mm + placed.height_mm)) : round(4 * (placed.y_mm + placed.height_mm + 5)),
                 round(4 * placed.x_mm) : round(4 * (placed.x_mm + placed.width_mm))]  # fmt: skip
    assert (below < 0.5).sum() > 40, "the payload's label is not drawn in the PDF"


def test_a_code_cropped_from_the_sheet_png_reads_back(model: deepmorph.Model) -> None:
    codes = [model.encode(p) for p in batch_payloads(24, start="0x5A3C96", count=12)]
    sheet = make_sheet(codes, code_mm=35)
    dpi = 200
    image = Image.open(io.BytesIO(sheet.png(dpi)))
    assert image.info["dpi"] == pytest.approx((dpi, dpi), abs=0.01)
    assert image.size[0] == round(210 / 25.4 * dpi)
    assert abs(image.size[1] - image.size[0] * 297 / 210) <= 1  # the page's aspect (resvg rounds up)
    pixels = np.asarray(image.convert("L"))
    mm = image.size[0] / 210  # pixels a millimetre
    for index in (5, 11):
        placed = sheet.placed[index]
        top, left = round((placed.y_mm - 3) * mm), round((placed.x_mm - 3) * mm)
        crop = pixels[top : top + round((placed.height_mm + 6) * mm), left : left + round((placed.width_mm + 6) * mm)]
        found = model.decode(crop)
        assert [(f.payload.hex, f.ok) for f in found] == [(codes[index].payload.hex, True)]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"code_mm": 300}, "a 300 mm code .* does not fit on A4 with 10 mm margins"),
        ({"code_mm": 20, "page": (30, 30)}, "does not fit on a 30 x 30 mm page"),
        ({"code_mm": 100}, "12 codes 100 mm wide do not fit on A4 with 10 mm margins \\(2 do\\)"),
        ({"page": "B7"}, "page 'B7': expected one of A3, A4, A5, Letter"),
        ({"code_mm": -5}, "positive number of millimetres"),
    ],
)
def test_a_sheet_that_cannot_be_made_says_why(model: deepmorph.Model, kwargs: dict, message: str) -> None:
    codes = [model.encode(p) for p in batch_payloads(24, start="0x000001", count=12)]
    with pytest.raises(DeepMorphError, match=message) as info:
        make_sheet(codes, **kwargs)
    assert "\n" not in str(info.value)


def test_truncate() -> None:
    assert truncate("short", 10) == "short"
    assert truncate("a longer text here", 10) == "a longer…"
