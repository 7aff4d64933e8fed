"""Reading SVG: hostile and broken input, styles, transforms, what is skipped."""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from deepmorph_core.drawing import load_drawing
from deepmorph_core.errors import SvgError, UnsupportedFeatureError
from deepmorph_core.morph import MorphSpace
from deepmorph_core.svg.style import BLACK, WHITE
from tests.conftest import make_svg

LINE = '<line x1="1" y1="1" x2="9" y2="9" stroke="black"/>'


def error_of(data: bytes, registry) -> SvgError:
    start = time.perf_counter()
    with pytest.raises(SvgError) as info:
        load_drawing(data, registry=registry, label="t.svg")
    assert time.perf_counter() - start < 5, "hostile input must fail fast"
    return info.value


@pytest.mark.parametrize(
    "data, expected, line",
    [
        (b"not xml", "malformed XML", 1),
        (b'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 9 9">\n<line x1="1"\n</svg>', "malformed XML", 3),
        (
            b'<?xml version="1.0"?>\n<!DOCTYPE l [\n<!ENTITY a "aaaaaaaaaa">\n<!ENTITY b "&a;&a;&a;&a;&a;&a;">\n]>'
            b'<svg xmlns="http://www.w3.org/2000/svg"><desc>&b;</desc></svg>',
            "entity declarations are not allowed",
            3,
        ),
        (
            b'<?xml version="1.0"?>\n<!DOCTYPE svg [ <!ENTITY x SYSTEM "file:///etc/passwd"> ]>\n'
            b'<svg xmlns="http://www.w3.org/2000/svg"><desc>&x;</desc></svg>',
            "entity declarations are not allowed",
            2,
        ),
        (b'<html xmlns="http://www.w3.org/1999/xhtml"/>', "not <svg>", 1),
        (make_svg('<line x1="NaN" y1="1" x2="2" y2="2" stroke="black"/>'), "not a number", 2),
        (make_svg('<line x1="inf" y1="1" x2="2" y2="2" stroke="black"/>'), "not a number", 2),
        (make_svg('<line x1="1e308" y1="1" x2="2" y2="2" stroke="black"/>'), "beyond", 2),
        (make_svg('<path d="M1 1 L1e400 2" stroke="black"/>'), "not finite", 2),
        (make_svg('<polyline points="1 2 3" stroke="black"/>'), "odd number", 2),
        (make_svg('<text x="1" y="1">hi</text>'), "unsupported: element <text>", 2),
        (make_svg('<image href="http://example.com/x.png" width="1" height="1"/>'), "unsupported: element <image>", 2),
        (make_svg('<use href="#a"/>'), "unsupported: element <use>", 2),
        (make_svg('<line x1="1" y1="1" x2="2" y2="2" stroke="reddish"/>'), "stroke='reddish': not a colour", 2),
        (make_svg('<line x1="1" y1="1" x2="2" y2="2" stroke="lab(50% 20 30)"/>'), "colour space lab", 2),
        (make_svg('<rect width="2" height="2" fill="url(http://example.com/p.svg#a)"/>'), "nothing is fetched", 2),
        (make_svg('<rect width="2" height="2" fill="url(#nowhere)"/>'), "no gradient with id 'nowhere'", 2),
        (
            make_svg("<style>\n.a { fill: red }\n@import url(x.css);\n</style>"),
            "CSS @import in <style> (nothing is fetched)",
            4,
        ),
        (make_svg("<style>.a { fill: url(https://example.com/x.svg) }</style>"), "nothing is fetched", 2),
        (make_svg("<style>.a::before { fill: red }</style>"), "pseudo-element", 2),
        (
            make_svg(
                '<style>.a { fill: red; </style><rect class="a" width="2" height="2" fill="red" filter="url(#f)"/>'
            ),
            "filter",
            2,
        ),
        (
            make_svg(
                '<linearGradient id="g" href="#h"/>\n<linearGradient id="h" href="#g"/>\n<rect width="2" height="2" fill="url(#g)"/>'
            ),
            "gradient #g references itself (#g -> #h -> #g)",
            3,
        ),
        (make_svg('<circle r="2" fill="red"/><text>hi</text>'), "outline the text", 2),
        (make_svg('<circle r="2" fill="red" clip-path="url(#c)"/>'), "clip-path", 2),
        (make_svg('<line x1="1" y1="1" x2="2" y2="2" stroke="black" stroke-dasharray="1 1"/>'), "stroke-dasharray", 2),
        (make_svg('<g transform="rotate(a)"><line x1="1" y1="1" x2="2" y2="2" stroke="black"/></g>'), "transform", 2),
        (make_svg('<g transform="scale(0)"><line x1="1" y1="1" x2="2" y2="2" stroke="black"/></g>'), "degenerate", 2),
        (make_svg(LINE, root='viewBox="0 0 -1 5"'), "viewBox", 1),
        (make_svg(LINE, root=""), "needs a viewBox", 1),
        (make_svg('<path d="M1 1 C 1 2 3 4 5 6" stroke="black"/>'), "unsupported: path command C", 2),
        (make_svg('<path d="M1 1 q 1 2 3 4" stroke="black"/>'), "unsupported: path command q", 2),
        (make_svg('<path d="M1 1 L 2 x" stroke="black"/>'), "path data", 2),
    ],
)
def test_bad_input_is_one_clear_error(data: bytes, expected: str, line: int, builtin_registry) -> None:
    err = error_of(data, builtin_registry)
    assert expected in str(err)
    assert err.line == line
    assert str(err).startswith(f"t.svg:{line}: ")


