"""Presentation attributes, ``style=""`` and stylesheet declarations with SVG inheritance.

Every paint is a :class:`Paint`: an sRGB colour with an alpha. Colours are read in every CSS
syntax (hex with 3, 4, 6 or 8 digits, ``rgb()``/``rgba()``, ``hsl()``/``hsla()``, ``hwb()``,
names, ``transparent``, ``currentColor``) by tinycss2's CSS Color 4 parser; ``url(#id)`` names a
gradient, read as its mean colour (:mod:`deepmorph_core.svg.gradients`). ``opacity``,
``fill-opacity`` and ``stroke-opacity`` scale the paint's alpha. ``paint-order`` decides
whether a stroke is painted under or over its fill.

Group ``opacity`` is applied to each shape inside the group: exact where the group's shapes do
not overlap, a slightly darker overlap where they do (the soft rasterizer composites shapes, not
groups).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, replace

import tinycss2.color4

from deepmorph_core.luminance import LUMA_WEIGHTS, Channel
from deepmorph_core.svg.values import parse_length, parse_number

#: Colour spaces tinycss2 converts to sRGB; others (lab, oklch, display-p3 ...) are refused.
_SRGB_SPACES = ("srgb", "hsl", "hwb")


@dataclass(frozen=True)
class Paint:
    """One paint: what a fill or a stroke lays down.

    Attributes:
        rgb: sRGB colour, each channel in ``[0, 1]``.
        alpha: opacity in ``(0, 1]``: the colour's own alpha times ``fill-opacity`` or
            ``stroke-opacity`` and every enclosing ``opacity``.
        gradient: the id of the gradient this paint stands for (``rgb``/``alpha`` are then its
            mean over the gradient's stops), or ``None`` for a solid colour.
    """

    rgb: tuple[float, float, float]
    alpha: float = 1.0
    gradient: str | None = None

    @property
    def luminance(self) -> float:
        """BT.601 luma of the colour (1 = white), before alpha."""
        return self.in_channel(LUMA_WEIGHTS)

    def in_channel(self, channel: Channel) -> float:
        """The colour's gray in a reading channel (red, green and blue weights; 1 = white),
        before alpha."""
        return sum(w * c for w, c in zip(channel, self.rgb))

    @property
    def black_or_white(self) -> bool:
        """Opaque solid black or white: the two paints of the paper's rasterizer."""
        return self.gradient is None and self.alpha >= 1.0 and self.rgb in ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))

    @property
    def ink_sign(self) -> int:
        """``+1`` for black, ``-1`` for white (only for :attr:`black_or_white` paints)."""
        return 1 if self.rgb == (0.0, 0.0, 0.0) else -1

    def with_alpha(self, factor: float) -> Paint:
        """This paint with its alpha multiplied by ``factor``."""
        return replace(self, alpha=self.alpha * factor)

    def describe(self) -> str:
        """``black``, ``white``, ``#rrggbb``, ``#rrggbbaa`` or ``url(#id) ~ #rrggbb``."""
        if self.black_or_white:
            return "black" if self.ink_sign > 0 else "white"
        hexa = "#" + "".join(f"{round(c * 255):02x}" for c in self.rgb)
        if self.alpha < 1.0:
            hexa += f"{round(self.alpha * 255):02x}"
        return f"url(#{self.gradient}) ~ {hexa}" if self.gradient else hexa


BLACK = Paint((0.0, 0.0, 0.0))
WHITE = Paint((1.0, 1.0, 1.0))

#: Resolves ``url(#id)`` to the gradient's mean paint (``None``: no gradient of that id).
UrlResolver = Callable[[str], "Paint | None"]


@dataclass(frozen=True)
class Style:
    """The computed style of one element (inherited values included).

    Attributes:
        fill, stroke: the paint, or ``None`` for ``none``; alpha not yet scaled by the
            opacities below.
        stroke_width: in the element's user units.
        linecap: ``butt``, ``round`` or ``square``.
        linejoin: ``miter``, ``round``, ``bevel`` (joins are drawn round; see docs).
        fill_rule: ``nonzero`` or ``evenodd``.
        color: what ``currentColor`` means here.
        fill_opacity, stroke_opacity: inherited opacities of each paint.
        opacity: the product of this element's and every enclosing element's ``opacity``.
        stroke_first: ``paint-order`` puts the stroke under the fill.
        shown: ``visibility`` (inherited; a child may set it back to visible).
        displayed: ``False`` under ``display="none"`` or zero ``opacity`` (whole subtree).
    """

    fill: Paint | None = BLACK
    stroke: Paint | None = None
    stroke_width: float = 1.0
    linecap: str = "butt"
    linejoin: str = "miter"
    fill_rule: str = "nonzero"
    color: Paint = BLACK
    fill_opacity: float = 1.0
    stroke_opacity: float = 1.0
    opacity: float = 1.0
    stroke_first: bool = False
    shown: bool = True
    displayed: bool = True

    @property
    def visible(self) -> bool:
        """Whether anything of the element is drawn."""
        return self.shown and self.displayed and bool(self.paints)

    @property
    def paints(self) -> list[tuple[str, Paint]]:
        """What is painted, bottom first (fill then stroke, unless ``paint-order`` says
        otherwise): ``[(mode, paint), ...]``, each paint's alpha scaled by its opacities."""
        out = []
        if self.fill is not None and self.fill_opacity * self.opacity > 0:
            out.append(("fill", self.fill.with_alpha(self.fill_opacity * self.opacity)))
        if self.stroke is not None and self.stroke_width > 0 and self.stroke_opacity * self.opacity > 0:
            out.append(("stroke", self.stroke.with_alpha(self.stroke_opacity * self.opacity)))
        return out[::-1] if self.stroke_first else out

    @property
    def palette(self) -> list[Paint]:
        """The paints' colours (opacities applied)."""
        return [paint for _, paint in self.paints]


