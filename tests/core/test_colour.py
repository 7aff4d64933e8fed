"""Colour artwork: CSS colours, opacities and paint order, stylesheets, gradients, the soft
rasterizer's compositing against resvg, colour prints read back, and bad colour input."""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from lxml import etree
from PIL import Image

import deepmorph
from deepmorph.training.codec import train_model
from deepmorph_core.drawing import load_drawing
from deepmorph_core.errors import SvgError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.render import render_svg, render_svg_rgb
from deepmorph_core.svg.plain_colours import plain_colours
from deepmorph_core.svg.style import Paint
from deepmorph_primitives import path as path_primitive
from tests.conftest import make_svg

DATA = Path(__file__).resolve().parents[1] / "data"  # the colour icons are MIT (LICENSE beside them)


def rgb_mad(md: MorphableDrawing, width: int = 96) -> float:
    """Mean absolute difference per channel between the soft and resvg renders, unmorphed."""
    values = md.neutral_values()
    with torch.no_grad():
        soft = md.rasterizer(width).render_rgb(values)[0].permute(1, 2, 0).numpy()
    return float(np.abs(soft - render_svg_rgb(md.to_svg(values[0]), width)).mean())


@pytest.mark.parametrize(
    "text, rgb, alpha",
    [
        ("#FFDC5D", (255, 220, 93), 1.0),
        ("#f80", (255, 136, 0), 1.0),
        ("#f808", (255, 136, 0), 0x88 / 255),
        ("#12345678", (0x12, 0x34, 0x56), 0x78 / 255),
        ("rgb(10, 20, 30)", (10, 20, 30), 1.0),
        ("rgba(10, 20, 30, 0.5)", (10, 20, 30), 0.5),
        ("rgb(10 20 30 / 25%)", (10, 20, 30), 0.25),
        ("hsl(120, 100%, 25%)", (0, 128, 0), 1.0),
        ("hsla(0, 100%, 50%, 0.5)", (255, 0, 0), 0.5),
        ("rebeccapurple", (102, 51, 153), 1.0),
        ("Teal", (0, 128, 128), 1.0),
    ],
)
def test_every_css_colour_syntax_reads_and_is_written_back_as_drawn(text: str, rgb: tuple, alpha: float) -> None:
    md = MorphableDrawing.load(make_svg(f'<rect x="2" y="2" width="20" height="20" fill="{text}" dm:move="1"/>'))
    ((mode, paint),) = md.drawing.primitives[0].style.paints
    assert mode == "fill"
    assert tuple(round(c * 255) for c in paint.rgb) == rgb and paint.alpha == pytest.approx(alpha, abs=1e-6)
    written = etree.fromstring(md.to_svg(md.values_from_unit(md.random_unit(1, seed=2))[0]).encode())
    assert written.find("{http://www.w3.org/2000/svg}rect").get("fill") == text  # byte for byte
    # and what a renderer is given paints the same colour the drawing was read as
    pixel = render_svg_rgb(md.to_svg(md.neutral_values()[0]), 24)[12, 12] * 255
    expected = np.array(rgb) * alpha + 255 * (1 - alpha)
    np.testing.assert_allclose(pixel, expected, atol=2.0)


def test_current_colour_opacity_inheritance_and_paint_order() -> None:
    body = """<g color="#0000ff" fill="currentColor" opacity="0.5" stroke-width="2">
      <rect x="2" y="2" width="8" height="8" fill-opacity="0.5"/>
      <circle cx="16" cy="16" r="4" stroke="red" stroke-opacity="80%" paint-order="stroke"/>
    </g>"""
    drawing = load_drawing(make_svg(body))
    rect, circle = drawing.primitives
    assert rect.style.paints == [("fill", Paint((0.0, 0.0, 1.0), 0.25))]
    (first, under), (second, over) = circle.style.paints
    assert (first, second) == ("stroke", "fill")  # paint-order: the stroke under the fill
    assert under.rgb == (1.0, 0.0, 0.0) and under.alpha == pytest.approx(0.4)
    assert over.alpha == pytest.approx(0.5)
    assert not drawing.black_and_white and [p.describe() for p in drawing.palette] == [
        "#0000ff40",
        "#ff000066",
        "#0000ff80",
    ]


