"""Colours spelled so that every renderer reads them: what resvg and Skia are given.

DeepMorph reads every CSS colour syntax, but renderers lag behind CSS: Skia's SVG module
paints ``hsl()`` and 8-digit hex as black, resvg paints CSS Color 4 names (``rebeccapurple``)
as black. A drawing written for the artist keeps the colours as drawn; before a document goes to
a renderer, :func:`plain_colours` rewrites each colour as ``#rrggbb``, its alpha moved into the
matching ``*-opacity``, so the print, the PDF and the training renders all show the colours
DeepMorph read.
"""

from __future__ import annotations

import re

from lxml import etree

from deepmorph_core.svg.secure import parse_svg_bytes
from deepmorph_core.svg.style import parse_colour, style_declarations

#: Colour properties, with the opacity property their alpha multiplies into.
_COLOUR_PROPERTIES = {"fill": "fill-opacity", "stroke": "stroke-opacity", "stop-color": "stop-opacity", "color": None}
#: Colour text every renderer reads: ``#rgb``, ``#rrggbb``, keywords that need no colour.
_PLAIN = re.compile(r"^(#[0-9a-fA-F]{3}|#[0-9a-fA-F]{6}|none|currentcolor|inherit|url\(.*)$", re.IGNORECASE)
#: A quick look for anything that might need a rewrite (most drawings hold only hex colours).
_MAYBE = re.compile(r"(fill|stroke|stop-color|color)\s*[=:]\s*[\"']?\s*(?!#[0-9a-fA-F]{6}\b|#[0-9a-fA-F]{3}\b|none\b|url)",
                    re.IGNORECASE)  # fmt: skip


def plain_colours(svg_text: str) -> str:
    """``svg_text`` with every colour written as ``#rrggbb`` (alpha in the ``*-opacity``
    property); the text unchanged when it holds only such colours already."""
    if not _MAYBE.search(svg_text):
        return svg_text
    root = parse_svg_bytes(svg_text.encode("utf-8"), "<svg>")
    changed = False
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        for prop, opacity in _COLOUR_PROPERTIES.items():
            value = element.get(prop)
            if value is not None and not _PLAIN.match(value.strip()):
                hexa, alpha = _plain(value, prop)
                element.set(prop, hexa)
                if opacity is not None and alpha < 1.0:
                    element.set(opacity, _times(element.get(opacity), alpha))
                changed = True
        if element.get("style"):
            decls = style_declarations(element.get("style"))
            rewritten = dict(decls)
            for prop, opacity in _COLOUR_PROPERTIES.items():
                value = decls.get(prop)
                if value is not None and not _PLAIN.match(value.strip()):
                    hexa, alpha = _plain(value, prop)
                    rewritten[prop] = hexa
                    if opacity is not None and alpha < 1.0:
                        rewritten[opacity] = _times(decls.get(opacity, element.get(opacity)), alpha)
            if rewritten != decls:
                element.set("style", "; ".join(f"{k}: {v}" for k, v in rewritten.items()))
                changed = True
    return etree.tostring(root, encoding="unicode") if changed else svg_text


def _plain(value: str, prop: str) -> tuple[str, float]:
    try:
        paint = parse_colour(value, prop)
    except ValueError:
        return value, 1.0  # not a colour DeepMorph reads: the drawing was refused before
    if paint is None:  # transparent
        return "none", 1.0
    return "#" + "".join(f"{round(c * 255):02x}" for c in paint.rgb), paint.alpha


def _times(opacity: str | None, alpha: float) -> str:
    base = 1.0
    if opacity is not None:
        text = opacity.strip()
        try:
            base = float(text[:-1]) / 100 if text.endswith("%") else float(text)
        except ValueError:
            base = 1.0
    return f"{min(1.0, max(0.0, base)) * alpha:.6g}"
