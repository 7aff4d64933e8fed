"""``<circle>`` and ``<ellipse>``: the centre is the control point; element scale and
rotation act on the radii."""

from __future__ import annotations

import numpy as np
from lxml import etree
from torch import Tensor

from deepmorph_core.outline import Frame, Outline
from deepmorph_core.primitive import (
    BasePrimitive,
    append_transform,
    apply_affine,
    as_points,
    builder_for,
    circle_linear,
    rotate_about,
    unit_circle,
    without_rotation,
)
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import format_number


class Ellipse(BasePrimitive):
    """An axis-aligned ellipse (in its own units) with radii ``rx``, ``ry``."""

    kind = "ellipse"
    tags = ("ellipse",)
    morphable = "centre (radii follow element scale)"

    def __init__(self, centre: np.ndarray, rx: float, ry: float):
        self.centre = centre
        self.rx, self.ry = rx, ry

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> Ellipse | None:
        c = np.array([[reader.length(element, "cx", 0.0), reader.length(element, "cy", 0.0)]])
        rx, ry = reader.length(element, "rx", -1.0), reader.length(element, "ry", -1.0)
        if rx < 0 and ry < 0:
            reader.error(element, "<ellipse> needs rx or ry")
        rx, ry = (ry if rx < 0 else rx), (rx if ry < 0 else ry)
        if rx == 0 or ry == 0:
            return None  # SVG draws nothing; the parser records it as invisible
        return cls(c, rx, ry)

    def control_points(self) -> Tensor:
        return as_points(self.centre)

    def outline(self, frame: Frame) -> Outline:
        b = builder_for(frame)
        centre = frame.to_pixels(frame.local)[:, 0]
        linear = circle_linear(frame, self.rx, self.ry).expand(centre.shape[0], 2, 2)
        theta0, dtheta = unit_circle(centre.dtype, centre.device)
        B = centre.shape[0]
        ring = b.arc(centre, linear, theta0.expand(B), dtheta.expand(B))
        b.ring(ring[:, :-1])
        return b.build()

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        c = apply_affine(without_rotation(morph).matrix(), points)[0]
        element.set("cx", format_number(c[0]))
        element.set("cy", format_number(c[1]))
        self._write_radii(element, morph.scale)
        rot = rotate_about(morph)
        if rot:
            append_transform(element, rot)

    def _write_radii(self, element: etree._Element, scale: float) -> None:
        element.set("rx", format_number(self.rx * scale))
        element.set("ry", format_number(self.ry * scale))


class Circle(Ellipse):
    """A circle of radius ``r``."""

    kind = "circle"
    tags = ("circle",)
    morphable = "centre (radius follows element scale)"

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> Circle | None:
        c = np.array([[reader.length(element, "cx", 0.0), reader.length(element, "cy", 0.0)]])
        r = reader.length(element, "r")
        if r < 0:
            reader.error(element, f"r={r:g} is negative")
        if r == 0:
            return None
        return cls(c, r, r)

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        c = apply_affine(morph.matrix(), points)[0]
        element.set("cx", format_number(c[0]))
        element.set("cy", format_number(c[1]))
        element.set("r", format_number(self.rx * morph.scale))