STYLED = """<style>
  path { fill: #aaaaaa }
  .sky, .sea { fill: #2196F3 }
  g.warm > .sun { fill: rgb(255, 193, 7); stroke: #cc3000; stroke-width: 1.5 }
  #moon { fill: #eeeeee !important }
  .thin { stroke-width: 0.5 }
</style>
<rect class="sky" x="1" y="1" width="22" height="11"/>
<rect class="sea" x="1" y="12" width="22" height="11" fill="black"/>
<g class="warm"><circle class="sun" cx="8" cy="8" r="4"/><circle class="sun thin" cx="16" cy="16" r="3"/></g>
<circle class="sun" cx="16" cy="8" r="2"/>
<circle id="moon" cx="5" cy="18" r="2" style="fill: black"/>
<path d="M12 14 L20 20 L12 20 Z" style="fill: #00ff00"/>
<path d="M2 2 L6 2 L2 6 Z"/>"""


def test_stylesheets_resolve_as_a_browser_does_and_are_written_inline() -> None:
    original = make_svg(STYLED)
    md = MorphableDrawing.load(original)
    paints = [[(m, p.describe()) for m, p in prim.style.paints] for prim in md.drawing.primitives]
    assert paints == [
        [("fill", "#2196f3")],  # class
        [("fill", "#2196f3")],  # a rule beats the presentation attribute
        [("fill", "#ffc107"), ("stroke", "#cc3000")],  # g.warm > .sun
        [("fill", "#ffc107"), ("stroke", "#cc3000")],
        [("fill", "black")],  # .sun outside g.warm: no rule, the initial black fill
        [("fill", "#eeeeee")],  # !important beats style=""
        [("fill", "#00ff00")],  # style="" beats the type rule
        [("fill", "#aaaaaa")],  # type selector
    ]
    assert md.drawing.primitives[3].style.stroke_width == 1.5  # the more specific rule beats the later .thin
    written = md.to_svg(md.neutral_values()[0])
    assert "<style" not in written and "class=" not in written
    # resvg reads the original stylesheet itself: the inlined document draws the same picture
    np.testing.assert_allclose(render_svg_rgb(written, 96), render_svg_rgb(original.decode(), 96), atol=1 / 255)


def test_translucent_layers_composite_as_resvg_does() -> None:
    body = """<rect x="2" y="2" width="14" height="14" fill="#ff0000" fill-opacity="0.6"/>
      <circle cx="14" cy="14" r="7" fill="rgba(0, 0, 255, 0.5)"/>
      <line x1="2" y1="22" x2="22" y2="2" stroke="#00aa00" stroke-width="2" opacity="0.7"/>"""
    md = MorphableDrawing.load(make_svg(body))
    values = md.neutral_values()
    with torch.no_grad():
        soft = md.rasterizer(96).render_rgb(values)[0].permute(1, 2, 0).numpy()
    real = render_svg_rgb(md.to_svg(values[0]), 96)
    assert np.abs(soft - real).mean() < 0.01
    for y, x in ((20, 20), (52, 52), (64, 64), (84, 12)):  # red, red under blue, blue, paper
        np.testing.assert_allclose(soft[y, x], real[y, x], atol=0.03)
    # the ink the decoder reads is one minus the luminance of the colours
    ink = md.render_soft(values, 96)[0, 0].numpy()
    np.testing.assert_allclose(1 - ink, soft @ np.array([0.299, 0.587, 0.114]), atol=1e-5)


