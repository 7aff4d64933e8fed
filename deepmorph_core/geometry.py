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


def safe_norm(v: Tensor, dim: int = -1) -> Tensor:
    """Euclidean norm with a finite gradient at zero (``sqrt(|v|^2 + eps)``)."""
    return torch.sqrt((v * v).sum(dim) + _EPS)


def segment_distance(grid: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """Unsigned distance from every grid point to every segment ``[a, b]``.

    Zero-length segments are points (their distance is the distance to ``a``).

    Shape:
        grid ``(P, 2)``, a/b ``(B, K, 2)`` -> ``(B, K, P)``.
    """
    # Component-wise: about half the work of stacked (..., 2) tensors and their reductions.
    px, py = grid[:, 0][None, None], grid[:, 1][None, None]  # (1, 1, P)
    ax, ay = a[..., 0][..., None], a[..., 1][..., None]  # (B, K, 1)
    bax, bay = b[..., 0][..., None] - ax, b[..., 1][..., None] - ay
    pax, pay = px - ax, py - ay  # (B, K, P)
    inv = 1.0 / (bax * bax + bay * bay).clamp_min(_EPS)
    h = ((pax * bax + pay * bay) * inv).clamp(0.0, 1.0)
    dx, dy = pax - bax * h, pay - bay * h
    return torch.sqrt(dx * dx + dy * dy + _EPS)


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
    hw = half_width[:, None, None]
    capsule = hw - segment_distance(grid, a, b)
    if not bool(((cap_start != CAP_ROUND) | (cap_end != CAP_ROUND)).any()):
        return capsule
    pa = grid[None, None] - a[:, :, None]
    ba = (b - a)[:, :, None]
    length = safe_norm(ba)
    u = ba / length[..., None]
    along = (pa * u).sum(-1)  # (B, K, P) distance along the segment from a
    perp = (pa[..., 0] * u[..., 1] - pa[..., 1] * u[..., 0]).abs()
    band = hw - perp
    ext_start = torch.where(cap_start == CAP_SQUARE, 1.0, 0.0).to(grid.dtype)[None, :, None] * hw
    ext_end = torch.where(cap_end == CAP_SQUARE, 1.0, 0.0).to(grid.dtype)[None, :, None] * hw
    start_cut = (cap_start != CAP_ROUND)[None, :, None]
    end_cut = (cap_end != CAP_ROUND)[None, :, None]
    first_half = along < length / 2
    out = torch.where(start_cut & first_half, torch.minimum(band, along + ext_start), capsule)
    out = torch.where(end_cut & ~first_half, torch.minimum(band, length - along + ext_end), out)
    # A zero-length segment with a butt cap draws nothing.
    degenerate = (length < 1e-6) & (cap_start == CAP_BUTT)[None, :, None]
    return torch.where(degenerate, torch.full_like(out, -1e3), out)


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
    # Component-wise (2x2 einsums become slow batched matmuls with an inner size of 2).
    rx = grid[:, 0][None, None] - center[..., 0][..., None]  # (B, J, P)
    ry = grid[:, 1][None, None] - center[..., 1][..., None]
    i00, i01 = inv_linear[..., 0, 0][..., None], inv_linear[..., 0, 1][..., None]
    i10, i11 = inv_linear[..., 1, 0][..., None], inv_linear[..., 1, 1][..., None]
    qx, qy = i00 * rx + i01 * ry, i10 * rx + i11 * ry
    rq = torch.sqrt(qx * qx + qy * qy + _EPS)
    gx, gy = (i00 * qx + i10 * qy) / rq, (i01 * qx + i11 * qy) / rq  # inv_linear^T qhat
    d_curve = (rq - 1.0).abs() / torch.sqrt(gx * gx + gy * gy + _EPS)
    if bool((dtheta.abs() >= 2 * math.pi - 1e-9).all()):
        return d_curve  # full circles and ellipses: every angle is on the curve
    with torch.no_grad():
        ang = torch.atan2(qy, qx)
        sign = torch.where(dtheta >= 0, 1.0, -1.0).to(grid.dtype)[..., None]
        offset = torch.remainder(sign * (ang - theta0[..., None]), 2 * math.pi)
        inside = offset <= dtheta.abs()[..., None] + 1e-9
    d_start = safe_norm(grid[None, None] - start[:, :, None])
    d_end = safe_norm(grid[None, None] - end[:, :, None])
    return torch.where(inside, d_curve, torch.minimum(d_start, d_end))


def ring_winding(grid: Tensor, ring: Tensor) -> Tensor:
    """Winding number of a closed polygon around each grid point (no gradient).

    Shape:
        grid ``(P, 2)``, ring ``(B, M, 2)`` (closed implicitly) -> ``(B, P)`` integers.
    """
    with torch.no_grad():
        x0 = ring[..., 0][:, :, None]
        y0 = ring[..., 1][:, :, None]
        x1 = torch.roll(ring[..., 0], -1, dims=1)[:, :, None]
        y1 = torch.roll(ring[..., 1], -1, dims=1)[:, :, None]
        px = grid[:, 0][None, None]
        py = grid[:, 1][None, None]
        cross = (x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)
        up = (y0 <= py) & (y1 > py) & (cross > 0)
        down = (y0 > py) & (y1 <= py) & (cross < 0)
        return (up.to(torch.int32) - down.to(torch.int32)).sum(1)


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
