"""Built-in ``<path>`` segment kinds: straight lines (``L H V Z``) and elliptical arcs (``A``).

They register as path segments through the same hook as third-party segment kinds such as
the Bézier plugin's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from svg.path import Arc as SvgArc
from svg.path import Close as SvgClose
from svg.path import Line as SvgLine
from torch import Tensor

from deepmorph_core import geometry as G
from deepmorph_core.outline import Frame, OutlineBuilder
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import format_number


class LineSegment:
    """A straight path segment; ``Z`` is a line back to the subpath start, written as ``Z``."""

    kind = "path-line"
    commands = "LlHhVvZz"
    svgpath_types = (SvgLine, SvgClose)
    morphable = "end point (shared with the next segment)"

    def __init__(self, closing: bool = False):
        self.closing = closing

    @classmethod
    def from_svgpath(cls, segment: Any, reader: ElementReader) -> tuple[LineSegment, list[complex]]:
        return cls(isinstance(segment, SvgClose)), [segment.end]

    def add_pieces(self, builder: OutlineBuilder, frame: Frame, points: Tensor, caps: tuple[int, int]) -> None:
        px = frame.to_pixels(points)
        builder.line(px[:, 0], px[:, 1], caps[0], caps[1])

    def flatten(self, frame: Frame, points: Tensor) -> Tensor:
        return frame.to_pixels(points[:, 1:])

    def to_d(self, points: np.ndarray, morph: ElementMorph) -> str:
        if self.closing:
            return "Z"
        return f"L{format_number(points[1, 0])} {format_number(points[1, 1])}"


class ArcSegment:
    """An elliptical arc; its end points morph, radii and flags stay (radii follow element
    scale), and the centre is recomputed as SVG renderers do."""

    kind = "path-arc"
    commands = "Aa"
    svgpath_types = (SvgArc,)
    morphable = "end point; radii follow element scale"

    def __init__(self, rx: float, ry: float, rotation: float, large_arc: bool, sweep: bool):
        self.rx, self.ry, self.rotation = abs(rx), abs(ry), rotation
        self.large_arc, self.sweep = large_arc, sweep

    @classmethod
    def from_svgpath(cls, segment: Any, reader: ElementReader) -> tuple[ArcSegment, list[complex]]:
        return (
            cls(segment.radius.real, segment.radius.imag, segment.rotation, bool(segment.arc), bool(segment.sweep)),
            [segment.end],
        )

    @property
    def is_straight(self) -> bool:
        """Zero radii make an arc a straight line (SVG F.6.2)."""
        return self.rx == 0 or self.ry == 0

    def centre_form(self, frame: Frame, points: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Pixel-space centre, unit-circle map, start angle and sweep of the arc, batched."""
        p0, p1 = points[:, 0], points[:, 1]
        like = p0[:, 0]
        phi = torch.full_like(like, math.radians(self.rotation))
        centre, rx, ry, theta0, dtheta = G.endpoint_to_center(
            p0, p1, torch.full_like(like, self.rx), torch.full_like(like, self.ry), phi,
            torch.full_like(like, float(self.large_arc)), torch.full_like(like, float(self.sweep)),
        )
        linear = frame.linear @ G.ellipse_linear(rx, ry, phi)
        return frame.to_pixels(centre[:, None])[:, 0], linear, theta0, dtheta

    def add_pieces(self, builder: OutlineBuilder, frame: Frame, points: Tensor, caps: tuple[int, int]) -> None:
        if self.is_straight:
            px = frame.to_pixels(points)
            builder.line(px[:, 0], px[:, 1], caps[0], caps[1])
            return
        builder.arc(*self.centre_form(frame, points))

    def flatten(self, frame: Frame, points: Tensor) -> Tensor:
        if self.is_straight:
            return frame.to_pixels(points[:, 1:])
        centre, linear, theta0, dtheta = self.centre_form(frame, points)
        pts = G.flatten_arc(centre[:, None], linear[:, None], theta0[:, None], dtheta[:, None], 24)[:, 0]
        return pts[:, 1:]

    def to_d(self, points: np.ndarray, morph: ElementMorph) -> str:
        f = format_number
        return (
            f"A{f(self.rx * morph.scale)} {f(self.ry * morph.scale)} {f(self.rotation + morph.rotate)} "
            f"{int(self.large_arc)} {int(self.sweep)} {f(points[1, 0])} {f(points[1, 1])}"
        )
