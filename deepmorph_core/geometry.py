"""Pure, batched, differentiable distance functions in pixel space.

Everything here is a plain function of tensors (kornia's habit): primitives wire their
parameters to these, the rasterizer composes them. Distances are in pixels.

Shapes used throughout:
    grid:  ``(P, 2)`` pixel-centre coordinates shared by the whole batch.
    a, b:  ``(B, K, 2)`` segment end points, K segments per batch item.
    out:   ``(B, K, P)`` per piece, or ``(B, P)`` after reducing over pieces.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

_EPS = 1e-12

#: Cap codes for the open ends of stroked line pieces (SVG ``stroke-linecap``).
CAP_ROUND, CAP_BUTT, CAP_SQUARE = 0, 1, 2
CAP_CODES = {"round": CAP_ROUND, "butt": CAP_BUTT, "square": CAP_SQUARE}


# -- elementwise kernels ----------------------------------------------------------------
# Every argument broadcasts against the others. The outer-product functions below (every
# point against every piece) and the rasterizer's flat path (one point per piece-pixel pair)
# both call these, so there is one implementation of each formula.


def segment_distance_xy(px: Tensor, py: Tensor, ax: Tensor, ay: Tensor, bx: Tensor, by: Tensor) -> Tensor:
    """Distance from points to segments, component-wise (zero-length segments are points)."""
    bax, bay = bx - ax, by - ay
    pax, pay = px - ax, py - ay
    inv = 1.0 / (bax * bax + bay * bay).clamp_min(_EPS)
    h = ((pax * bax + pay * bay) * inv).clamp(0.0, 1.0)
    dx, dy = pax - bax * h, pay - bay * h
    return torch.sqrt(dx * dx + dy * dy + _EPS)


class _SegmentDistance(torch.autograd.Function):
    """Point-to-segment distance with a hand-written backward.

    Autograd would keep about a dozen intermediates per (point, segment) pair and replay two
    dozen elementwise ops; the gradient is simply ``-(1 - h) n`` for ``a`` and ``-h n`` for ``b``
    (``n`` the unit vector from the closest point to the query point, ``h`` the clamped
    projection), so three saved tensors suffice. Points get no gradient (they are pixel centres).
    """

    @staticmethod
    def forward(ctx, px: Tensor, py: Tensor, ax: Tensor, ay: Tensor, bx: Tensor, by: Tensor) -> Tensor:  # type: ignore[override]
        bax, bay = bx - ax, by - ay
        pax, pay = px - ax, py - ay
        h = ((pax * bax + pay * bay) / (bax * bax + bay * bay).clamp_min(_EPS)).clamp_(0.0, 1.0)
        dx = pax.sub_(bax * h)
        dy = pay.sub_(bay * h)
        d = torch.sqrt(dx * dx + dy * dy + _EPS)
        ctx.save_for_backward(dx.div_(d), dy.div_(d), h)
        ctx.shapes = (ax.shape, ay.shape, bx.shape, by.shape)
        return d

    @staticmethod
    def backward(ctx, grad: Tensor):  # type: ignore[override]
        nx, ny, h = ctx.saved_tensors
        gb = grad * h
        ga = grad - gb
        out = []
        for g, n, shape in (
            (ga, nx, ctx.shapes[0]),
            (ga, ny, ctx.shapes[1]),
            (gb, nx, ctx.shapes[2]),
            (gb, ny, ctx.shapes[3]),
        ):
            out.append(_sum_to(-(g * n), shape))
        return (None, None, *out)


def _sum_to(t: Tensor, shape: torch.Size) -> Tensor:
    """Reduce a broadcast gradient back to an input's shape."""
    if t.shape == shape:
        return t
    return t.sum_to_size(shape)


def segment_distance_fused(px: Tensor, py: Tensor, ax: Tensor, ay: Tensor, bx: Tensor, by: Tensor) -> Tensor:
    """:func:`segment_distance_xy` with the lean backward of :class:`_SegmentDistance` (same values)."""
    return _SegmentDistance.apply(px, py, ax, ay, bx, by)


