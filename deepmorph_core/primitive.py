"""Helpers for primitive authors: a base class holding what the parser sets, the signed
distance of an outline's paint, and small numeric helpers shared by built-in and third-party
kinds.

A plugin's primitive only has to read its element, name its control points, build an
:class:`~deepmorph_core.outline.Outline` and write itself back; distances, caps, fills and
culling come from the core.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import torch
from torch import Tensor

from deepmorph_core.geometry import CAP_CODES, CAP_ROUND
from deepmorph_core.outline import Frame, Outline, OutlineBuilder, fill_sdf, stroke_sdf
from deepmorph_core.protocols import ElementMorph, Primitive
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.values import format_number


class BasePrimitive:
    """Shared behaviour of primitives. Subclasses set the class attributes and implement
    ``from_element``, ``control_points``, ``outline`` and ``write``.

    Attributes:
        evenodd: fill rule of the element (set by the drawing parser from the style).
        filled: whether the element paints a fill (set by the parser). Outlines of unfilled
            elements may leave out their rings, which only fills use.
    """

    kind: ClassVar[str]
    tags: ClassVar[tuple[str, ...]] = ()
    priority: ClassVar[int] = 0
    morphable: ClassVar[str] = ""
    evenodd: bool = False
    filled: bool = True

    def outline(self, frame: Frame) -> Outline:  # pragma: no cover - abstract
        raise NotImplementedError


def paint_sdf(primitive: Primitive, frame: Frame, grid: Tensor, paint: str, half_width: Tensor) -> Tensor:
    """Differentiable signed distance ``(B, P)`` (positive inside, zero on the border) of a
    primitive's ``"stroke"`` or ``"fill"`` over ``grid`` ``(P, 2)`` pixel centres, from its
    outline: what the rasterizer evaluates (culled), in full, for tests and plugin authors."""
    return outline_paint_sdf(primitive.outline(frame), grid, paint, half_width, primitive.evenodd)


def outline_paint_sdf(outline: Outline, grid: Tensor, paint: str, half_width: Tensor, evenodd: bool) -> Tensor:
    """The SDF of one paint of an already-built outline."""
    if paint == "stroke":
        return stroke_sdf(outline, grid, half_width)
    if paint == "fill":
        return fill_sdf(outline, grid, evenodd)
    raise ValueError(f"paint must be 'stroke' or 'fill', got {paint!r}")


def as_points(points: np.ndarray | list[list[float]]) -> Tensor:
    """Control points as a float64 ``(n, 2)`` tensor."""
    return torch.as_tensor(np.asarray(points, dtype=np.float64).reshape(-1, 2))


def apply_affine(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 3x3 affine to ``(n, 2)`` points."""
    return points @ matrix[:2, :2].T + matrix[:2, 2]


def append_transform(element, transform: str) -> None:
    """Compose ``transform`` after the element's own transform (i.e. in its local units)."""
    old = element.get("transform")
    element.set("transform", f"{old} {transform}" if old else transform)


def rotate_about(morph: ElementMorph) -> str | None:
    """The ``rotate(a cx cy)`` that finishes ``morph`` after its shift and scale, if any."""
    if morph.rotate == 0.0:
        return None
    cx, cy = morph.centre[0] + morph.shift[0], morph.centre[1] + morph.shift[1]
    return f"rotate({format_number(morph.rotate)} {format_number(cx)} {format_number(cy)})"


def without_rotation(morph: ElementMorph) -> ElementMorph:
    """The shift-and-scale part of a morph (its rotation is written as a transform)."""
    return ElementMorph(morph.centre, morph.shift, morph.scale, 0.0)


def unit_circle(builder_dtype: torch.dtype, device: torch.device) -> tuple[Tensor, Tensor]:
    """``theta0 = 0`` and ``dtheta = 2*pi`` scalars for full circles."""
    zero = torch.zeros((), dtype=builder_dtype, device=device)
    return zero, zero + 2 * torch.pi


def builder_for(frame: Frame) -> OutlineBuilder:
    """An empty outline builder matching the frame's batch, dtype and device."""
    return OutlineBuilder(frame.local.shape[0], frame.local.dtype, frame.local.device)


def cap_of(reader: ElementReader) -> int:
    """The cap code of the element being read (from its computed style)."""
    return CAP_CODES.get(reader.style.linecap, CAP_ROUND)


def add_polyline(builder: OutlineBuilder, px: Tensor, closed: bool, cap: int) -> None:
    """Line pieces through ``px`` ``(B, n, 2)``; open ends get ``cap``, joins are round."""
    n = px.shape[1]
    count = n if closed else n - 1
    for k in range(count):
        a, b = px[:, k], px[:, (k + 1) % n]
        start = cap if (not closed and k == 0) else CAP_ROUND
        end = cap if (not closed and k == count - 1) else CAP_ROUND
        builder.line(a, b, start, end)
    builder.ring(px)


def circle_linear(frame: Frame, rx: Tensor | float, ry: Tensor | float) -> Tensor:
    """``(B, 2, 2)`` map from the unit circle to the pixel-space ellipse of radii rx, ry."""
    diag = torch.zeros(2, 2, dtype=frame.local.dtype, device=frame.local.device)
    diag[0, 0], diag[1, 1] = rx, ry
    return frame.linear @ diag