def test_unsupported_is_its_own_type(builtin_registry) -> None:
    with pytest.raises(UnsupportedFeatureError):
        load_drawing(make_svg('<path d="M1 1 S 1 2 3 4" stroke="black"/>'), registry=builtin_registry)


def test_deep_nesting_and_huge_files(tmp_path, builtin_registry) -> None:
    deep = make_svg("<g>" * 100 + LINE + "</g>" * 100)
    assert "nested deeper" in str(error_of(deep, builtin_registry))
    very_deep = make_svg("<g>" * 1000 + "</g>" * 1000)
    assert "nested" in str(error_of(very_deep, builtin_registry))
    big = tmp_path / "big.svg"
    big.write_bytes(make_svg("<desc>" + "x" * (9 * 1024 * 1024) + "</desc>"))
    with pytest.raises(SvgError, match="limit is"):
        load_drawing(big, registry=builtin_registry)
    with pytest.raises(SvgError, match="cannot read file"):
        load_drawing(tmp_path / "missing.svg", registry=builtin_registry)


def test_public_doctype_is_not_fetched(builtin_registry) -> None:
    data = (
        b'<?xml version="1.0"?>\n<!DOCTYPE svg PUBLIC "-//W3C//DTD SVG 1.1//EN" '
        b'"http://www.w3.org/Graphics/SVG/1.1/DTD/svg11.dtd">\n' + make_svg(LINE)
    )
    drawing = load_drawing(data, registry=builtin_registry)
    assert [p.primitive.kind for p in drawing.primitives] == ["line"]
    space = MorphSpace(drawing)
    assert "DOCTYPE" not in space.write_svg(torch.zeros(space.n_variables))


def test_styles_inherit_and_invisible_elements_are_skipped(builtin_registry) -> None:
    body = """
<g stroke="black" stroke-width="3" style="stroke-linecap: round">
  <line x1="1" y1="1" x2="5" y2="1"/>
  <line x1="1" y1="2" x2="5" y2="2" visibility="hidden"/>
  <g display="none"><line x1="1" y1="3" x2="5" y2="3"/></g>
  <line x1="1" y1="4" x2="5" y2="4" stroke="none"/>
  <circle cx="5" cy="5" r="2" fill="white" stroke="currentColor" opacity="0"/>
  <rect x="1" y="1" width="0" height="3"/>
  <circle cx="5" cy="5" r="2" style="fill:#FFF; stroke: none"/>
</g>
<metadata><whatever/></metadata>
"""
    drawing = load_drawing(make_svg(body, style='fill="none"'), registry=builtin_registry)
    kinds = [(p.primitive.kind, p.line, p.style.paints) for p in drawing.primitives]
    assert kinds == [("line", 4, [("stroke", BLACK)]), ("circle", 10, [("fill", WHITE)])]
    assert drawing.primitives[0].style.stroke_width == 3
    assert drawing.primitives[0].style.linecap == "round"
    assert len(drawing.skipped) == 5


def test_transforms_compose_into_the_ctm(builtin_registry) -> None:
    body = '<g transform="translate(2 3) scale(2)"><line x1="1" y1="1" x2="2" y2="2" stroke="black" transform="rotate(90)"/></g>'
    prim = load_drawing(make_svg(body), registry=builtin_registry).primitives[0]
    point = prim.ctm @ np.array([1.0, 0.0, 1.0])
    np.testing.assert_allclose(point[:2], [2.0, 5.0], atol=1e-9)  # rotate (1,0)->(0,1), scale x2, translate