def segment_stroke_sdf_xy(
    px: Tensor,
    py: Tensor,
    ax: Tensor,
    ay: Tensor,
    bx: Tensor,
    by: Tensor,
    hw: Tensor,
    cap_start: Tensor,
    cap_end: Tensor,
) -> Tensor:
    """Signed distance of stroked segments with per-end caps, component-wise (see
    :func:`segment_stroke_sdf`)."""
    capsule = hw - segment_distance_fused(px, py, ax, ay, bx, by)
    if not bool(((cap_start != CAP_ROUND) | (cap_end != CAP_ROUND)).any()):
        return capsule
    bax, bay = bx - ax, by - ay
    pax, pay = px - ax, py - ay
    length = torch.sqrt(bax * bax + bay * bay + _EPS)
    ux, uy = bax / length, bay / length
    along = pax * ux + pay * uy  # distance along the segment from a
    band = hw - (pax * uy - pay * ux).abs()
    ext_start = (cap_start == CAP_SQUARE).to(px.dtype) * hw
    ext_end = (cap_end == CAP_SQUARE).to(px.dtype) * hw
    first_half = along < length / 2
    out = torch.where((cap_start != CAP_ROUND) & first_half, torch.minimum(band, along + ext_start), capsule)
    out = torch.where((cap_end != CAP_ROUND) & ~first_half, torch.minimum(band, length - along + ext_end), out)
    # A zero-length segment with a butt cap draws nothing.
    degenerate = (length < 1e-6) & (cap_start == CAP_BUTT)
    return torch.where(degenerate, torch.full_like(out, -1e3), out)


def arc_distance_xy(
    px: Tensor,
    py: Tensor,
    cx: Tensor,
    cy: Tensor,
    inv: tuple[Tensor, Tensor, Tensor, Tensor],
    theta0: Tensor,
    dtheta: Tensor,
    start: tuple[Tensor, Tensor],
    end: tuple[Tensor, Tensor],
) -> Tensor:
    """Distance to centre-form arcs, component-wise (see :func:`arc_distance`); ``inv`` is the
    inverse unit-circle map as its four entries ``(i00, i01, i10, i11)``."""
    i00, i01, i10, i11 = inv
    rx, ry = px - cx, py - cy
    qx, qy = i00 * rx + i01 * ry, i10 * rx + i11 * ry
    rq = torch.sqrt(qx * qx + qy * qy + _EPS)
    gx, gy = (i00 * qx + i10 * qy) / rq, (i01 * qx + i11 * qy) / rq  # inv^T qhat
    d_curve = (rq - 1.0).abs() / torch.sqrt(gx * gx + gy * gy + _EPS)
    if bool((dtheta.abs() >= 2 * math.pi - 1e-9).all()):
        return d_curve  # full circles and ellipses: every angle is on the curve
    with torch.no_grad():
        ang = torch.atan2(qy, qx)
        sign = torch.where(dtheta >= 0, 1.0, -1.0).to(px.dtype)
        offset = torch.remainder(sign * (ang - theta0), 2 * math.pi)
        inside = offset <= dtheta.abs() + 1e-9
    d_start = torch.sqrt((px - start[0]) ** 2 + (py - start[1]) ** 2 + _EPS)
    d_end = torch.sqrt((px - end[0]) ** 2 + (py - end[1]) ** 2 + _EPS)
    return torch.where(inside, d_curve, torch.minimum(d_start, d_end))


# -- every grid point against every piece ------------------------------------------------


def _grid_xy(grid: Tensor) -> tuple[Tensor, Tensor]:
    return grid[:, 0][None, None], grid[:, 1][None, None]  # (1, 1, P)


def _piece_xy(points: Tensor) -> tuple[Tensor, Tensor]:
    return points[..., 0][..., None], points[..., 1][..., None]  # (B, K, 1)


