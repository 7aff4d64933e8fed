"""Vectorised stroke evaluation: every stroke of a colour run in one set of tensor operations.

Looping over primitives costs a few hundred small tensor operations per primitive (forward
and backward), which dominates at icon sizes. Here each piece (line segment or arc) of every
stroke is paired with the pixels of its own padded bounding box, all pairs are evaluated at
once with the elementwise kernels of :mod:`deepmorph_core.geometry`, and each stroke's pieces
are combined with a scatter ``amax`` into per-stroke pixel slots — the same exact union as
:func:`deepmorph_core.outline.stroke_sdf`, evaluated only where a piece can reach.

Index building (which pixels pair with which piece) runs in NumPy without autograd; the
geometry runs in torch with gradients to every control point.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from deepmorph_core import geometry as G
from deepmorph_core.outline import Outline


def _rects(lo: np.ndarray, hi: np.ndarray, pad: np.ndarray, H: int, W: int) -> np.ndarray:
    """Integer pixel rectangles ``(n, 4)`` = x0, y0, x1, y1 covering ``[lo - pad, hi + pad]``."""
    x0 = np.clip(np.floor(lo[:, 0] - pad), 0, W)
    y0 = np.clip(np.floor(lo[:, 1] - pad), 0, H)
    x1 = np.clip(np.ceil(hi[:, 0] + pad) + 1, 0, W)
    y1 = np.clip(np.ceil(hi[:, 1] + pad) + 1, 0, H)
    return np.stack([x0, y0, x1, y1], 1).astype(np.int64)


def _pixels(rect: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row-major pixel coordinates (xs, ys) of a rectangle."""
    x0, y0, x1, y1 = rect
    ys, xs = np.mgrid[y0:y1, x0:x1]
    return xs.reshape(-1), ys.reshape(-1)


