"""Outlines: what a primitive draws, as batched line pieces, arcs and closed rings in pixels.

A primitive turns its (morphed) parameters into an :class:`Outline`; the signed distance of a
stroke or a fill is then computed here, once, for every kind. That keeps each primitive down to
its own geometry and gives culling a bounding box for free.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import Tensor

from deepmorph_core import geometry as G


@dataclass
class Frame:
    """Where a primitive's control points are for one batch of morphs.

    Attributes:
        local: ``(B, n, 2)`` control points in the element's own user units, after per-point moves.
        affine: ``(B, 3, 3)`` map from those units to pixels: viewBox scale, group morphs,
            the element's CTM and its element-level morph (shift/scale/rotate).
        stroke_scale: ``(B,)`` factor from the element's stroke width to pixels. It leaves out
            the element-level morph, which is written back into the geometry (a stroke keeps
            its width), but keeps group morphs, which are written back as transforms.
    """

    local: Tensor
    affine: Tensor
    stroke_scale: Tensor | None = None

    def to_pixels(self, points: Tensor) -> Tensor:
        """Map ``(B, ..., 2)`` local points to pixels with this frame's affine."""
        lin = self.affine[:, :2, :2]
        off = self.affine[:, :2, 2]
        shape = points.shape
        flat = points.reshape(shape[0], -1, 2)
        out = torch.einsum("bkl,bnl->bnk", lin, flat) + off[:, None]
        return out.reshape(shape)

    @property
    def linear(self) -> Tensor:
        """``(B, 2, 2)`` linear part of the affine."""
        return self.affine[:, :2, :2]

    @property
    def scale(self) -> Tensor:
        """``(B,)`` mean scale factor (sqrt of the determinant), used for stroke widths."""
        return torch.sqrt(torch.linalg.det(self.linear).abs() + 1e-12)


@dataclass
class Outline:
    """Batched drawn geometry of one primitive, in pixels.

    Attributes:
        line_a, line_b: ``(B, K, 2)`` line pieces (``K`` may be 0).
        cap_start, cap_end: ``(K,)`` cap codes at each piece end (round at interior joins).
        arcs: centre-form arcs: ``center (B, J, 2)``, ``linear (B, J, 2, 2)`` (unit circle to
            ellipse), ``theta0``/``dtheta`` ``(B, J)``, end points ``(B, J, 2)``.
        rings: closed polygons ``(B, M, 2)``, one per closed (or fill-closed) subpath.
        extent: ``(B, E, 2)`` points whose bounding box contains everything drawn.
    """

    line_a: Tensor
    line_b: Tensor
    cap_start: Tensor
    cap_end: Tensor
    arc_center: Tensor
    arc_linear: Tensor
    arc_theta0: Tensor
    arc_dtheta: Tensor
    arc_start: Tensor
    arc_end: Tensor
    rings: list[Tensor]
    extent: Tensor


@dataclass
class OutlineBuilder:
    """Collects pieces for one primitive; :meth:`build` concatenates them into an :class:`Outline`."""

    batch: int
    dtype: torch.dtype
    device: torch.device
    _lines: list[tuple[Tensor, Tensor, int, int]] = field(default_factory=list)
    _arcs: list[tuple[Tensor, Tensor, Tensor, Tensor]] = field(default_factory=list)
    _rings: list[Tensor] = field(default_factory=list)
    _extent: list[Tensor] = field(default_factory=list)

    def line(self, a: Tensor, b: Tensor, cap_start: int = G.CAP_ROUND, cap_end: int = G.CAP_ROUND) -> None:
        """Add a line piece from ``a`` to ``b`` (each ``(B, 2)``) with the caps of its two ends."""
        self._lines.append((a, b, cap_start, cap_end))
        self._extent.append(torch.stack([a, b], 1))

    def arc(self, center: Tensor, linear: Tensor, theta0: Tensor, dtheta: Tensor) -> Tensor:
        """Add a centre-form arc (``(B, 2)``, ``(B, 2, 2)``, ``(B,)``, ``(B,)``).

        Returns:
            ``(B, 33, 2)`` points along it (for the caller's rings).
        """
        self._arcs.append((center, linear, theta0, dtheta))
        pts = G.flatten_arc(center[:, None], linear[:, None], theta0[:, None], dtheta[:, None], 32)[:, 0]
        self._extent.append(pts)
        return pts

    def ring(self, points: Tensor) -> None:
        """Add a closed polygon ``(B, M, 2)`` used for fill inside tests."""
        self._rings.append(points)

    def build(self) -> Outline:
        B, dt, dev = self.batch, self.dtype, self.device
        if self._lines:
            a = torch.stack([x[0] for x in self._lines], 1)
            b = torch.stack([x[1] for x in self._lines], 1)
            cs = torch.tensor([x[2] for x in self._lines], device=dev)
            ce = torch.tensor([x[3] for x in self._lines], device=dev)
        else:
            a = b = torch.zeros(B, 0, 2, dtype=dt, device=dev)
            cs = ce = torch.zeros(0, dtype=torch.long, device=dev)
        if self._arcs:
            center = torch.stack([x[0] for x in self._arcs], 1)
            linear = torch.stack([x[1] for x in self._arcs], 1)
            theta0 = torch.stack([x[2] for x in self._arcs], 1)
            dtheta = torch.stack([x[3] for x in self._arcs], 1)
            unit = lambda t: torch.stack([torch.cos(t), torch.sin(t)], -1)  # noqa: E731
            start = center + torch.einsum("bjkl,bjl->bjk", linear, unit(theta0))
            end = center + torch.einsum("bjkl,bjl->bjk", linear, unit(theta0 + dtheta))
        else:
            center = start = end = torch.zeros(B, 0, 2, dtype=dt, device=dev)
            linear = torch.zeros(B, 0, 2, 2, dtype=dt, device=dev)
            theta0 = dtheta = torch.zeros(B, 0, dtype=dt, device=dev)
        extent = torch.cat(self._extent, 1) if self._extent else torch.zeros(B, 1, 2, dtype=dt, device=dev)
        return Outline(a, b, cs, ce, center, linear, theta0, dtheta, start, end, list(self._rings), extent)


