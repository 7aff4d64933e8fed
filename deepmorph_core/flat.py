"""Vectorised stroke and fill evaluation: every stroke of a colour run in one set of tensor operations.

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

from dataclasses import replace

import numpy as np
import torch
from torch import Tensor

from deepmorph_core import geometry as G
from deepmorph_core.outline import Outline

#: at most this many (pixel, segment) distances are held at once while culling: about one large
#: arc's box at 256 px, what culling one piece at a time held
CULL_CHUNK = 1 << 20


def _rects(lo: np.ndarray, hi: np.ndarray, pad: np.ndarray, H: int, W: int) -> np.ndarray:
    """Integer pixel rectangles ``(n, 4)`` = x0, y0, x1, y1 covering ``[lo - pad, hi + pad]``."""
    x0 = np.clip(np.floor(lo[:, 0] - pad), 0, W)
    y0 = np.clip(np.floor(lo[:, 1] - pad), 0, H)
    x1 = np.clip(np.ceil(hi[:, 0] + pad) + 1, 0, W)
    y1 = np.clip(np.ceil(hi[:, 1] + pad) + 1, 0, H)
    return np.stack([x0, y0, x1, y1], 1).astype(np.int64)


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
    # Pixels a piece can reach: within its reach of its mean polyline (not its whole box, which
    # for a diagonal stroke is mostly empty); lines first, then arcs, as the pieces are numbered.
    pair_piece, pair_pixel = [], []
    first = 0
    for paths, reach_of in zip(polylines, reaches):
        piece_k, pixel_k = _reached_pixels(paths, reach_of, H, W)
        pair_piece.append(piece_k + first)
        pair_pixel.append(pixel_k)
        first += len(paths)
    piece = np.concatenate(pair_piece)
    pixel = np.concatenate(pair_pixel)
    if not len(piece):
        return None
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


def flat_fill_sdf(fills: list[tuple[Outline, bool]], H: int, W: int, reach: float) -> tuple[Tensor, Tensor] | None:
    """Signed distances of many fills (positive inside), evaluated only where they can change.

    Near its outline (within ``reach`` of every batch item's edge) a fill gets its exact signed
    distance, with gradients, from the stroke machinery above (a zero-width stroke with round
    ends is the distance to the outline) and the sign from the winding number. Farther in, every
    batch item agrees that the pixel is inside (the edges cannot reach it), so it gets a
    constant deep-inside value without gradient; farther out, nothing. This keeps a large fill
    as cheap as its outline instead of its area times its pieces.

    Args:
        fills: ``(outline, evenodd)`` per fill paint.
        H, W: canvas size in pixels.
        reach: pixels beyond the edge that get evaluated (the sigmoid's reach).

    Returns:
        ``positions (S,)`` and ``sdf (S, B)`` as :func:`flat_stroke_sdf`, or ``None``.
    """
    ref = fills[0][0].extent
    B, dtype, device = ref.shape[0], ref.dtype, ref.device
    zero = torch.zeros(B, dtype=dtype, device=device)
    positions: list[Tensor] = []
    sdfs: list[Tensor] = []
    for outline, evenodd in fills:
        if not outline.rings:
            continue
        round_ends = replace(
            outline,
            cap_start=torch.full_like(outline.cap_start, G.CAP_ROUND),
            cap_end=torch.full_like(outline.cap_end, G.CAP_ROUND),
        )
        near = flat_stroke_sdf([(round_ends, zero)], H, W, reach)
        near_pixels = near[0] if near is not None else torch.zeros(0, dtype=torch.long, device=device)
        with torch.no_grad():
            # the sign, per batch item, where the edge is near
            grid = torch.stack([(near_pixels % W).to(dtype) + 0.5, (near_pixels // W).to(dtype) + 0.5], -1)
            inside = _inside(grid, outline.rings, evenodd)  # (B, S)
            # deep inside: pixels of the outline's box that no edge reaches, tested on the mean outline
            ext = outline.extent.reshape(-1, 2)
            x0, y0 = (max(0, int(np.floor(float(v)))) for v in ext.amin(0))
            x1, y1 = (min(n, int(np.ceil(float(v))) + 1) for v, n in zip(ext.amax(0), (W, H)))
            deep = torch.zeros(0, dtype=torch.long, device=device)
            if x1 > x0 and y1 > y0:
                rows = torch.arange(y0, y1, device=device)[:, None] * W
                box = (rows + torch.arange(x0, x1, device=device)[None]).reshape(-1)
                far = ~torch.isin(box, near_pixels)
                box = box[far]
                centre = torch.stack([(box % W).to(dtype) + 0.5, (box // W).to(dtype) + 0.5], -1)
                mean_rings = [ring.mean(0, keepdim=True) for ring in outline.rings]
                deep = box[_inside(centre, mean_rings, evenodd)[0]]
        if near is not None:
            positions.append(near_pixels)
            sdfs.append(torch.where(inside.t(), -near[1], near[1]))
        if len(deep):
            positions.append(deep)
            sdfs.append(torch.full((len(deep), B), 1e3, dtype=dtype, device=device))
    if not positions:
        return None
    return torch.cat(positions), torch.cat(sdfs, 0)


def _inside(grid: Tensor, rings: list[Tensor], evenodd: bool) -> Tensor:
    """``(B, P)`` whether each point is inside the rings (``nonzero`` or ``evenodd`` rule)."""
    winding = G.winding_numbers(grid, rings)
    return (winding % 2 == 1) if evenodd else (winding != 0)


def _reached_pixels(paths: np.ndarray, reach: np.ndarray, H: int, W: int) -> tuple[np.ndarray, np.ndarray]:
    """The pixels each polyline reaches: ``(piece, pixel)`` pairs (indices into ``paths``, flat
    canvas indices), pieces in order, each one's pixels row-major in its padded box.

    ``paths``: ``(n, points, 2)`` polylines; ``reach``: ``(n,)`` how far from its polyline a
    piece reaches. All pieces' boxes are evaluated together, :data:`CULL_CHUNK` distances at a time
    (one piece at a time cost a loop of small NumPy calls per piece: a fifth of a colour render)."""
    segments = paths.shape[1] - 1
    rects = _rects(paths.min(1), paths.max(1), reach, H, W)
    widths = np.maximum(rects[:, 2] - rects[:, 0], 0)
    sizes = widths * np.maximum(rects[:, 3] - rects[:, 1], 0)
    # per piece, its segments' starts, directions and squared lengths
    starts = paths[:, :-1]
    steps = paths[:, 1:] - starts
    lengths = np.maximum((steps * steps).sum(2), 1e-12)
    cost = np.cumsum(sizes * segments)
    pieces, pixels = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    start = 0
    while start < len(paths):
        done = cost[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cost, done + CULL_CHUNK, side="right")))
        ks = np.arange(start, stop)
        piece = np.repeat(ks, sizes[ks])
        within = np.arange(len(piece)) - np.repeat(np.cumsum(sizes[ks]) - sizes[ks], sizes[ks])
        span = widths[piece]  # at least 1: a piece whose box is empty has no pixels here
        xs = rects[piece, 0] + within % span
        ys = rects[piece, 1] + within // span
        a, d = starts[piece], steps[piece]
        x, y = (xs + 0.5)[:, None], (ys + 0.5)[:, None]
        t = np.clip(((x - a[..., 0]) * d[..., 0] + (y - a[..., 1]) * d[..., 1]) / lengths[piece], 0.0, 1.0)
        dx = x - (a[..., 0] + t * d[..., 0])
        dy = y - (a[..., 1] + t * d[..., 1])
        near = np.sqrt(dx * dx + dy * dy).min(1) <= reach[piece]
        pieces.append(piece[near])
        pixels.append((ys * W + xs)[near])
        start = stop
    return np.concatenate(pieces), np.concatenate(pixels)


__all__ = ["flat_stroke_sdf"]
