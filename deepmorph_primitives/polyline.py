"""``<polyline>`` (open) and ``<polygon>`` (closed): every vertex is a control point."""

from __future__ import annotations

import numpy as np
from lxml import etree
from torch import Tensor

from deepmorph_core.outline import Frame, Outline
from deepmorph_core.primitive import BasePrimitive, add_polyline, apply_affine, as_points, builder_for, cap_of
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import format_number


class Polyline(BasePrimitive):
    """An open chain of segments with round joins; its fill (if any) closes implicitly."""

    kind = "polyline"
    tags = ("polyline",)
    morphable = "every vertex"
    closed = False

    def __init__(self, points: np.ndarray, cap: int):
        self.points = points
        self.cap = cap

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> Polyline:
        return cls(reader.points(element), cap_of(reader))

    def control_points(self) -> Tensor:
        return as_points(self.points)

    def outline(self, frame: Frame) -> Outline:
        b = builder_for(frame)
        add_polyline(b, frame.to_pixels(frame.local), self.closed, self.cap)
        return b.build()

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        p = apply_affine(morph.matrix(), points)
        element.set("points", " ".join(f"{format_number(x)},{format_number(y)}" for x, y in p))


class Polygon(Polyline):
    """A closed chain of segments (no caps)."""

    kind = "polygon"
    tags = ("polygon",)
    closed = True
