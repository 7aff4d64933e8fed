"""``<line>``: two end points."""

from __future__ import annotations

import numpy as np
from lxml import etree
from torch import Tensor

from deepmorph_core.outline import Frame, Outline
from deepmorph_core.primitive import BasePrimitive, apply_affine, as_points, builder_for, cap_of
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import format_number


class Line(BasePrimitive):
    """A straight stroked segment; a zero-length line with round caps is a dot."""

    kind = "line"
    tags = ("line",)
    morphable = "2 end points"

    def __init__(self, points: np.ndarray, cap: int):
        self.points = points
        self.cap = cap

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> Line:
        pts = [
            [reader.number(element, "x1", 0.0), reader.number(element, "y1", 0.0)],
            [reader.number(element, "x2", 0.0), reader.number(element, "y2", 0.0)],
        ]
        return cls(np.asarray(pts), cap_of(reader))

    def control_points(self) -> Tensor:
        return as_points(self.points)

    def outline(self, frame: Frame) -> Outline:
        px = frame.to_pixels(frame.local)
        b = builder_for(frame)
        b.line(px[:, 0], px[:, 1], self.cap, self.cap)
        return b.build()

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        p = apply_affine(morph.matrix(), points)
        for (x, y), (nx, ny) in zip((("x1", "y1"), ("x2", "y2")), p):
            element.set(x, format_number(nx))
            element.set(y, format_number(ny))
