"""Helpers for primitive authors: a base class giving ``sdf`` from ``outline``, and small
numeric helpers shared by built-in and third-party kinds.

A plugin's primitive only has to read its element, name its control points, build an
:class:`~deepmorph_core.outline.Outline` and write itself back; distances, caps, fills and
culling come from the core.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import torch
from torch import Tensor

from deepmorph_core.outline import Frame, Outline, fill_sdf, stroke_sdf
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.values import format_number


class BasePrimitive:
    """Shared behaviour of primitives. Subclasses set the class attributes and implement
    ``from_element``, ``control_points``, ``outline`` and ``write``.

    Attributes:
        evenodd: fill rule of the element (set by the drawing parser from the style).
    """

    kind: ClassVar[str]
    tags: ClassVar[tuple[str, ...]] = ()
    priority: ClassVar[int] = 0
    morphable: ClassVar[str] = ""
    evenodd: bool = False

    def outline(self, frame: Frame) -> Outline:  # pragma: no cover - abstract
        raise NotImplementedError

    def sdf(self, frame: Frame, grid: Tensor, paint: str, half_width: Tensor) -> Tensor:
        """Signed distance ``(B, P)`` of the stroke or the fill (see the protocol)."""
        outline = self.outline(frame)
        return outline_paint_sdf(outline, grid, paint, half_width, self.evenodd)


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
