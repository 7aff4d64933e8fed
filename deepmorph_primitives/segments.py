"""Built-in ``<path>`` segment kinds: straight lines (``L H V Z``) and elliptical arcs (``A``).

They register as path segments through the same hook as third-party segment kinds such as
the Bézier plugin's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from svg.path import Arc as SvgArc
from svg.path import Close as SvgClose
from svg.path import Line as SvgLine
from torch import Tensor

from deepmorph_core import geometry as G
from deepmorph_core.outline import Frame, OutlineBuilder
from deepmorph_core.primitive import apply_affine
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


@dataclass(frozen=True)
class RestArc:
    """An arc's rest pose in centre form (local units), for arcs that follow their chord."""

    start: np.ndarray
    end: np.ndarray
    centre: np.ndarray
    rx: float
    ry: float
    theta0: float
    dtheta: float
    exact_half: bool

    @classmethod
    def of(cls, arc: ArcSegment, p: np.ndarray) -> RestArc:
        t = torch.as_tensor(p, dtype=torch.float64)
        one = torch.ones((), dtype=torch.float64)
        centre, rx, ry, theta0, dtheta = G.endpoint_to_center(
            t[0],
            t[1],
            one * arc.rx,
            one * arc.ry,
            one * math.radians(arc.rotation),
            one * float(arc.large_arc),
            one * float(arc.sweep),
        )
        exact = abs(arc._radius_scale(p) - 1.0) < 1e-6 or float(rx) > arc.rx * (1 + 1e-9)
        return cls(p[0], p[1], centre.numpy(), float(rx), float(ry), float(theta0), float(dtheta), exact)


