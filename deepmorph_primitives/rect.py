"""``<rect>`` with optional rounded corners: two opposite corners are the control points,
so a morphed rect is still a rect (element rotation is written as a transform)."""

from __future__ import annotations

import math

import numpy as np
import torch
from lxml import etree
from torch import Tensor

from deepmorph_core.geometry import CAP_ROUND
from deepmorph_core.outline import Frame, Outline
from deepmorph_core.primitive import (
    BasePrimitive,
    append_transform,
    apply_affine,
    as_points,
    builder_for,
    rotate_about,
    without_rotation,
)
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import format_number


class Rect(BasePrimitive):
    """A rectangle from corner ``(x, y)`` to ``(x + width, y + height)``, corner radii rx/ry."""

    kind = "rect"
    tags = ("rect",)
    morphable = "2 opposite corners (stays a rectangle)"

    def __init__(self, corners: np.ndarray, rx: float, ry: float):
        self.corners = corners
        self.rx, self.ry = rx, ry

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> Rect | None:
        x, y = reader.length(element, "x", 0.0), reader.length(element, "y", 0.0)
        w, h = reader.length(element, "width", 0.0), reader.length(element, "height", 0.0)
        if w < 0 or h < 0:
            reader.error(element, "<rect> width and height must not be negative")
        if w == 0 or h == 0:
            return None
        rx, ry = reader.length(element, "rx", -1.0), reader.length(element, "ry", -1.0)
        rx, ry = (ry if rx < 0 else rx), (rx if ry < 0 else ry)
        rx, ry = max(rx, 0.0), max(ry, 0.0)
        return cls(np.array([[x, y], [x + w, y + h]]), min(rx, w / 2), min(ry, h / 2))

    def control_points(self) -> Tensor:
        return as_points(self.corners)

    def ink_reach(self) -> np.ndarray:
        """The other two corners take x from one control point and y from the other, so they
        move by up to sqrt(2) times the points' move."""
        return np.full(2, math.sqrt(2.0))

    def outline(self, frame: Frame) -> Outline:
        b = builder_for(frame)
        lo = torch.minimum(frame.local[:, 0], frame.local[:, 1])
        hi = torch.maximum(frame.local[:, 0], frame.local[:, 1])
        size = hi - lo
        rx = torch.minimum(torch.full_like(size[:, 0], self.rx), size[:, 0] / 2)
        ry = torch.minimum(torch.full_like(size[:, 1], self.ry), size[:, 1] / 2)
        x0, y0, x1, y1 = lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]
        P = lambda x, y: frame.to_pixels(torch.stack([x, y], -1)[:, None])[:, 0]  # noqa: E731
        # Clockwise (in SVG's y-down frame) from the top edge; each corner is a quarter arc.
        edges = [
            (P(x0 + rx, y0), P(x1 - rx, y0)),
            (P(x1, y0 + ry), P(x1, y1 - ry)),
            (P(x1 - rx, y1), P(x0 + rx, y1)),
            (P(x0, y1 - ry), P(x0, y0 + ry)),
        ]
        ring: list[Tensor] = []
        if self.rx > 0 and self.ry > 0:
            centres = [(x1 - rx, y0 + ry), (x1 - rx, y1 - ry), (x0 + rx, y1 - ry), (x0 + rx, y0 + ry)]
            starts = [-math.pi / 2, 0.0, math.pi / 2, math.pi]
            diag = torch.zeros(frame.local.shape[0], 2, 2, dtype=lo.dtype, device=lo.device)
            diag[:, 0, 0], diag[:, 1, 1] = rx, ry
            linear = frame.linear @ diag
            for (a, c), (cx, cy), t0 in zip(edges, centres, starts):
                b.line(a, c, CAP_ROUND, CAP_ROUND)
                ring.append(a[:, None])
                theta0 = torch.full_like(rx, t0)
                pts = b.arc(P(cx, cy), linear, theta0, torch.full_like(rx, math.pi / 2))
                ring.append(pts)
        else:
            for a, c in edges:
                b.line(a, c, CAP_ROUND, CAP_ROUND)
                ring.append(a[:, None])
        b.ring(torch.cat(ring, 1))
        return b.build()

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        p = apply_affine(without_rotation(morph).matrix(), points)
        lo, hi = p.min(0), p.max(0)
        for name, value in zip(("x", "y", "width", "height"), (lo[0], lo[1], *(hi - lo))):
            element.set(name, format_number(value))
        if self.rx > 0:
            element.set("rx", format_number(self.rx * morph.scale))
            element.set("ry", format_number(self.ry * morph.scale))
        rot = rotate_about(morph)
        if rot:
            append_transform(element, rot)