def _piece_distances(outline: Outline, grid: Tensor) -> list[Tensor]:
    out = []
    if outline.line_a.shape[1]:
        out.append(G.segment_distance(grid, outline.line_a, outline.line_b))
    if outline.arc_center.shape[1]:
        out.append(_arc_distance(outline, grid))
    return out


def _arc_distance(outline: Outline, grid: Tensor) -> Tensor:
    inv = torch.linalg.inv(outline.arc_linear)
    return G.arc_distance(
        grid, outline.arc_center, inv, outline.arc_theta0, outline.arc_dtheta, outline.arc_start, outline.arc_end
    )


def stroke_sdf(outline: Outline, grid: Tensor, half_width: Tensor) -> Tensor:
    """Signed distance of the stroked outline (union of its pieces), ``(B, P)``.

    Args:
        outline: the primitive's outline.
        grid: ``(P, 2)`` pixel centres.
        half_width: ``(B,)`` half the stroke width in pixels.
    """
    parts = []
    if outline.line_a.shape[1]:
        parts.append(
            G.segment_stroke_sdf(grid, outline.line_a, outline.line_b, half_width, outline.cap_start, outline.cap_end)
        )
    if outline.arc_center.shape[1]:
        parts.append(half_width[:, None, None] - _arc_distance(outline, grid))
    if not parts:
        return torch.full((half_width.shape[0], grid.shape[0]), -1e3, dtype=grid.dtype, device=grid.device)
    return torch.cat(parts, 1).amax(1)


def fill_sdf(outline: Outline, grid: Tensor, evenodd: bool = False) -> Tensor:
    """Signed distance of the filled area (positive inside), ``(B, P)``.

    The magnitude is the distance to the outline; the sign comes from the winding number of
    the closed rings (``nonzero`` rule, or ``evenodd``).
    """
    dists = _piece_distances(outline, grid)
    B = outline.extent.shape[0]
    if not dists or not outline.rings:
        return torch.full((B, grid.shape[0]), -1e3, dtype=grid.dtype, device=grid.device)
    d = torch.cat(dists, 1).amin(1)
    winding = G.winding_numbers(grid, outline.rings)
    inside = (winding % 2 == 1) if evenodd else (winding != 0)
    return torch.where(inside, d, -d)


def pixel_grid(x0: int, y0: int, x1: int, y1: int, dtype: torch.dtype, device: torch.device) -> Tensor:
    """Pixel centres of the rectangle ``[x0, x1) x [y0, y1)``, row-major, ``(P, 2)``."""
    ys = torch.arange(y0, y1, dtype=dtype, device=device) + 0.5
    xs = torch.arange(x0, x1, dtype=dtype, device=device) + 0.5
    gy, gx = torch.meshgrid(ys, xs, indexing="ij")
    return torch.stack([gx.reshape(-1), gy.reshape(-1)], -1)


def pixel_bbox(outline: Outline, pad: Tensor | float) -> Tensor:
    """Union over the batch of the padded bounding box, ``(4,)`` = x0, y0, x1, y1 in pixels."""
    with torch.no_grad():
        ext = outline.extent.reshape(-1, 2)
        lo = ext.amin(0) - pad
        hi = ext.amax(0) + pad
        return torch.cat([lo, hi])
