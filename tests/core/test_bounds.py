"""Bound-specs: parsing, inheritance, readable errors, and property tests that a morph never
leaves its bounds (in the map T, in the geometry, and in the written SVG)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deepmorph_core.bounds import BoundSpec, parse_bounds
from deepmorph_core.drawing import load_drawing
from deepmorph_core.errors import BoundsError, DeepMorphError
from deepmorph_core.morphable import MorphableDrawing
from tests.conftest import make_svg


def test_attribute_forms() -> None:
    spec = parse_bounds({"move": "0.5", "shift": "1 2", "scale": "0.9 1.1", "rotate": "-5 5", "fixed": "false"})
    assert spec == BoundSpec(move=0.5, shift=(1.0, 2.0), scale=(0.9, 1.1), rotate=(-5.0, 5.0), fixed=False)
    assert parse_bounds({"shift": "3"}).shift == (3.0, 3.0)


@pytest.mark.parametrize(
    "attr, message",
    [
        ('dm:scale="1.1 0.9"', "scale: lower bound 1.1 is above upper bound 0.9"),
        ('dm:move="-2"', "dm:move"),
        ('dm:move="a"', "dm:move"),
        ('dm:rotate="-200 5"', "rotate: degrees must lie in [-180, 180]"),
        ('dm:shift="1 2 3"', "dm:shift"),
        ('dm:fixed="maybe"', "dm:fixed"),
        ('dm:wobble="2"', "unknown attribute dm:wobble"),
    ],
)
def test_bad_bounds_are_one_readable_error(attr: str, message: str, builtin_registry) -> None:
    svg = make_svg(f'<line x1="1" y1="1" x2="5" y2="5" stroke="black"\n {attr}/>')
    with pytest.raises(BoundsError) as info:
        load_drawing(svg, registry=builtin_registry, label="b.svg")
    assert message in str(info.value)
    assert str(info.value).startswith("b.svg:3: ")  # libxml2 reports the line the start tag ends on


def test_inheritance_and_defaults(builtin_registry) -> None:
    body = """
<line x1="1" y1="1" x2="5" y2="5" stroke="black"/>
<g dm:move="0.3"><line x1="1" y1="1" x2="5" y2="5" stroke="black" dm:rotate="-4 4"/>
  <g dm:fixed="true"><circle cx="9" cy="9" r="2" stroke="black"/></g></g>
<line x1="1" y1="1" x2="5" y2="5" stroke="black" dm:move="0"/>"""
    drawing = load_drawing(
        make_svg(body, root='viewBox="0 0 24 24" dm:move="1" dm:shift="0.5"'),
        registry=builtin_registry,
        defaults=BoundSpec(move=9.0, scale=(0.9, 1.1)),
    )
    p = drawing.primitives
    assert (p[0].bounds.move, p[0].bounds.shift, p[0].bounds.scale) == (1.0, (0.5, 0.5), (0.9, 1.1))
    assert (p[1].bounds.move, p[1].bounds.rotate) == (0.3, (-4.0, 4.0))
    assert p[2].fixed
    assert p[3].bounds.move == 0.0
    md = MorphableDrawing.load(make_svg(body, root='viewBox="0 0 24 24" dm:move="1" dm:shift="0.5"'))
    roles = [(v.index, v.role) for v in md.variables]
    assert (2, "move-x") not in roles and (2, "shift-x") not in roles  # fixed
    assert (3, "move-x") not in roles and (3, "shift-x") in roles


def test_fixed_inside_morphing_group_is_refused(builtin_registry) -> None:
    body = '<g dm:shift="1"><circle cx="9" cy="9" r="2" stroke="black" dm:fixed="true"/></g>'
    with pytest.raises(DeepMorphError, match="dm:fixed element cannot sit inside a group"):
        load_drawing(make_svg(body), registry=builtin_registry)


def test_no_bounds_means_zero_variables() -> None:
    md = MorphableDrawing.load(make_svg('<line x1="1" y1="1" x2="5" y2="5" stroke="black"/>'))
    assert md.n_variables == 0
    assert (
        MorphableDrawing.load(make_svg('<line x1="1" y1="1" x2="5" y2="5" stroke="black"/>'), move=0.5).n_variables == 4
    )


BOUNDED = make_svg(
    """
<polyline points="2 2 8 6 14 2" stroke="black" dm:move="0.7"/>
<circle cx="12" cy="14" r="3" stroke="black" dm:move="0.4" dm:shift="0.5 1" dm:scale="0.8 1.25"/>
<path d="M3 20 L8 17 A3 3 0 0 1 14 17" stroke="black" fill="none" dm:move="0.6"/>
<g transform="rotate(20 12 12)" dm:rotate="-7 7" dm:shift="0.3"><line x1="16" y1="6" x2="22" y2="10" stroke="black"/></g>
"""
)
MD = MorphableDrawing.load(BOUNDED)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.floats(0.0, 1.0), min_size=MD.n_variables, max_size=MD.n_variables))
def test_values_stay_inside_bounds(unit: list[float]) -> None:
    u = torch.tensor([unit], dtype=torch.float64)
    values = MD.space.physical(MD.values_from_unit(u))[0]
    moves: dict[tuple[int, int], list[float]] = {}
    for v, x in zip(MD.variables, values.tolist()):
        if v.role.startswith("move"):
            moves.setdefault((v.index, v.point), []).append(x)
            assert v.lo - 1e-12 <= x <= v.hi + 1e-12
        else:
            assert v.lo - 1e-9 <= x <= v.hi + 1e-9, (v, x)
    for (index, _), (dx, dy) in moves.items():
        radius = MD.drawing.primitives[index].bounds.move
        assert math.hypot(dx, dy) <= radius + 1e-9


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=MD.n_variables, max_size=MD.n_variables))
def test_written_svg_stays_inside_bounds(unit: list[float]) -> None:
    """Re-read the written SVG: every moved point is within its dm:move radius (plus the
    element's own bounded shift/scale for the circle)."""
    values = MD.values_from_unit(torch.tensor([unit], dtype=torch.float64))
    again = load_drawing(
        MD.to_svg(values[0]).encode(),
    )
    before = [p.primitive.control_points().numpy() for p in MD.drawing.primitives]
    after = [p.primitive.control_points().numpy() for p in again.primitives]
    for k in (0, 2):  # move-only elements
        assert np.linalg.norm(after[k] - before[k], axis=1).max() <= MD.drawing.primitives[k].bounds.move + 1e-3
    shift = np.abs(after[1][0] - before[1][0])
    # the element scale (up to 1.25) acts about the original centre on the moved centre
    assert shift[0] <= 1.25 * 0.4 + 0.5 + 1e-3 and shift[1] <= 1.25 * 0.4 + 1.0 + 1e-3
    r = float(again.primitives[1].primitive.rx)
    assert 3 * 0.8 - 1e-3 <= r <= 3 * 1.25 + 1e-3