def declarations(element_attrib: dict[str, str], style_attr: str | None) -> dict[str, str]:
    """Presentation attributes overridden by ``style=""`` declarations (CSS wins)."""
    props = {k: v for k, v in element_attrib.items() if "}" not in k}
    props.update(style_declarations(style_attr))
    return props


def style_declarations(style_attr: str | None) -> dict[str, str]:
    """The declarations of a ``style=""`` attribute, names lower-cased, ``!important`` dropped.

    Raises:
        ValueError: a declaration that is not ``name: value``.
    """
    props: dict[str, str] = {}
    if not style_attr:
        return props
    for decl in style_attr.split(";"):
        if not decl.strip():
            continue
        if ":" not in decl:
            raise ValueError(f"cannot read style declaration {decl.strip()!r}")
        name, value = decl.split(":", 1)
        props[name.strip().lower()] = re.sub(r"\s*!\s*important\s*$", "", value.strip(), flags=re.IGNORECASE)
    return props


#: A paint naming a paint server in the file: ``url(#id)``, then an optional fallback colour
#: (groups: the quote, the id, the fallback).
PAINT_URL = re.compile(r"^url\(\s*(['\"]?)#([^'\")\s]+)\1\s*\)\s*(.*)$", re.IGNORECASE)


def parse_colour(value: str, prop: str) -> Paint | None:
    """A CSS colour (``None`` for ``none``); ``currentColor`` is the caller's to resolve.

    Raises:
        ValueError: a value that is not a colour DeepMorph reads.
    """
    text = value.strip()
    if text.lower() == "none":
        return None
    colour = tinycss2.color4.parse_color(text)
    if colour is None or isinstance(colour, str):
        raise ValueError(f"{prop}={value!r}: not a colour (hex, rgb(), hsl(), a name, currentColor or none)")
    if colour.space not in _SRGB_SPACES:
        raise ValueError(f"{prop}={value!r}: the colour space {colour.space} is not supported (use sRGB: hex or rgb())")
    r, g, b, alpha = (float(c) for c in colour.to("srgb"))
    rgb = tuple(min(1.0, max(0.0, c)) for c in (r, g, b))
    alpha = min(1.0, max(0.0, alpha))
    return None if alpha <= 0 else Paint(rgb, alpha)  # type: ignore[arg-type]


def _paint(value: str, current: Paint, prop: str, urls: UrlResolver | None) -> Paint | None:
    text = value.strip()
    if text.lower() == "currentcolor":
        return current
    match = PAINT_URL.match(text)
    if match:
        paint = urls(match.group(2)) if urls is not None else None
        if paint is not None:
            return paint
        fallback = match.group(3).strip()
        if not fallback:
            raise ValueError(f"{prop}={value!r}: no gradient with id {match.group(2)!r} in the file")
        return _paint(fallback, current, prop, None)
    if text.lower().startswith("url("):
        raise ValueError(f"{prop}={value!r}: only url(#id) of a gradient in the same file is read (nothing is fetched)")
    return parse_colour(text, prop)


def _opacity(value: str, prop: str) -> float:
    text = value.strip()
    alpha = parse_number(text.rstrip("%"))
    if text.endswith("%"):
        alpha /= 100
    if not 0 <= alpha or alpha != alpha:
        raise ValueError(f"{prop}={value!r} is not an opacity")
    return min(alpha, 1.0)


def compute_style(props: dict[str, str], parent: Style, urls: UrlResolver | None = None) -> Style:
    """Apply one element's declarations on top of its parent's computed style.

    Only the properties this module reads are looked at; which others a drawing may hold is
    :mod:`deepmorph_core.svg.policy`'s decision. ``urls`` resolves ``url(#id)`` paints.

    Raises:
        ValueError: an unsupported value (the caller adds file and line).
    """
    style = replace(parent, opacity=parent.opacity)  # opacity is not inherited, it multiplies
    if "color" in props and props["color"].strip().lower() != "inherit":
        colour = _paint(props["color"], parent.color, "color", None)
        style = replace(style, color=colour if colour is not None else parent.color)
    for prop in ("fill", "stroke"):
        if prop in props and props[prop].strip().lower() != "inherit":
            style = replace(style, **{prop: _paint(props[prop], style.color, prop, urls)})
    if "stroke-width" in props and props["stroke-width"].strip() != "inherit":
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
    if "paint-order" in props:
        order = props["paint-order"].strip().lower().split()
        if order and order != ["normal"] and order[0] not in ("fill", "stroke", "markers"):
            raise ValueError(f"paint-order={props['paint-order']!r} is not a paint order")
        if order != ["inherit"]:
            painted = [p for p in order if p in ("fill", "stroke")]
            style = replace(style, stroke_first=bool(painted) and painted[0] == "stroke")
    shown, displayed = parent.shown, parent.displayed
    if props.get("visibility", "").strip() in ("hidden", "collapse"):
        shown = False
    elif props.get("visibility", "").strip() == "visible":
        shown = True
    if props.get("display", "").strip() == "none":
        displayed = False
    for prop, attr in (("fill-opacity", "fill_opacity"), ("stroke-opacity", "stroke_opacity")):
        if prop in props and props[prop].strip() != "inherit":
            style = replace(style, **{attr: _opacity(props[prop], prop)})
    opacity = parent.opacity
    if "opacity" in props and props["opacity"].strip() != "inherit":
        opacity *= _opacity(props["opacity"], "opacity")
        if opacity <= 0:
            displayed = False
    return replace(style, opacity=opacity, shown=shown, displayed=displayed)