class ArcSegment:
    """An elliptical arc whose end points morph.

    In morph geometry 2 (:data:`~deepmorph_core.svg.reader.GEOMETRY_VERSION`) every arc *follows
    its chord*: it moves as the similarity that takes its rest chord onto the morphed chord
    (centre, radii and axis angle included), so its shape is kept and its ink moves boundedly
    (:meth:`ink_reach`). At rest it is exactly the arc in the file, the map is smooth, and it is
    written back with the radii and angle scaled and turned by that similarity, which SVG's own
    centre formula reproduces.

    In geometry 1 (older bundles) an arc keeps its radii and flags (radii follow element scale)
    and its centre is recomputed as SVG renderers do, except arcs of (nearly) half an ellipse,
    which follow their chord there too: SVG's centre formula has a square-root singularity at
    exactly half, where a tiny move of an end point swings the centre and the gradient explodes.
    """

    kind = "path-arc"
    commands = "Aa"
    svgpath_types = (SvgArc,)
    morphable = "end point; the arc follows its chord"

    #: |sqrt(lambda) - 1| below which an arc follows its chord.
    NEAR_HALF = 0.02

    def __init__(self, rx: float, ry: float, rotation: float, large_arc: bool, sweep: bool):
        self.rx, self.ry, self.rotation = abs(rx), abs(ry), rotation
        self.large_arc, self.sweep = large_arc, sweep
        self.rest: RestArc | None = None

    @classmethod
    def from_svgpath(cls, segment: Any, reader: ElementReader) -> tuple[ArcSegment, list[complex]]:
        arc = cls(segment.radius.real, segment.radius.imag, segment.rotation, bool(segment.arc), bool(segment.sweep))
        p = np.array([[segment.start.real, segment.start.imag], [segment.end.real, segment.end.imag]])
        near_half = not arc.is_straight and abs(arc._radius_scale(p) - 1.0) < cls.NEAR_HALF
        follows = near_half or (reader.geometry >= 2 and not arc.is_straight)
        if follows and np.linalg.norm(p[1] - p[0]) > 1e-9:
            arc.rest = RestArc.of(arc, p)
        return arc, [segment.end]

    def ink_reach(self) -> tuple[float, float]:
        """How far the arc's ink moves, at most, per unit move of its two end points.

        An arc that follows its chord moves every point ``z`` by ``d0 + w (d1 - d0)`` with
        ``w = (z - p0) / (p1 - p0)`` (complex numbers), so by at most ``|1 - w| + |w|`` times the
        end points' move: 1 on the chord, about 1.41 at the top of a half circle, more for arcs
        that bulge further. Arcs that keep their radius have no such bound (1 is claimed).
        """
        r = self.rest
        if r is None:
            return (1.0, 1.0)
        t = r.theta0 + np.linspace(0.0, 1.0, 65) * r.dtheta
        c, s = math.cos(math.radians(self.rotation)), math.sin(math.radians(self.rotation))
        ex, ey = r.rx * np.cos(t), r.ry * np.sin(t)
        z = (r.centre[0] + c * ex - s * ey) + 1j * (r.centre[1] + s * ex + c * ey)
        p0, p1 = complex(*r.start), complex(*r.end)
        w = (z - p0) / (p1 - p0)
        reach = float(np.max(np.abs(1 - w) + np.abs(w)))
        return (max(reach, 1.0), max(reach, 1.0))

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

    def _chord_similarity(self, points: Tensor) -> tuple[Tensor, Tensor]:
        """``scale * R`` ``(B, 2, 2)`` taking the rest chord onto the current one, and the
        current centre ``(B, 2)`` (local units)."""
        assert self.rest is not None
        rest_chord = self.rest.end - self.rest.start
        chord = points[:, 1] - points[:, 0]
        denom = float(rest_chord @ rest_chord)  # chord / rest_chord as complex numbers
        re = (chord[:, 0] * rest_chord[0] + chord[:, 1] * rest_chord[1]) / denom
        im = (chord[:, 1] * rest_chord[0] - chord[:, 0] * rest_chord[1]) / denom
        rot = torch.stack([torch.stack([re, -im], -1), torch.stack([im, re], -1)], -2)
        offset = torch.as_tensor(self.rest.centre - self.rest.start, dtype=points.dtype, device=points.device)
        return rot, points[:, 0] + torch.einsum("bkl,l->bk", rot, offset)

    def centre_form(self, frame: Frame, points: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Pixel-space centre, unit-circle map, start angle and sweep of the arc, batched."""
        p0, p1 = points[:, 0], points[:, 1]
        like = p0[:, 0]
        phi = torch.full_like(like, math.radians(self.rotation))
        if self.rest is not None:
            r = self.rest
            rot, centre = self._chord_similarity(points)
            unit_map = rot @ G.ellipse_linear(torch.full_like(like, r.rx), torch.full_like(like, r.ry), phi)
            return (
                frame.to_pixels(centre[:, None])[:, 0],
                frame.linear @ unit_map,
                torch.full_like(like, r.theta0),
                torch.full_like(like, r.dtheta),
            )
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
        scale, angle = morph.scale, self.rotation + morph.rotate
        if self.rest is not None:  # the similarity of the chord, measured on the written points
            rest = apply_affine(morph.matrix(), np.stack([self.rest.start, self.rest.end]))
            before, after = rest[1] - rest[0], points[1] - points[0]
            scale *= float(np.hypot(*after) / np.hypot(*before))
            angle += math.degrees(math.atan2(after[1], after[0]) - math.atan2(before[1], before[0]))
        rx, ry = self.rx * scale, self.ry * scale
        if self.rest is not None and self.rest.exact_half:
            # Round the radii down: a renderer then scales them up to span the chord exactly and
            # puts the centre on it. Rounding up would leave it where SVG's formula is singular.
            rx, ry = math.floor(rx * 1e4) / 1e4, math.floor(ry * 1e4) / 1e4
        return (
            f"A{f(rx)} {f(ry)} {f(angle)} {int(self.large_arc)} {int(self.sweep)} {f(points[1, 0])} {f(points[1, 1])}"
        )
