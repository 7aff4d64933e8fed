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

import tinycss2.color3
from lxml import etree

from deepmorph_core.svg.secure import parse_svg_bytes
from deepmorph_core.svg.style import parse_colour, style_declarations

#: Colour properties, with the opacity property their alpha multiplies into.
_COLOUR_PROPERTIES = {"fill": "fill-opacity", "stroke": "stroke-opacity", "stop-color": "stop-opacity", "color": None}
#: Colour text every renderer reads: ``#rgb``, ``#rrggbb``, keywords that need no colour, and
#: (checked in :func:`_is_plain`) SVG 1.1's colour names and its comma ``rgb()``.
_PLAIN = re.compile(r"^(#[0-9a-fA-F]{3}|#[0-9a-fA-F]{6}|none|currentcolor|inherit|url\(.*)$", re.IGNORECASE)
#: Every colour value in a document, as attribute or declaration: a quick look before any parse.
_VALUES = re.compile(r"(?<![\w-])(?:fill|stroke|stop-color|color)\s*(?:=\s*[\"']|:)\s*([^\"';]*)", re.IGNORECASE)


def _is_plain(value: str) -> bool:
    """Whether every renderer reads ``value`` as DeepMorph does: hex without alpha, keywords,
    ``url()``, and the CSS 2 / SVG 1.1 colours (names and comma ``rgb()``, tinycss2's CSS 3
    parser, which knows no CSS 4 name and no ``rgb()`` with spaces)."""
    text = value.strip()
    if _PLAIN.match(text):
        return True
    if not (text.isalpha() or text.lower().startswith("rgb(")):
        return False
    colour = tinycss2.color3.parse_color(text)
    return colour is not None and not isinstance(colour, str) and colour.alpha == 1.0


def plain_colours(svg_text: str) -> str:
    """``svg_text`` with every colour written as ``#rrggbb`` (alpha in the ``*-opacity``
    property); the text unchanged when it holds only such colours already."""
    if all(_is_plain(v) for v in _VALUES.findall(svg_text)):
        return svg_text
    root = parse_svg_bytes(svg_text.encode("utf-8"), "<svg>")
    changed = False
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        for prop, opacity in _COLOUR_PROPERTIES.items():
            value = element.get(prop)
            if value is not None and not _is_plain(value):
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
                if value is not None and not _is_plain(value):
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