def test_colour_runs_are_laid_over_the_paper_by_the_over_operator() -> None:
    """Each run's squashed coverage times its alpha lays its colour over what lies below:
    ``image (1 - alpha) + colour alpha``, to float rounding, in value and in gradient (however
    the rasterizer computes it)."""
    from deepmorph_core.raster import normalised_squash

    body = """<rect x="2" y="2" width="14" height="14" fill="#ff0000" fill-opacity="0.6"/>
      <circle cx="14" cy="14" r="7" fill="rgba(0, 0, 255, 0.5)"/>
      <line x1="2" y1="22" x2="22" y2="2" stroke="#00aa00" stroke-width="2" opacity="0.7"/>"""
    md = MorphableDrawing.load(make_svg(body), move=0.5)
    raster = md.rasterizer(64)
    values = md.values_from_unit(md.random_unit(3, seed=1)).requires_grad_(True)
    image = torch.ones(3, 3, raster.height, raster.width)
    for (paint, _), cover in zip(raster._runs, raster._run_covers(values)):
        alpha = (normalised_squash(cover, raster.settings.squash) * paint.alpha)[:, None]
        image = image * (1.0 - alpha) + torch.tensor(paint.rgb)[None, :, None, None] * alpha
    rendered = raster.render_rgb(values)
    torch.testing.assert_close(rendered, image, rtol=0, atol=1e-6)
    weights = torch.rand_like(image)
    (expected,) = torch.autograd.grad((image * weights).sum(), values)
    (got,) = torch.autograd.grad((rendered * weights).sum(), values)
    torch.testing.assert_close(got, expected, rtol=1e-4, atol=1e-6)


def test_black_and_white_drawings_keep_the_papers_blend() -> None:
    md = MorphableDrawing.load(DATA / "feather" / "airplay.svg", move=0.5)
    assert md.drawing.black_and_white and not md.colour
    values = md.values_from_unit(md.random_unit(2, seed=0))
    raster = md.rasterizer(64)
    assert torch.equal(raster.render_rgb(values), (1 - raster(values)).expand(-1, 3, -1, -1))


@pytest.mark.parametrize("name", ["flat-color-icons/about.svg", "flat-color-icons/android-os.svg",
                                  "flat-color-icons/business-contact.svg", "fluent-emoji-flat/coin.svg",
                                  "fluent-emoji-flat/american-football.svg", "fluent-emoji-flat/eleven-oclock.svg"])  # fmt: skip
def test_real_colour_artwork_loads_and_the_soft_rasterizer_draws_it_as_resvg(name: str, with_bezier) -> None:
    md = MorphableDrawing.load(DATA / name, move=0.5)
    assert md.colour and md.n_variables > 0
    assert rgb_mad(md) < 0.03


def test_gradients_are_written_back_whole_and_drawn_with_their_mean(with_bezier) -> None:
    md = MorphableDrawing.load(DATA / "fluent-emoji-flat" / "eleven-oclock.svg", move=0.5)
    hand = next(p for p in md.drawing.primitives if p.style.fill is not None and p.style.fill.gradient)
    mean = hand.style.fill
    assert mean.gradient == "SVGqoSj3bia"  # #d52c38 -> #df1f81: the mean of the two stops
    assert tuple(round(c * 255) for c in mean.rgb) == (218, 38, 92)  # (56 + 129) / 2 = 92.5, the mean in floats
    written = md.to_svg(md.values_from_unit(md.random_unit(1, seed=1))[0])
    root = etree.fromstring(written.encode())
    gradient = root.find(".//{http://www.w3.org/2000/svg}linearGradient")
    assert gradient is not None and gradient.get("id") == "SVGqoSj3bia"
    assert [s.get("stop-color") for s in gradient] == ["#d52c38", "#df1f81"]
    original = (DATA / "fluent-emoji-flat" / "eleven-oclock.svg").read_text()
    neutral = md.to_svg(md.neutral_values()[0])
    assert np.abs(render_svg_rgb(neutral, 96) - render_svg_rgb(original, 96)).mean() < 2 / 255


def test_what_cannot_be_drawn_is_one_line_that_says_what_to_do(with_bezier) -> None:
    with pytest.raises(
        SvgError, match=r"airplane-arrival.svg:1: unsupported: clip-path='url\(#.*\)': flatten the effect"
    ):
        MorphableDrawing.load(DATA / "fluent-emoji-flat" / "airplane-arrival.svg")


def test_drop_unsupported_says_what_it_dropped_and_keeps_strokes_strokes() -> None:
    body = """<style>.line { stroke: #1976d2; stroke-width: 2; fill: none; filter: url(#f) }</style>
      <polyline class="line" points="3 12 9 6 15 12 21 6"/>"""
    md = MorphableDrawing.load(make_svg(body), drop_unsupported=True)
    assert [(line, what.split("=")[0]) for line, what in md.drawing.dropped] == [(3, "filter")]
    assert [m for m, _ in md.drawing.primitives[0].style.paints] == ["stroke"]
    written = md.to_svg(md.neutral_values()[0])
    assert "stroke: #1976d2" in written and "filter" not in written