def flat_stroke_sdf(
    strokes: list[tuple[Outline, Tensor]], H: int, W: int, reach: float
) -> tuple[Tensor, Tensor] | None:
    """Signed distances of many strokes over the pixels they can reach.

    Args:
        strokes: ``(outline, half_width (B,))`` per stroke paint.
        H, W: canvas size in pixels.
        reach: pixels beyond the stroke edge that still get evaluated (the sigmoid's reach).

    Returns:
        ``positions (S,)`` flat canvas indices and ``sdf (S, B)``, one slot per pixel of each
        stroke's box (a pixel covered by two strokes has two slots), or ``None`` if nothing is
        on the canvas.
    """
    ref = strokes[0][1]
    B, dtype, device = ref.shape[0], ref.dtype, ref.device
    hw = torch.stack([h for _, h in strokes], 1)  # (B, n_strokes)
    n_lines = [o.line_a.shape[1] for o, _ in strokes]
    n_arcs = [o.arc_center.shape[1] for o, _ in strokes]
    line_owner = np.repeat(np.arange(len(strokes)), n_lines)
    arc_owner = np.repeat(np.arange(len(strokes)), n_arcs)
    line_a = torch.cat([o.line_a for o, _ in strokes], 1)
    line_b = torch.cat([o.line_b for o, _ in strokes], 1)
    cap_s = torch.cat([o.cap_start for o, _ in strokes])
    cap_e = torch.cat([o.cap_end for o, _ in strokes])
    have_arcs = len(arc_owner) > 0
    if have_arcs:
        arc_c = torch.cat([o.arc_center for o, _ in strokes], 1)
        arc_lin = torch.cat([o.arc_linear for o, _ in strokes], 1)
        arc_t0 = torch.cat([o.arc_theta0 for o, _ in strokes], 1)
        arc_dt = torch.cat([o.arc_dtheta for o, _ in strokes], 1)
        arc_s = torch.cat([o.arc_start for o, _ in strokes], 1)
        arc_e = torch.cat([o.arc_end for o, _ in strokes], 1)

    # -- which pixels pair with which piece (no gradient) --------------------------------
    with torch.no_grad():
        pad = (hw.amax(0) + reach).cpu().numpy()
        # Each piece as a mean polyline over the batch, with how far any batch item strays from it.
        ends = torch.stack([line_a, line_b], 2)  # (B, L, 2, 2)
        mean_ends = ends.mean(0)
        stray = (ends - mean_ends).norm(dim=-1).amax(dim=(0, 2))
        polylines = [mean_ends.cpu().numpy()]
        reaches = [pad[line_owner] + stray.cpu().numpy()]
        if have_arcs:
            pts = G.flatten_arc(arc_c, arc_lin, arc_t0, arc_dt, 16)  # (B, J, 17, 2)
            mean_pts = pts.mean(0)
            # the chord between flattening points sags by up to r (1 - cos(pi / 16)) < 2 % of r
            sag = 0.02 * torch.linalg.matrix_norm(arc_lin, ord=2).amax(0)
            arc_stray = (pts - mean_pts).norm(dim=-1).amax(dim=(0, 2)) + sag
            polylines.append(mean_pts.cpu().numpy())
            reaches.append(pad[arc_owner] + arc_stray.cpu().numpy())
    owners = np.concatenate([line_owner, arc_owner])
    piece_reach = np.concatenate(reaches)
    piece_paths = [pl for group in polylines for pl in group]  # (n_points, 2) per piece
    piece_rects = (
        np.concatenate(
            [
                _rects(pl.min(0, keepdims=True), pl.max(0, keepdims=True), r, H, W)
                for pl, r in zip(piece_paths, piece_reach)
            ]
        )
        if piece_paths
        else np.zeros((0, 4), np.int64)
    )
    # Pixels a piece can reach: within its reach of its mean polyline (not its whole box, which
    # for a diagonal stroke is mostly empty).
    pair_piece, pair_pixel = [], []
    for k, rect in enumerate(piece_rects):
        if rect[2] <= rect[0] or rect[3] <= rect[1]:
            continue
        xs, ys = _pixels(rect)
        near = _polyline_distance(xs + 0.5, ys + 0.5, piece_paths[k]) <= piece_reach[k]
        if near.any():
            pair_piece.append(np.full(int(near.sum()), k))
            pair_pixel.append((ys * W + xs)[near])
    if not pair_piece:
        return None
    piece = np.concatenate(pair_piece)
    pixel = np.concatenate(pair_pixel)
    # one slot per (stroke, pixel): a stroke's pieces meet there with an exact max
    keys, slot_np = np.unique(owners[piece] * (H * W) + pixel, return_inverse=True)
    slot = torch.from_numpy(slot_np.reshape(-1)).to(device)
    px = torch.from_numpy(pixel % W).to(device=device, dtype=dtype) + 0.5
    py = torch.from_numpy(pixel // W).to(device=device, dtype=dtype) + 0.5
    positions_t = torch.from_numpy(keys % (H * W)).to(device)
    n_line_pieces = len(line_owner)
    is_line = piece < n_line_pieces

    # -- geometry of every (piece, pixel) pair (with gradient) ---------------------------
    # Pairs-first layout (pairs, B): gathering rows and scattering them back (the backward of
    # index_select) then moves contiguous rows of B values, several times faster on CPU than
    # indexing the second dimension.
    parts: list[Tensor] = []
    slots: list[Tensor] = []
    hw_t = hw.t().contiguous()  # (n_strokes, B)
    if is_line.any():
        sel = torch.from_numpy(piece[is_line]).to(device)
        owner = torch.from_numpy(line_owner[piece[is_line]]).to(device)
        a = line_a.transpose(0, 1).reshape(-1, 2 * B).index_select(0, sel)  # (n, 2B): x then y interleaved per batch
        b = line_b.transpose(0, 1).reshape(-1, 2 * B).index_select(0, sel)
        mask = torch.from_numpy(is_line).to(device)
        parts.append(
            G.segment_stroke_sdf_xy(
                px[mask][:, None],
                py[mask][:, None],
                a[:, 0::2],
                a[:, 1::2],
                b[:, 0::2],
                b[:, 1::2],
                hw_t.index_select(0, owner),
                cap_s[sel][:, None],
                cap_e[sel][:, None],
            )
        )
        slots.append(slot[mask])
    if have_arcs and (~is_line).any():
        arc_piece = piece[~is_line] - n_line_pieces
        sel = torch.from_numpy(arc_piece).to(device)
        owner = torch.from_numpy(arc_owner[arc_piece]).to(device)
        mask = torch.from_numpy(~is_line).to(device)
        J = arc_c.shape[1]
        rows = lambda t, k: t.transpose(0, 1).reshape(J, -1).index_select(0, sel)  # noqa: E731  (n, k*B)
        inv = rows(torch.linalg.inv(arc_lin), 4)  # per batch: i00 i01 i10 i11
        c, st, en = rows(arc_c, 2), rows(arc_s, 2), rows(arc_e, 2)
        d = G.arc_distance_xy(
            px[mask][:, None],
            py[mask][:, None],
            c[:, 0::2],
            c[:, 1::2],
            (inv[:, 0::4], inv[:, 1::4], inv[:, 2::4], inv[:, 3::4]),
            rows(arc_t0, 1),
            rows(arc_dt, 1),
            (st[:, 0::2], st[:, 1::2]),
            (en[:, 0::2], en[:, 1::2]),
        )
        parts.append(hw_t.index_select(0, owner) - d)
        slots.append(slot[mask])
    out = torch.full((len(keys), B), -1e3, dtype=dtype, device=device)
    index = torch.cat(slots)[:, None].expand(-1, B)
    out = out.scatter_reduce(0, index, torch.cat(parts, 0), reduce="amax", include_self=True)
    return positions_t, out


def _polyline_distance(x: np.ndarray, y: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Distance from points to a polyline ``(n, 2)`` (NumPy; for culling only)."""
    a, b = path[:-1], path[1:]
    d = b - a
    denom = np.maximum((d * d).sum(1), 1e-12)
    t = np.clip(((x[:, None] - a[:, 0]) * d[:, 0] + (y[:, None] - a[:, 1]) * d[:, 1]) / denom, 0.0, 1.0)
    dx = x[:, None] - (a[:, 0] + t * d[:, 0])
    dy = y[:, None] - (a[:, 1] + t * d[:, 1])
    return np.sqrt(dx * dx + dy * dy).min(1)


__all__ = ["flat_stroke_sdf"]
