"""``<path>``: subpaths of segments whose kinds come from the registry.

Lines and arcs are built in (:mod:`deepmorph_primitives.segments`); other commands (Béziers)
need a plugin, and without one a path using them is an ``unsupported: path command C`` error.
Every distinct vertex is a control point; neighbouring segments share their end points, so a
morphed path stays connected.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from lxml import etree
from svg.path import Close, CubicBezier, Move, QuadraticBezier, parse_path
from torch import Tensor

from deepmorph_core.geometry import CAP_ROUND
from deepmorph_core.outline import Frame, Outline
from deepmorph_core.primitive import BasePrimitive, apply_affine, as_points, builder_for, cap_of
from deepmorph_core.protocols import ElementMorph, PathSegment
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import check_finite, format_number

_COMMAND_LETTERS = {CubicBezier: ("C", "S"), QuadraticBezier: ("Q", "T")}


@dataclass
class Subpath:
    """One ``M ...`` run: the index of its start point and its segments with point indices."""

    start: int
    segments: list[tuple[PathSegment, list[int]]] = field(default_factory=list)
    closed: bool = False


def parse_path_data(element: etree._Element, reader: ElementReader) -> tuple[np.ndarray, list[Subpath]]:
    """Read ``d`` into shared control points ``(n, 2)`` and subpaths of registered segments."""
    d = reader.text(element, "d")
    try:
        parsed = parse_path(d)
    except Exception as exc:  # svg.path raises several types for bad data
        reader.error(element, f"cannot read path data: {exc}")
    points: list[complex] = []
    subpaths: list[Subpath] = []
    current: Subpath | None = None
    for seg in parsed:
        if isinstance(seg, Move):
            points.append(seg.end)
            current = Subpath(len(points) - 1)
            subpaths.append(current)
            continue
        if current is None:
            reader.error(element, "path data must start with a moveto (M)")
        cls = reader.registry.segment_for(seg)
        if cls is None:
            reader.unsupported(element, f"path command {_command_letter(seg, d)} (install a plugin that handles it)")
        obj, added = cls.from_svgpath(seg, reader)
        last = current.segments[-1][1][-1] if current.segments else current.start
        if isinstance(seg, Close):
            current.segments.append((obj, [last, current.start]))
            current.closed = True
            current = Subpath(current.start)  # drawing may go on from the start point
            subpaths.append(current)
            continue
        indices = [last]
        for pt in added:
            points.append(pt)
            indices.append(len(points) - 1)
        current.segments.append((obj, indices))
    for pt in points:
        try:
            check_finite(pt.real, "coordinate")
            check_finite(pt.imag, "coordinate")
        except ValueError as exc:
            reader.error(element, f"path data: {exc}")
    if not points:
        reader.error(element, "path data is empty")
    return np.array([[p.real, p.imag] for p in points]), [s for s in subpaths if s.segments]


def _command_letter(seg: Any, d: str) -> str:
    letters = _COMMAND_LETTERS.get(type(seg))
    if letters is None:
        return type(seg).__name__
    letter = letters[1] if getattr(seg, "smooth", False) else letters[0]
    m = re.search(f"[{letter}{letter.lower()}]", d)
    return m.group(0) if m else letter


class Path(BasePrimitive):
    """A general path of registered segment kinds."""

    kind = "path"
    tags = ("path",)
    morphable = "every vertex and handle; arcs follow their chords"

    def __init__(self, points: np.ndarray, subpaths: list[Subpath], cap: int):
        self.points = points
        self.subpaths = subpaths
        self.cap = cap

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> Path | None:
        points, subpaths = parse_path_data(element, reader)
        if not subpaths:
            return None
        return cls(points, subpaths, cap_of(reader))

    def control_points(self) -> Tensor:
        return as_points(self.points)

    def outline(self, frame: Frame) -> Outline:
        b = builder_for(frame)
        for sub in self.subpaths:
            n = len(sub.segments)
            # rings (a second evaluation of every curve) only matter to fills
            ring = [frame.to_pixels(frame.local[:, sub.start : sub.start + 1])] if self.filled else None
            for k, (seg, idx) in enumerate(sub.segments):
                open_end = not sub.closed
                caps = (
                    self.cap if open_end and k == 0 else CAP_ROUND,
                    self.cap if open_end and k == n - 1 else CAP_ROUND,
                )
                pts = frame.local[:, idx]
                seg.add_pieces(b, frame, pts, caps)
                if ring is not None:
                    ring.append(seg.flatten(frame, pts))
            if ring is not None:
                b.ring(torch.cat(ring, 1))
        return b.build()

    def ink_reach(self) -> np.ndarray:
        """Per control point, the most any segment through it moves its ink per unit move (see
        :func:`deepmorph_core.morph.ink_reach`); segments that say nothing count 1."""
        reach = np.ones(len(self.points))
        for sub in self.subpaths:
            for seg, idx in sub.segments:
                method = getattr(seg, "ink_reach", None)
                if method is None:
                    continue
                for point, r in zip((idx[0], idx[-1]), method()):
                    reach[point] = max(reach[point], float(r))
        return reach

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        p = apply_affine(morph.matrix(), points)
        parts = []
        for sub in self.subpaths:
            parts.append(f"M{format_number(p[sub.start, 0])} {format_number(p[sub.start, 1])}")
            parts.extend(seg.to_d(p[idx], morph) for seg, idx in sub.segments)
        element.set("d", " ".join(parts))


class HalfCircle(BasePrimitive):
    """A path that is exactly one 180-degree circular arc, open or closed by its diameter.

    Its two diameter end points are the control points and the radius follows them, so a
    morphed half-circle is always a half-circle.
    """

    kind = "half-circle"
    tags = ("path",)
    priority = 10
    morphable = "2 diameter end points (radius follows)"

    def __init__(self, points: np.ndarray, sweep: bool, closed: bool, cap: int):
        self.points = points
        self.sweep = sweep
        self.closed = closed
        self.cap = cap

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> HalfCircle | None:
        try:
            segs = list(parse_path(reader.text(element, "d")))
        except Exception:
            return None  # the general path kind reports the error
        kinds = [type(s).__name__ for s in segs]
        if kinds not in (["Move", "Arc"], ["Move", "Arc", "Close"]):
            return None
        arc = segs[1]
        r, chord = arc.radius.real, abs(arc.end - arc.start)
        if r <= 0 or not math.isclose(r, arc.radius.imag, rel_tol=1e-3) or not math.isclose(chord, 2 * r, rel_tol=1e-2):
            return None
        pts = np.array([[arc.start.real, arc.start.imag], [arc.end.real, arc.end.imag]])
        if not np.isfinite(pts).all():
            return None
        return cls(pts, bool(arc.sweep), len(segs) == 3, cap_of(reader))

    def control_points(self) -> Tensor:
        return as_points(self.points)

    def ink_reach(self) -> np.ndarray:
        """The top of a half circle moves by ``|d0 + d1| / 2 + |d0 - d1| / 2``, at most sqrt(2)
        times its end points' move."""
        return np.full(2, math.sqrt(2.0))

    def outline(self, frame: Frame) -> Outline:
        b = builder_for(frame)
        p0, p1 = frame.local[:, 0], frame.local[:, 1]
        mid = (p0 + p1) / 2
        half = p0 - mid
        r = torch.sqrt((half * half).sum(-1) + 1e-12)
        theta0 = torch.atan2(half[:, 1], half[:, 0])
        dtheta = torch.full_like(theta0, math.pi if self.sweep else -math.pi)
        eye = torch.eye(2, dtype=r.dtype, device=r.device)
        linear = frame.linear @ (eye * r[:, None, None])
        centre = frame.to_pixels(mid[:, None])[:, 0]
        ring = b.arc(centre, linear, theta0, dtheta)
        if self.closed:
            px = frame.to_pixels(frame.local)
            b.line(px[:, 1], px[:, 0], CAP_ROUND, CAP_ROUND)
        b.ring(ring)
        return b.build()

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        p = apply_affine(morph.matrix(), points)
        r = float(np.linalg.norm(p[1] - p[0]) / 2)
        f = format_number
        d = f"M{f(p[0, 0])} {f(p[0, 1])} A{f(r)} {f(r)} 0 0 {int(self.sweep)} {f(p[1, 0])} {f(p[1, 1])}"
        element.set("d", d + (" Z" if self.closed else ""))
