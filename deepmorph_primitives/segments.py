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
    scale), and the centre is recomputed as SVG renderers do.

    An arc drawn as (almost) exactly half an ellipse is special: SVG's centre formula has a
    square-root singularity there, so a tiny move of an end point would swing the centre and
    the gradient would explode. Such arcs *follow the chord* instead: the centre stays at the
    midpoint and the radii scale with the chord (written back scaled), so they stay halves.
    """

    kind = "path-arc"
    commands = "Aa"
    svgpath_types = (SvgArc,)
    morphable = "end point; radii follow element scale"

    def __init__(self, rx: float, ry: float, rotation: float, large_arc: bool, sweep: bool, follow_chord: bool = False):
        self.rx, self.ry, self.rotation = abs(rx), abs(ry), rotation
        self.large_arc, self.sweep = large_arc, sweep
        self.follow_chord = follow_chord

    @classmethod
    def from_svgpath(cls, segment: Any, reader: ElementReader) -> tuple[ArcSegment, list[complex]]:
        arc = cls(segment.radius.real, segment.radius.imag, segment.rotation, bool(segment.arc), bool(segment.sweep))
        if not arc.is_straight:
            p = np.array([[segment.start.real, segment.start.imag], [segment.end.real, segment.end.imag]])
            arc.follow_chord = abs(arc._radius_scale(p) - 1.0) < 0.01
        return arc, [segment.end]

    def _radius_scale(self, points: np.ndarray) -> float:
        """sqrt(lambda) of SVG F.6.6: how much the radii must grow to span the end points."""
        half = (points[0] - points[1]) / 2
        c, s = math.cos(math.radians(self.rotation)), math.sin(math.radians(self.rotation))
        x, y = c * half[0] + s * half[1], -s * half[0] + c * half[1]
        return math.sqrt((x / self.rx) ** 2 + (y / self.ry) ** 2)

    @property
    def is_straight(self) -> bool:
        """Zero radii make an arc a straight line (SVG F.6.2)."""
        return self.rx == 0 or self.ry == 0

    def centre_form(self, frame: Frame, points: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Pixel-space centre, unit-circle map, start angle and sweep of the arc, batched."""
        p0, p1 = points[:, 0], points[:, 1]
        like = p0[:, 0]
        phi = torch.full_like(like, math.radians(self.rotation))
        if self.follow_chord:
            centre = (p0 + p1) / 2
            c, s = math.cos(math.radians(self.rotation)), math.sin(math.radians(self.rotation))
            half = p0 - centre
            x = (c * half[:, 0] + s * half[:, 1]) / self.rx
            y = (-s * half[:, 0] + c * half[:, 1]) / self.ry
            scale = torch.sqrt(x * x + y * y + 1e-12)
            rx, ry = self.rx * scale, self.ry * scale
            theta0 = torch.atan2(y / scale, x / scale)
            dtheta = torch.full_like(like, math.pi if self.sweep else -math.pi)
            linear = frame.linear @ G.ellipse_linear(rx, ry, phi)
            return frame.to_pixels(centre[:, None])[:, 0], linear, theta0, dtheta
        centre, rx, ry, theta0, dtheta = G.endpoint_to_center(
            p0,
            p1,
            torch.full_like(like, self.rx),
            torch.full_like(like, self.ry),
            phi,
            torch.full_like(like, float(self.large_arc)),
            torch.full_like(like, float(self.sweep)),
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
        grow = 1.0
        if self.follow_chord:  # radii follow the (already morphed) chord
            grow = ArcSegment(
                self.rx * morph.scale, self.ry * morph.scale, self.rotation + morph.rotate, self.large_arc, self.sweep
            )._radius_scale(points)
        return (
            f"A{f(self.rx * morph.scale * grow)} {f(self.ry * morph.scale * grow)} {f(self.rotation + morph.rotate)} "
            f"{int(self.large_arc)} {int(self.sweep)} {f(points[1, 0])} {f(points[1, 1])}"
        )