def segment_distance(grid: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """Unsigned distance from every grid point to every segment ``[a, b]``.

    Zero-length segments are points (their distance is the distance to ``a``).

    Shape:
        grid ``(P, 2)``, a/b ``(B, K, 2)`` -> ``(B, K, P)``.
    """
    return segment_distance_xy(*_grid_xy(grid), *_piece_xy(a), *_piece_xy(b))


def segment_stroke_sdf(
    grid: Tensor,
    a: Tensor,
    b: Tensor,
    half_width: Tensor,
    cap_start: Tensor,
    cap_end: Tensor,
) -> Tensor:
    """Signed distance of a stroked segment (positive inside the ink).

    Interior joins and round caps are exact capsules; ``butt`` and ``square`` caps cut the
    stroke square at (or half a width beyond) the end they are set on. A zero-length segment
    with a round cap is a dot, with a butt cap nothing (as SVG renders them).

    Args:
        grid: ``(P, 2)`` pixel centres.
        a, b: ``(B, K, 2)`` end points.
        half_width: ``(B,)`` half the stroke width in pixels.
        cap_start, cap_end: ``(K,)`` integer cap codes (``CAP_*``) for each end; interior
            ends use ``CAP_ROUND`` so that consecutive capsules form round joins.

    Returns:
        ``(B, K, P)`` signed distances.
    """
    return segment_stroke_sdf_xy(
        *_grid_xy(grid),
        *_piece_xy(a),
        *_piece_xy(b),
        half_width[:, None, None],
        cap_start[None, :, None],
        cap_end[None, :, None],
    )


def arc_distance(
    grid: Tensor,
    center: Tensor,
    inv_linear: Tensor,
    theta0: Tensor,
    dtheta: Tensor,
    start: Tensor,
    end: Tensor,
) -> Tensor:
    """Distance to elliptical arcs given in centre form.

    The arc is ``center + L @ (cos t, sin t)`` for ``t`` from ``theta0`` to ``theta0 + dtheta``
    with ``L = inv(inv_linear)``. Near the curve the distance is the first-order estimate
    ``|f| / |grad f|`` with ``f = |inv_linear (p - c)| - 1``, which is exact for circles (under any
    similarity) and accurate within a few pixels of an ellipse; points whose normalised angle
    falls outside the arc measure to the nearer end point.

    Shape:
        grid ``(P, 2)``; center/start/end ``(B, J, 2)``; inv_linear ``(B, J, 2, 2)``;
        theta0/dtheta ``(B, J)`` -> ``(B, J, P)``.
    """
    inv = tuple(inv_linear[..., i, j][..., None] for i in (0, 1) for j in (0, 1))
    return arc_distance_xy(
        *_grid_xy(grid),
        *_piece_xy(center),
        inv,
        theta0[..., None],
        dtheta[..., None],
        _piece_xy(start),
        _piece_xy(end),
    )


def winding_numbers(grid: Tensor, rings: list[Tensor]) -> Tensor:
    """Winding numbers of closed polygons around grid points by rows (no gradient): the count
    of signed edge crossings, in far less work than every point against every edge.

    A point's winding number counts the edges crossing the horizontal ray to its right (up
    +1, down -1). The crossings are found once per pixel row (``B x edges x rows``, not
    ``x points``), sorted by row and position, and each point sums those to its right with a
    binary search.

    Shape:
        grid ``(P, 2)``, rings each ``(B, M_k, 2)`` (closed implicitly) -> ``(B, P)`` integers.
    """
    with torch.no_grad():
        B, P = rings[0].shape[0], grid.shape[0]
        if P == 0:
            return torch.zeros(B, 0, dtype=torch.int64, device=grid.device)
        a = torch.cat(rings, 1)
        b = torch.cat([torch.roll(ring, -1, dims=1) for ring in rings], 1)
        rows, row_of = torch.unique(grid[:, 1], return_inverse=True)  # (R,), (P,)
        R = rows.shape[0]
        y0, y1 = a[..., 1][:, :, None], b[..., 1][:, :, None]
        r = rows[None, None]
        up = (y0 <= r) & (y1 > r)
        down = (y0 > r) & (y1 <= r)
        bi, mi, ri = torch.nonzero(up | down, as_tuple=True)
        sign = torch.where(up[bi, mi, ri], 1, -1)
        ax, ay, bx, by = a[bi, mi, 0], a[bi, mi, 1], b[bi, mi, 0], b[bi, mi, 1]
        x_cross = ax + (rows[ri] - ay) * (bx - ax) / (by - ay)
        lo = float(min(x_cross.min(), grid[:, 0].min())) if len(x_cross) else float(grid[:, 0].min())
        hi = float(max(x_cross.max(), grid[:, 0].max())) if len(x_cross) else float(grid[:, 0].max())
        span = hi - lo + 3.0
        keys = (bi * R + ri).to(grid.dtype) * span + (x_cross - lo + 1.0)
        order = torch.argsort(keys)
        keys = keys[order]
        total = torch.cat([torch.zeros(1, dtype=torch.int64, device=grid.device), torch.cumsum(sign[order], 0)])
        segment = (torch.arange(B, device=grid.device)[:, None] * R + row_of[None]).to(grid.dtype)  # (B, P)
        query = segment * span + (grid[:, 0] - lo + 1.0)[None]
        start = torch.searchsorted(keys, query.reshape(-1), right=True)
        end = torch.searchsorted(keys, ((segment + 1) * span).reshape(-1))
        return (total[end] - total[start]).reshape(B, P)


def flatten_arc(center: Tensor, linear: Tensor, theta0: Tensor, dtheta: Tensor, n: int) -> Tensor:
    """Points along arcs in centre form, for bounding boxes and inside tests.

    Shape:
        center ``(B, J, 2)``, linear ``(B, J, 2, 2)``, theta0/dtheta ``(B, J)`` -> ``(B, J, n+1, 2)``.
    """
    steps = torch.linspace(0.0, 1.0, n + 1, dtype=center.dtype, device=center.device)
    t = theta0[..., None] + dtheta[..., None] * steps  # (B, J, n+1)
    unit = torch.stack([torch.cos(t), torch.sin(t)], -1)
    return center[:, :, None] + torch.einsum("bjkl,bjnl->bjnk", linear, unit)


def endpoint_to_center(
    p0: Tensor, p1: Tensor, rx: Tensor, ry: Tensor, phi: Tensor, large_arc: Tensor, sweep: Tensor
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """SVG arc endpoint parameterisation to centre form (SVG 1.1, appendix F.6.5-F.6.6).

    Radii too small to span the end points are scaled up as SVG renderers do. Batched and
    differentiable with respect to the end points.

    Args:
        p0, p1: ``(..., 2)`` end points.
        rx, ry, phi: ``(...)`` radii and x-axis rotation in radians.
        large_arc, sweep: ``(...)`` booleans (as 0./1. tensors).

    Returns:
        ``center (..., 2)``, ``rx (...)``, ``ry (...)``, ``theta0 (...)``, ``dtheta (...)``.
    """
    cos_phi, sin_phi = torch.cos(phi), torch.sin(phi)
    dx2 = (p0[..., 0] - p1[..., 0]) / 2
    dy2 = (p0[..., 1] - p1[..., 1]) / 2
    x1p = cos_phi * dx2 + sin_phi * dy2
    y1p = -sin_phi * dx2 + cos_phi * dy2
    rx, ry = rx.abs(), ry.abs()
    lam = (x1p / rx) ** 2 + (y1p / ry) ** 2
    scale = torch.sqrt(torch.clamp(lam, min=1.0))
    rx, ry = rx * scale, ry * scale
    num = rx**2 * ry**2 - rx**2 * y1p**2 - ry**2 * x1p**2
    den = (rx**2 * y1p**2 + ry**2 * x1p**2).clamp_min(_EPS)
    coef = torch.sqrt(torch.clamp(num / den, min=0.0) + _EPS)
    coef = torch.where((large_arc > 0.5) == (sweep > 0.5), -coef, coef)
    cxp = coef * rx * y1p / ry
    cyp = -coef * ry * x1p / rx
    cx = cos_phi * cxp - sin_phi * cyp + (p0[..., 0] + p1[..., 0]) / 2
    cy = sin_phi * cxp + cos_phi * cyp + (p0[..., 1] + p1[..., 1]) / 2
    ux, uy = (x1p - cxp) / rx, (y1p - cyp) / ry
    vx, vy = (-x1p - cxp) / rx, (-y1p - cyp) / ry
    theta0 = torch.atan2(uy, ux)
    dtheta = torch.atan2(ux * vy - uy * vx, ux * vx + uy * vy)
    two_pi = 2 * math.pi
    dtheta = torch.where((sweep < 0.5) & (dtheta > 0), dtheta - two_pi, dtheta)
    dtheta = torch.where((sweep > 0.5) & (dtheta < 0), dtheta + two_pi, dtheta)
    return torch.stack([cx, cy], -1), rx, ry, theta0, dtheta


def ellipse_linear(rx: Tensor, ry: Tensor, phi: Tensor) -> Tensor:
    """The 2x2 map ``R(phi) @ diag(rx, ry)`` taking the unit circle onto an ellipse.

    Shape:
        ``(...)`` -> ``(..., 2, 2)``.
    """
    c, s = torch.cos(phi), torch.sin(phi)
    return torch.stack([torch.stack([c * rx, -s * ry], -1), torch.stack([s * rx, c * ry], -1)], -2)
