"""``<linearGradient>`` and ``<radialGradient>``: read as their mean colour, written back whole.

The morph moves geometry only, so a gradient is written back exactly as drawn and a renderer
draws it over the morphed shape. The soft rasterizer paints a gradient-filled shape with the
gradient's mean colour: the average over its offsets of the colour its stops interpolate
(``stop-color`` with ``stop-opacity``). A gradient that inherits its stops (``href``) from
another is followed; a chain that comes back to itself is an error.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from lxml import etree

from deepmorph_core.svg.style import PAINT_URL, Paint, parse_colour, style_declarations

GRADIENT_TAGS = frozenset({"linearGradient", "radialGradient"})
XLINK_NS = "http://www.w3.org/1999/xlink"
#: Attributes a gradient keeps when written (geometry of the paint, its stops' link).
GRADIENT_ATTRIBUTES = frozenset(
    {"id", "x1", "y1", "x2", "y2", "cx", "cy", "r", "fx", "fy", "fr", "gradientUnits", "gradientTransform",
     "spreadMethod"}
)  # fmt: skip
STOP_ATTRIBUTES = frozenset({"offset", "stop-color", "stop-opacity"})
#: The most links followed from one gradient to the one it inherits stops from.
MAX_CHAIN = 32


class GradientError(ValueError):
    """A gradient DeepMorph cannot read; ``line`` is its line in the file."""

    def __init__(self, message: str, line: int | None):
        super().__init__(message)
        self.line = line


def href_of(element: etree._Element) -> str | None:
    """The id a gradient links to (``href`` or ``xlink:href`` of the form ``#id``)."""
    raw = element.get("href") or element.get(f"{{{XLINK_NS}}}href")
    if raw is None:
        return None
    raw = raw.strip()
    if not raw.startswith("#"):
        raise GradientError(f"unsupported: gradient href={raw[:60]!r} (only #id in the same file)", element.sourceline)
    return raw[1:]


@dataclass
class Gradients:
    """Every gradient of a document by id, with their mean paints (computed once, on demand).

    Attributes:
        elements: ``id -> <linearGradient>/<radialGradient>``.
        used: ids read through :meth:`paint` (with the ids they inherit from): what is written.
        others: ``id -> tag`` of every other element with an id (to name what a paint points at).
    """

    elements: dict[str, etree._Element] = field(default_factory=dict)
    used: list[str] = field(default_factory=list)
    others: dict[str, str] = field(default_factory=dict)
    stop_style: Callable[[etree._Element], dict[str, str]] | None = None
    _means: dict[str, Paint | None] = field(default_factory=dict)

    @classmethod
    def from_root(
        cls, root: etree._Element, stop_style: Callable[[etree._Element], dict[str, str]] | None = None
    ) -> Gradients:
        """Collect the gradients under ``root``; ``stop_style`` gives a ``<stop>``'s declarations
        from stylesheets (by default only its attributes and ``style=""`` count)."""
        found = cls(stop_style=stop_style)
        for el in root.iter():
            if isinstance(el.tag, str) and el.get("id"):
                tag = etree.QName(el).localname
                if tag in GRADIENT_TAGS:
                    found.elements.setdefault(el.get("id").strip(), el)
                else:
                    found.others.setdefault(el.get("id").strip(), tag)
        return found

    def missing_paint(self, value: str) -> str | None:
        """Why a paint ``url(#id)`` without a fallback cannot be read (a ``<pattern>`` or no
        element of that id), or ``None`` when it can (a gradient, a fallback, or no ``url``)."""
        match = PAINT_URL.match(value.strip())
        if match is None or match.group(3).strip() or match.group(2) in self.elements:
            return None
        what = self.others.get(match.group(2))
        if what is not None:
            return f"a <{what}> paint is not read: fill with a colour or a gradient"
        return f"no gradient with id {match.group(2)!r} in the file"

    def chain(self, gradient_id: str) -> list[str]:
        """``gradient_id`` and the ids it inherits from, in order.

        Raises:
            GradientError: a link to a missing id or one that comes back to itself.
        """
        out = [gradient_id]
        element = self.elements[gradient_id]
        while (target := href_of(element)) is not None:
            if target in out:
                raise GradientError(
                    f"gradient #{gradient_id} references itself ({' -> '.join('#' + i for i in [*out, target])})",
                    element.sourceline,
                )
            if target not in self.elements or len(out) > MAX_CHAIN:
                raise GradientError(f"gradient #{out[-1]} links to #{target}, which is not a gradient here",
                                    element.sourceline)  # fmt: skip
            out.append(target)
            element = self.elements[target]
        return out

    def paint(self, gradient_id: str) -> Paint | None:
        """The gradient's mean paint, or ``None`` when no gradient has that id (a gradient without
        stops paints nothing: a transparent paint then).

        Raises:
            GradientError: a broken link or an unreadable stop, with the line.
        """
        if gradient_id not in self.elements:
            return None
        if gradient_id not in self._means:
            chain = self.chain(gradient_id)
            stops: list[etree._Element] = []
            for link in chain:  # stops come from the first gradient in the chain that has any
                element = self.elements[link]
                stops = [s for s in element if isinstance(s.tag, str) and etree.QName(s).localname == "stop"]
                if stops:
                    break
            self._means[gradient_id] = self._mean(gradient_id, stops)
            for link in chain:
                if link not in self.used:
                    self.used.append(link)
        mean = self._means[gradient_id]
        return mean if mean is not None else Paint((0.0, 0.0, 0.0), 0.0, gradient_id)

    def _mean(self, gradient_id: str, stops: list[etree._Element]) -> Paint | None:
        points: list[tuple[float, tuple[float, float, float], float]] = []
        last = 0.0
        for stop in stops:
            props = {k: v for k, v in stop.attrib.items() if "}" not in k}
            if self.stop_style is not None:
                props.update(self.stop_style(stop))
            props.update(style_declarations(stop.get("style")))
            try:
                offset = _fraction(props.get("offset", "0"))
                colour = parse_colour(props.get("stop-color", "black"), "stop-color")
                opacity = _fraction(props.get("stop-opacity", "1"))
            except ValueError as exc:
                raise GradientError(f"gradient #{gradient_id}: {exc}", stop.sourceline) from None
            last = max(last, offset)  # offsets never go back (SVG clamps them to the largest so far)
            rgb = colour.rgb if colour is not None else (0.0, 0.0, 0.0)
            alpha = (colour.alpha if colour is not None else 0.0) * opacity
            points.append((last, rgb, alpha))
        if not points:
            return None
        if len(points) == 1:
            _, rgb, alpha = points[0]
            return Paint(rgb, alpha, gradient_id)
        # average of the piecewise-linear colour over [0, 1], premultiplied by alpha
        spans = [(0.0, points[0][1], points[0][2], points[0][0], points[0][1], points[0][2])]
        spans += [(a[0], a[1], a[2], b[0], b[1], b[2]) for a, b in zip(points, points[1:])]
        spans.append((points[-1][0], points[-1][1], points[-1][2], 1.0, points[-1][1], points[-1][2]))
        acc = [0.0, 0.0, 0.0]
        alpha_acc = 0.0
        for t0, c0, a0, t1, c1, a1 in spans:
            width = max(0.0, t1 - t0)
            for k in range(3):
                acc[k] += width * (c0[k] * a0 + c1[k] * a1) / 2
            alpha_acc += width * (a0 + a1) / 2
        if alpha_acc <= 0:
            return Paint((0.0, 0.0, 0.0), 0.0, gradient_id)
        rgb = tuple(min(1.0, max(0.0, c / alpha_acc)) for c in acc)
        return Paint(rgb, min(1.0, alpha_acc), gradient_id)  # type: ignore[arg-type]


def _fraction(value: str) -> float:
    text = value.strip()
    try:
        number = float(text[:-1]) / 100 if text.endswith("%") else float(text)
    except ValueError:
        raise ValueError(f"{text[:40]!r} is not a number") from None
    if number != number:
        raise ValueError(f"{text[:40]!r} is not a number")
    return min(1.0, max(0.0, number))
