"""Presentation attributes and ``style=""`` with SVG inheritance, reduced to black and white.

DeepMorph renders black-and-white drawings: every paint is black (+1 ink), white (-1 ink) or
none (0). ``currentColor`` is the ``color`` property, black unless set.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

from deepmorph_core.svg.values import parse_length, parse_number

BLACK, WHITE, NONE = 1, -1, 0

#: Properties this module reads; of these, all but display/opacity inherit.
INHERITED = ("fill", "stroke", "stroke-width", "stroke-linecap", "stroke-linejoin", "fill-rule", "visibility", "color")
_NAMED = {
    "black": BLACK,
    "#000": BLACK,
    "#000000": BLACK,
    "rgb(0,0,0)": BLACK,
    "white": WHITE,
    "#fff": WHITE,
    "#ffffff": WHITE,
    "rgb(255,255,255)": WHITE,
    "none": NONE,
    "transparent": NONE,
}


@dataclass(frozen=True)
class Style:
    """The computed style of one element (inherited values included).

    Attributes:
        fill, stroke: ``BLACK``, ``WHITE`` or ``NONE``.
        stroke_width: in the element's user units.
        linecap: ``butt``, ``round`` or ``square``.
        linejoin: ``miter``, ``round``, ``bevel`` (joins are drawn round; see docs).
        fill_rule: ``nonzero`` or ``evenodd``.
        color: what ``currentColor`` means here.
        shown: ``visibility`` (inherited; a child may set it back to visible).
        displayed: ``False`` under ``display="none"`` or zero ``opacity`` (whole subtree).
    """

    fill: int = BLACK
    stroke: int = NONE
    stroke_width: float = 1.0
    linecap: str = "butt"
    linejoin: str = "miter"
    fill_rule: str = "nonzero"
    color: int = BLACK
    shown: bool = True
    displayed: bool = True

    @property
    def visible(self) -> bool:
        """Whether anything of the element is drawn."""
        return self.shown and self.displayed and bool(self.paints)

    @property
    def paints(self) -> list[tuple[str, int]]:
        """What is painted, in SVG's order (fill, then stroke): ``[(mode, colour), ...]``."""
        out = []
        if self.fill != NONE:
            out.append(("fill", self.fill))
        if self.stroke != NONE and self.stroke_width > 0:
            out.append(("stroke", self.stroke))
        return out


def declarations(element_attrib: dict[str, str], style_attr: str | None) -> dict[str, str]:
    """Presentation attributes overridden by ``style=""`` declarations (CSS wins)."""
    props = {k: v for k, v in element_attrib.items() if "}" not in k}
    if style_attr:
        for decl in style_attr.split(";"):
            if not decl.strip():
                continue
            if ":" not in decl:
                raise ValueError(f"cannot read style declaration {decl.strip()!r}")
            name, value = decl.split(":", 1)
            props[name.strip().lower()] = value.strip()
    return props


def _colour(value: str, current: int, prop: str) -> int:
    v = re.sub(r"\s+", "", value.strip().lower())
    if v == "currentcolor":
        return current
    if v in _NAMED:
        return _NAMED[v]
    raise ValueError(f"{prop}={value!r}: only black, white and none are supported")


def compute_style(props: dict[str, str], parent: Style) -> Style:
    """Apply one element's declarations on top of its parent's computed style.

    Only the properties this module reads are looked at; which others a drawing may hold is
    :mod:`deepmorph_core.svg.policy`'s decision.

    Raises:
        ValueError: an unsupported value (the caller adds file and line).
    """
    style = parent
    if "color" in props:
        style = replace(style, color=_colour(props["color"], parent.color, "color"))
    if "fill" in props:
        style = replace(style, fill=_colour(props["fill"], style.color, "fill"))
    if "stroke" in props:
        style = replace(style, stroke=_colour(props["stroke"], style.color, "stroke"))
    if "stroke-width" in props:
        w = parse_length(props["stroke-width"])
        if w < 0:
            raise ValueError(f"stroke-width {w:g} is negative")
        style = replace(style, stroke_width=w)
    for prop, attr, allowed in (
        ("stroke-linecap", "linecap", ("butt", "round", "square")),
        ("stroke-linejoin", "linejoin", ("miter", "round", "bevel", "miter-clip", "arcs")),
        ("fill-rule", "fill_rule", ("nonzero", "evenodd")),
    ):
        if prop in props and props[prop].strip() != "inherit":
            value = props[prop].strip().lower()
            if value not in allowed:
                raise ValueError(f"{prop}={props[prop]!r} is not one of {', '.join(allowed)}")
            style = replace(style, **{attr: value})
    shown, displayed = parent.shown, parent.displayed
    if props.get("visibility", "").strip() in ("hidden", "collapse"):
        shown = False
    elif props.get("visibility", "").strip() == "visible":
        shown = True
    if props.get("display", "").strip() == "none":
        displayed = False
    for prop in ("opacity", "fill-opacity", "stroke-opacity"):
        if prop in props:
            alpha = parse_number(props[prop].strip().rstrip("%"))
            if props[prop].strip().endswith("%"):
                alpha /= 100
            if alpha <= 0:
                if prop == "opacity":
                    displayed = False
                elif prop == "fill-opacity":
                    style = replace(style, fill=NONE)
                else:
                    style = replace(style, stroke=NONE)
            elif alpha < 1:
                raise ValueError(f"{prop}={props[prop]!r}: partial transparency is not supported")
    return replace(style, shown=shown, displayed=displayed)
