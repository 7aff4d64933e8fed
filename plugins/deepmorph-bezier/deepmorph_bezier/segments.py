"""Cubic (``C c S s``) and quadratic (``Q q T t``) Bézier ``<path>`` segments.

Both are drawn the same way: the curve is evaluated in Bernstein form on its control points
mapped to pixels (Béziers are affine-invariant, so mapping the control points is mapping the
curve) and cut into line pieces that the core strokes and fills like any polyline. The number
of pieces follows Wang's formula, which bounds the distance between the curve and its
uniform-parameter polyline by ``d (d - 1) / 8 * max|P[i] - 2 P[i+1] + P[i+2]| / n**2`` for a
degree-``d`` curve; that keeps the polyline within :attr:`_BezierSegment.tolerance_px` of the
true curve without over-cutting short or flat curves.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np
import torch
from svg.path import CubicBezier as SvgCubicBezier
from svg.path import QuadraticBezier as SvgQuadraticBezier
from torch import Tensor

from deepmorph_core.geometry import CAP_ROUND
from deepmorph_core.outline import Frame, OutlineBuilder
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import format_number


@lru_cache(maxsize=256)
def _bernstein_table(degree: int, pieces: int) -> np.ndarray:
    """Bernstein weights at ``pieces + 1`` evenly spaced parameters (float64, cached and
    read-only; :func:`bernstein_weights` hands out tensor copies).

    Shape:
        ``(pieces + 1, degree + 1)``; row ``i`` holds ``C(d, k) t^k (1 - t)^(d - k)`` at
        ``t = i / pieces``. The first and last rows are exactly ``e_0`` and ``e_d``.
    """
    t = np.linspace(0.0, 1.0, pieces + 1)[:, None]
    k = np.arange(degree + 1)[None, :]
    binom = np.array([math.comb(degree, i) for i in range(degree + 1)], dtype=np.float64)[None, :]
    table = binom * t**k * (1.0 - t) ** (degree - k)
    table.setflags(write=False)
    return table


def bernstein_weights(degree: int, pieces: int, dtype: torch.dtype, device: torch.device) -> Tensor:
    """Constant Bernstein weights for evaluating a degree-``degree`` curve at ``pieces + 1`` points.

    Shape:
        ``(pieces + 1, degree + 1)``.
    """
    return torch.tensor(_bernstein_table(degree, pieces), dtype=dtype, device=device)


def evaluate_bezier(control: Tensor, pieces: int) -> Tensor:
    """Points of Bézier curves at ``pieces + 1`` evenly spaced parameters, differentiably.

    Args:
        control: control points, start first and end last (degree = count - 1).
        pieces: number of parameter steps.

    Shape:
        control ``(B, d + 1, 2)`` -> ``(B, pieces + 1, 2)``; the first and last points are the
        start and end control points exactly (so consecutive segments stay joined).
    """
    weights = bernstein_weights(control.shape[1] - 1, pieces, control.dtype, control.device)
    return torch.einsum("mk,bkd->bmd", weights, control)


def wang_piece_count(control: Tensor, tolerance: float, min_pieces: int, max_pieces: int) -> int:
    """How many uniform pieces keep the polyline within ``tolerance`` of every curve in the batch.

    Wang's formula ``n = ceil(sqrt(d (d - 1) / 8 * M / tolerance))`` with ``M`` the largest
    second difference of the control polygon, taken over the whole batch (one count for the
    batch keeps tensor shapes static). Computed without gradient: it only picks a resolution.

    Args:
        control: control points, in the units of ``tolerance`` (pixels).
        tolerance: allowed distance between curve and polyline.
        min_pieces, max_pieces: clamp on the result.

    Shape:
        control ``(B, d + 1, 2)``.
    """
    degree = control.shape[1] - 1
    if degree < 2:
        return min_pieces
    with torch.no_grad():
        second = control[:, :-2] - 2.0 * control[:, 1:-1] + control[:, 2:]
        largest = float(torch.linalg.vector_norm(second, dim=-1).amax()) if second.numel() else 0.0
    if not math.isfinite(largest):
        return max_pieces
    n = math.ceil(math.sqrt(degree * (degree - 1) / 8.0 * largest / tolerance))
    return max(min_pieces, min(max_pieces, n))


class _BezierSegment:
    """Shared behaviour of Bézier segments of any degree.

    Class attributes:
        degree: polynomial degree (number of points the segment adds).
        letter: the absolute command letter written back (``C`` or ``Q``).
        tolerance_px: target distance between the drawn polyline and the true curve.
        min_pieces, max_pieces: clamp on the number of line pieces per segment.
    """

    kind: ClassVar[str]
    commands: ClassVar[str]
    svgpath_types: ClassVar[tuple[type, ...]]
    morphable: ClassVar[str]
    degree: ClassVar[int]
    letter: ClassVar[str]
    tolerance_px: ClassVar[float] = 0.05
    min_pieces: ClassVar[int] = 4
    max_pieces: ClassVar[int] = 48

    def __init__(self, smooth: bool = False):
        #: Whether it was read from a smooth command (``S``/``T``); informational only, since
        #: it is always written back with explicit handles.
        self.smooth = smooth

    def __repr__(self) -> str:
        return f"{type(self).__name__}(smooth={self.smooth})"

    def pixel_curve(self, frame: Frame, points: Tensor) -> Tensor:
        """Points along the curve in pixels, start and end included.

        Shape:
            points ``(B, degree + 1, 2)`` local units -> ``(B, n + 1, 2)`` pixels, with ``n``
            from :func:`wang_piece_count`.
        """
        px = frame.to_pixels(points)
        n = wang_piece_count(px, self.tolerance_px, self.min_pieces, self.max_pieces)
        return evaluate_bezier(px, n)

    def add_pieces(self, builder: OutlineBuilder, frame: Frame, points: Tensor, caps: tuple[int, int]) -> None:
        """Add the curve as line pieces; only its two ends get ``caps``, interior joins are round.

        Shape:
            points ``(B, degree + 1, 2)`` local units: the start point then the added points.
        """
        curve = self.pixel_curve(frame, points)
        last = curve.shape[1] - 2
        for i in range(last + 1):
            builder.line(
                curve[:, i],
                curve[:, i + 1],
                caps[0] if i == 0 else CAP_ROUND,
                caps[1] if i == last else CAP_ROUND,
            )

    def flatten(self, frame: Frame, points: Tensor) -> Tensor:
        """Pixel points along the curve without its start (for fill rings).

        Shape:
            points ``(B, degree + 1, 2)`` -> ``(B, n, 2)``.
        """
        return self.pixel_curve(frame, points)[:, 1:]

    def to_d(self, points: np.ndarray, morph: ElementMorph) -> str:
        """Absolute ``C``/``Q`` path data for ``(degree + 1, 2)`` already-morphed points.

        Smooth input is written with explicit handles: once morphed, they are no longer
        reflections of the previous segment's.
        """
        coords = " ".join(f"{format_number(x)} {format_number(y)}" for x, y in points[1:])
        return f"{self.letter}{coords}"


class CubicBezierSegment(_BezierSegment):
    """A cubic Bézier (``C c S s``): two handles and an end point, all morphable."""

    kind = "cubic-bezier"
    commands = "CcSs"
    svgpath_types = (SvgCubicBezier,)
    morphable = "both handles and end point (shared with the next segment)"
    degree = 3
    letter = "C"

    @classmethod
    def from_svgpath(cls, segment: Any, reader: ElementReader) -> tuple[CubicBezierSegment, list[complex]]:
        """Read an ``svg.path`` cubic (relative and smooth forms already resolved by it).

        Returns:
            The segment and its added points ``[control1, control2, end]``.
        """
        return cls(bool(getattr(segment, "smooth", False))), [segment.control1, segment.control2, segment.end]


class QuadraticBezierSegment(_BezierSegment):
    """A quadratic Bézier (``Q q T t``): one handle and an end point, both morphable."""

    kind = "quadratic-bezier"
    commands = "QqTt"
    svgpath_types = (SvgQuadraticBezier,)
    morphable = "handle and end point (shared with the next segment)"
    degree = 2
    letter = "Q"

    @classmethod
    def from_svgpath(cls, segment: Any, reader: ElementReader) -> tuple[QuadraticBezierSegment, list[complex]]:
        """Read an ``svg.path`` quadratic (relative and smooth forms already resolved by it).

        Returns:
            The segment and its added points ``[control, end]``.
        """
        return cls(bool(getattr(segment, "smooth", False))), [segment.control, segment.end]
