"""Writing morphs back: the written SVG draws exactly the morph that was rasterized, and
everything the morph does not touch is left as it was."""

from __future__ import annotations

import torch
from lxml import etree

from deepmorph_core.morphable import MorphableDrawing
from tests.conftest import make_svg

EVERY_KIND = make_svg(
    """
<!-- a comment that must survive -->
<g stroke="black" stroke-width="1.5" fill="none" dm:move="0.5">
  <line x1="2" y1="2" x2="9" y2="4" dm:rotate="-10 10"/>
  <polyline points="2 7 6 9 10 7" dm:scale="0.8 1.2"/>
  <polygon points="13 2 20 3 17 8" fill="black" dm:shift="1 0.5"/>
  <rect x="2" y="12" width="7" height="5" rx="1.5" dm:rotate="-15 15" dm:scale="0.9 1.1"/>
  <circle cx="15" cy="14" r="3" dm:scale="0.7 1.3"/>
  <ellipse cx="15" cy="20" rx="4" ry="1.5" dm:rotate="-20 20"/>
  <path d="M2 22 L5 19 A2 2 0 0 1 9 19 L10 22" dm:rotate="-5 5"/>
  <path d="M18 9 A2.5 2.5 0 0 1 23 9 Z" fill="black"/>
  <g transform="translate(20 14) rotate(30)" dm:shift="0.7" dm:rotate="-10 10">
    <line x1="-2" y1="0" x2="2" y2="0"/>
  </g>
  <circle cx="21" cy="22" r="1" dm:fixed="true"/>
</g>"""
)


def test_written_svg_reproduces_the_morph() -> None:
    md = MorphableDrawing.load(EVERY_KIND)
    kinds = [p.primitive.kind for p in md.drawing.primitives]
    assert kinds == [
        "line",
        "polyline",
        "polygon",
        "rect",
        "circle",
        "ellipse",
        "path",
        "half-circle",
        "line",
        "circle",
    ]
    values = md.values_from_unit(md.random_unit(3, seed=11).double())
    soft = md.render_soft(values, 72, cull=False)  # dense: compare geometry, not culling
    for k in range(3):
        again = MorphableDrawing.load(md.to_svg(values[k]).encode())
        assert again.n_variables == md.n_variables
        rerendered = again.render_soft(again.neutral_values().double(), 72, cull=False)
        torch.testing.assert_close(rerendered[0], soft[k], atol=2e-3, rtol=0)


def test_untouched_elements_and_comments_stay_as_they_were() -> None:
    md = MorphableDrawing.load(EVERY_KIND)
    out = md.to_svg(md.values_from_unit(md.random_unit(1, seed=2))[0])
    assert "<!-- a comment that must survive -->" in out
    root = etree.fromstring(out.encode())
    fixed = [el for el in root.iter() if el.get("{urn:deepmorph:1}fixed") == "true"][0]
    assert dict(fixed.attrib) == {"cx": "21", "cy": "22", "r": "1", "{urn:deepmorph:1}fixed": "true"}
    assert all(v.index != 9 for v in md.variables if v.owner == "primitive")


def test_neutral_morph_changes_nothing() -> None:
    md = MorphableDrawing.load(EVERY_KIND)
    original = etree.tostring(md.drawing.root.getroottree(), encoding="unicode")
    neutral = md.neutral_values()[0]
    neutral[[i for i, v in enumerate(md.variables) if v.role == "scale"]] = 0.0  # factor 1
    assert md.to_svg(neutral) == original


def test_morphs_written_together_are_each_as_written_alone() -> None:
    # to_svgs writes each morph into one sanitized copy in turn: what one morph adds (a
    # rotation's transform, a group's matrix, new radii) must not stay for the next
    md = MorphableDrawing.load(EVERY_KIND)
    original = etree.tostring(md.drawing.root.getroottree(), encoding="unicode")
    values = md.values_from_unit(md.random_unit(3, seed=5).double())
    neutral = md.neutral_values()[0].double()
    neutral[[i for i, v in enumerate(md.variables) if v.role == "scale"]] = 0.0
    morphs = torch.stack([values[0], neutral, values[1], values[2]])
    together = md.to_svgs(morphs)
    assert together == [MorphableDrawing.load(EVERY_KIND).to_svg(m) for m in morphs]
    assert "rotate(" in together[0] and "matrix(" in together[0]
    assert together[1] == original
    assert len(set(together)) == 4