@pytest.mark.parametrize(
    "body, message",
    [
        ('<style>.a { fill: #12 }</style><rect class="a" width="4" height="4"/>', "fill='#12': not a colour"),
        ("<style>.a:nth-child(2n+) { fill: red }</style>", "unsupported: CSS selector"),
        ("<style>" + ".a{fill:red}" * 100_000 + "</style>", "more than 200,000 characters of CSS"),
        (
            '<linearGradient id="a" href="#a"/><rect width="4" height="4" fill="url(#a)"/>',
            r"gradient #a references itself \(#a -> #a\)",
        ),
        (
            '<linearGradient id="a"><stop offset="x"/></linearGradient><rect width="4" height="4" fill="url(#a)"/>',
            "not a number",
        ),
    ],
)
def test_bad_colour_input_is_one_clear_error_and_quick(body: str, message: str) -> None:
    start = time.perf_counter()
    with pytest.raises(SvgError, match=message) as info:
        load_drawing(make_svg(body), label="bad.svg")
    assert time.perf_counter() - start < 2
    assert str(info.value).startswith("bad.svg:2: ")


def test_a_huge_path_is_refused_before_its_geometry_is_parsed(monkeypatch: pytest.MonkeyPatch) -> None:
    """A 7 MB path is refused from a count of its numbers: its 700,000 segments are never parsed
    (which took seconds), while a small path is."""
    parsed: list[object] = []
    parse = path_primitive.parse_path_data
    monkeypatch.setattr(
        path_primitive, "parse_path_data", lambda element, reader: parsed.append(element) or parse(element, reader)
    )
    load_drawing(make_svg('<path d="M1 1 L2.25 2.5 L3.75 1.5" stroke="black"/>'), label="small.svg")
    assert len(parsed) == 1
    data = make_svg('<path d="M1 1' + " L2.25 2.5 L3.75 1.5" * 350_000 + '" stroke="black"/>')  # 700,000 segments, 7 MB
    assert len(data) > 6_000_000
    with pytest.raises(SvgError, match="more than the 10000 control points"):
        load_drawing(data, label="huge.svg")
    assert len(parsed) == 1


def test_renderers_are_given_colours_they_all_read() -> None:
    text = make_svg(
        '<rect width="4" height="4" fill="hsl(14, 100%, 40%)" fill-opacity="0.5" style="stroke: #0f08"/>'
    ).decode()
    plain = etree.fromstring(plain_colours(text).encode()).find("{http://www.w3.org/2000/svg}rect")
    assert plain.get("fill") == "#cc3000" and plain.get("fill-opacity") == "0.5"
    assert plain.get("style") == "stroke: #00ff00; stroke-opacity: 0.533333"
    hex_only = make_svg('<rect width="4" height="4" fill="#ff0000" stroke="none"/>').decode()
    assert plain_colours(hex_only) is hex_only  # nothing to rewrite: not even parsed


TWO_COLOURS = make_svg(
    """<g stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="2.5">
  <rect x="2" y="2" width="20" height="20" rx="3" fill="#ffd54f" stroke="none" dm:move="1"/>
  <polyline points="4 6 12 4 20 6" stroke="#1565c0"/>
  <line x1="4" y1="12" x2="20" y2="12" stroke="#1565c0"/>
  <polyline points="4 18 12 20 20 18" stroke="#1565c0"/>
  <circle cx="12" cy="12" r="3" stroke="#1565c0" dm:move="1.5"/>
</g>"""
)


def test_a_short_training_run_on_a_two_colour_drawing_reads_its_bits_from_a_colour_print(tmp_path: Path) -> None:
    svg = tmp_path / "two.svg"
    svg.write_bytes(TWO_COLOURS)
    out = tmp_path / "two.dmm"
    train = {
        "width": 48,
        "batch": 16,
        "severity": "none",
        "hard_fraction": 0.25,
        "steps": 500,
        "seed": 1,
        "threads": 1,
        "trust_samples": 0,
    }  # validated, not counted (minutes: tests/app/test_trust.py counts)
    train_model(svg, out, payload_bits=4, crc_bits=16, ecc_t=0, train=train)
    model = DeepMorphModel.load(out)
    assert model.drawing.colour
    gen = torch.Generator().manual_seed(0)
    bits = torch.randint(0, 2, (64, model.codec.spec.code_bits), generator=gen).float()
    with torch.no_grad():
        probs = model.probabilities(1 - model.rasterizer()(model.morph_values(bits)))
    assert ((probs > 0.5) == (bits > 0.5)).float().mean().item() > 0.8  # chance is 0.5
    # a print in its colours (the PNG is RGB), read through the photo chain
    api = deepmorph.load(out)
    code = api.encode(0xA)
    png = Image.open(io.BytesIO(code.png(width_mm=30, dpi=150)))
    assert png.mode == "RGB"
    found = list(api.decode(np.asarray(png)))
    assert [(f.payload.int, f.ok) for f in found] == [(0xA, True)]
    # and the luminance it reads is the renderer's
    gray = render_svg(code.svg, 64)
    rgb = render_svg_rgb(code.svg, 64)
    np.testing.assert_allclose(gray, rgb @ np.array([0.299, 0.587, 0.114]), atol=1 / 255)


CYAN_BARS = make_svg('<path fill="#00BCD4" d="M9.5 11h5v10h-5zM3 6h5v15H3zm13-3h5v18h-5z" dm:move="0.25"/>')


def test_a_drawing_in_light_colours_is_framed_by_its_own_darkest_paint() -> None:
    """Cyan on white (luminance 0.53) has no pixel darker than 0.5 until its contrast is
    stretched as a photo's is: then framing and the photo chain's templates find its ink."""
    from deepmorph_core.luminance import stretch_ink
    from deepmorph_detect.fastrender import render_svg_resvg, stretched_renderer

    md = MorphableDrawing.load(CYAN_BARS)
    assert md.ink_level == pytest.approx(0.5275, abs=1e-3)
    raw = md.render_real(md.neutral_values(), 96)
    assert raw.min() > 0.5  # no ink at all by the black-and-white rule
    stretched = stretch_ink(raw, md.ink_level)
    assert stretched.min() < 0.02 and stretched.max() == 1.0
    cx, cy, sx, sy = md.neutral_moments(96).tolist()
    assert 40 < cx < 56 and 40 < cy < 60 and 20 < sx < 40  # the bars' ink, not the frame's fallback
    render = stretched_renderer(render_svg_resvg, md.ink_level)
    svg = md.to_svg(md.neutral_values()[0])
    assert (render(svg, 64, md.drawing.viewbox) < 0.5).mean() > 0.2
    assert stretched_renderer(render_svg_resvg, 0.0) is render_svg_resvg  # black ink: untouched


def test_a_light_print_on_a_dark_desk_is_framed_on_its_sheet() -> None:
    """A desk as dark as cyan ink is the darkest thing in the photo: the whole image's ink mask
    takes the desk; on the paper sheet alone the drawing's ink is found."""
    from deepmorph_detect.fastrender import render_svg_resvg, stretched_renderer
    from deepmorph_detect.propose import InkFrame, whole_frame, whole_frame_on_paper
    from deepmorph_detect.refine import LEVELS, Template

    md = MorphableDrawing.load(CYAN_BARS)
    svg = md.to_svg(md.neutral_values()[0])
    viewbox = md.drawing.viewbox
    template = Template.from_svg(svg, viewbox, LEVELS, stretched_renderer(render_svg_resvg, md.ink_level))
    ink = InkFrame.of(template)
    corners = np.array([[0, 0], [24, 0], [24, 24], [0, 24]], dtype=np.float64)
    photo = np.full((300, 300), 0.45, np.float32)  # a desk darker than the cyan (0.53 x paper)
    photo[40:260, 50:250] = 0.92  # the sheet
    photo[70:230, 70:230] = 0.92 * render_svg(svg, 160)
    sheet = whole_frame_on_paper(photo, ink, template, corners)
    assert len(sheet) == 1
    x0, y0, x1, y1 = sheet[0].bbox
    assert 60 <= x0 and 60 <= y0 and x1 <= 240 and y1 <= 240  # the bars, inside the sheet
    whole = whole_frame(photo, ink, template, corners)
    assert not whole or whole[0].bbox[0] < 50  # the whole image's ink reaches out to the desk
