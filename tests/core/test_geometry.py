"""Every primitive's SDF is differentiable w.r.t. its morph variables (float64 gradcheck), and
its sign convention holds (positive inside the ink, negative outside)."""

from __future__ import annotations

import pytest
import torch

from deepmorph_core import geometry as G
from deepmorph_core.drawing import load_drawing
from deepmorph_core.morph import MorphSpace
from deepmorph_core.primitive import paint_sdf
from tests.conftest import make_svg

AFFINE = 'dm:move="0.6" dm:shift="0.5" dm:scale="0.9 1.1" dm:rotate="-10 10"'

CASES = {
    "line-round": f'<line x1="4" y1="5" x2="18" y2="15" stroke="black" stroke-width="2" stroke-linecap="round" {AFFINE}/>',
    "line-butt": f'<line x1="4" y1="5" x2="18" y2="15" stroke="black" stroke-width="2" {AFFINE}/>',
    "line-square": f'<line x1="4" y1="5" x2="18" y2="15" stroke="black" stroke-width="2" stroke-linecap="square" {AFFINE}/>',
    "polyline": f'<polyline points="3 3 10 12 17 5 21 20" stroke="black" stroke-width="2" fill="none" {AFFINE}/>',
    "polygon-fill": f'<polygon points="3 3 20 6 12 20" fill="black" stroke="none" {AFFINE}/>',
    "polygon-stroke": f'<polygon points="3 3 20 6 12 20" fill="none" stroke="black" stroke-width="2" {AFFINE}/>',
    "rect": f'<rect x="4" y="5" width="14" height="10" fill="none" stroke="black" stroke-width="2" {AFFINE}/>',
    "rect-rounded-fill": f'<rect x="4" y="5" width="14" height="10" rx="3" fill="black" {AFFINE}/>',
    "circle": f'<circle cx="12" cy="12" r="7" fill="none" stroke="black" stroke-width="2" {AFFINE}/>',
    "ellipse": f'<ellipse cx="12" cy="12" rx="8" ry="4" fill="none" stroke="black" stroke-width="2" {AFFINE}/>',
    "path": f'<path d="M3 20 L3 10 a5 5 0 0 1 10 0 h5 v8 Z" fill="none" stroke="black" stroke-width="2" {AFFINE}/>',
    "path-fill": f'<path d="M3 20 L3 10 a5 5 0 0 1 10 0 h5 v8 Z" fill="black" {AFFINE}/>',
    "half-circle": f'<path d="M6 12 A6 6 0 0 1 18 12" fill="none" stroke="black" stroke-width="2" {AFFINE}/>',
    "half-circle-closed": f'<path d="M6 12 A6 6 0 0 0 18 12 Z" fill="black" {AFFINE}/>',
    "transformed-group": (
        '<g transform="translate(1 2) rotate(15) skewX(10)" dm:shift="0.5" dm:rotate="-5 5">'
        '<circle cx="10" cy="10" r="5" fill="none" stroke="black" stroke-width="2" dm:move="0.5"/></g>'
    ),
}


def _setup(case: str, registry):
    drawing = load_drawing(make_svg(CASES[case]), registry=registry)
    space = MorphSpace(drawing)
    prim = drawing.primitives[0]
    paint, colour = prim.style.paints[-1]
    return drawing, space, prim, paint


@pytest.mark.parametrize("case", sorted(CASES))
def test_sdf_gradcheck(case: str, builtin_registry) -> None:
    drawing, space, prim, paint = _setup(case, builtin_registry)
    assert space.n_variables > 0
    expected_kind = case.split("-")[0] if not case.startswith(("transformed", "half")) else None
    if expected_kind:
        assert prim.primitive.kind == expected_kind
    width = 48
    gen = torch.Generator().manual_seed(0)
    grid = torch.rand(40, 2, generator=gen, dtype=torch.float64) * width
    unit = torch.rand(2, space.n_variables, generator=gen, dtype=torch.float64) * 0.8 + 0.1

    def sdf(u: torch.Tensor) -> torch.Tensor:
        values = space.values_from_unit(u)
        frame = space.frames(values, width)[0]
        hw = frame.scale * prim.style.stroke_width / 2
        return paint_sdf(prim.primitive, frame, grid, paint, hw)

    unit.requires_grad_(True)
    assert torch.autograd.gradcheck(sdf, (unit,), eps=1e-6, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("case", ["circle", "rect-rounded-fill", "polygon-fill", "line-round"])
def test_sdf_sign_convention(case: str, builtin_registry) -> None:
    """Positive inside the ink, negative outside, about zero on the border."""
    drawing, space, prim, paint = _setup(case, builtin_registry)
    values = space.values_from_unit(space.neutral_unit(1, torch.float64))
    frame = space.frames(values, 24)[0]  # 1 px per user unit
    hw = frame.scale * prim.style.stroke_width / 2
    far = torch.tensor([[0.2, 23.8]], dtype=torch.float64)
    assert paint_sdf(prim.primitive, frame, far, paint, hw).item() < -1
    inside = {
        "circle": [12.0, 5.0],  # on the stroke's centre line
        "rect-rounded-fill": [11.0, 10.0],
        "polygon-fill": [11.0, 9.0],
        "line-round": [11.0, 10.0],
    }[case]
    assert paint_sdf(prim.primitive, frame, torch.tensor([inside], dtype=torch.float64), paint, hw).item() > 0.5
    if case == "circle":
        border = torch.tensor([[12.0, 4.0], [12.0, 6.0], [20.0, 12.0]], dtype=torch.float64)
        torch.testing.assert_close(
            paint_sdf(prim.primitive, frame, border, paint, hw),
            torch.zeros(1, 3, dtype=torch.float64),
            atol=1e-6,
            rtol=0,
        )


def test_fused_segment_distance_matches_autograd() -> None:
    """The hand-written backward gives autograd's gradients (and the same values)."""
    from deepmorph_core.geometry import segment_distance_fused, segment_distance_xy

    gen = torch.Generator().manual_seed(0)
    px, py = (torch.rand(1, 7, 50, generator=gen, dtype=torch.float64) * 10 for _ in range(2))
    params = [(torch.rand(3, 7, 1, generator=gen, dtype=torch.float64) * 10).requires_grad_() for _ in range(4)]
    params[2].data[0, 0] = params[0].data[0, 0]  # a zero-length x extent
    assert torch.autograd.gradcheck(lambda *p: segment_distance_fused(px, py, *p), params)
    w = torch.rand(3, 7, 50, generator=gen, dtype=torch.float64)
    g1 = torch.autograd.grad((segment_distance_fused(px, py, *params) * w).sum(), params)
    g2 = torch.autograd.grad((segment_distance_xy(px, py, *params) * w).sum(), params)
    for a, b in zip(g1, g2):
        torch.testing.assert_close(a, b)


def dense_winding(grid: torch.Tensor, ring: torch.Tensor) -> torch.Tensor:
    """The reference: every point against every edge of ``ring`` ``(B, M, 2)``, ``(B, P)``."""
    x0, y0 = ring[..., 0][:, :, None], ring[..., 1][:, :, None]
    x1 = torch.roll(ring[..., 0], -1, dims=1)[:, :, None]
    y1 = torch.roll(ring[..., 1], -1, dims=1)[:, :, None]
    px, py = grid[:, 0][None, None], grid[:, 1][None, None]
    cross = (x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)
    up = (y0 <= py) & (y1 > py) & (cross > 0)
    down = (y0 > py) & (y1 <= py) & (cross < 0)
    return (up.to(torch.int64) - down.to(torch.int64)).sum(1)


@pytest.mark.parametrize("seed", range(6))
def test_winding_numbers_by_rows_equal_the_dense_count(seed: int) -> None:
    """The rasterizer's inside test by rows gives exactly the per-point crossing count."""
    gen = torch.Generator().manual_seed(seed)
    rings = [torch.rand(3, int(torch.randint(3, 60, (1,), generator=gen)), 2, generator=gen, dtype=torch.float64) * 24
             for _ in range(1 + seed % 3)]  # fmt: skip
    ys, xs = torch.meshgrid(torch.arange(24.0) + 0.5, torch.arange(24.0) + 0.5, indexing="ij")
    grid = torch.stack([xs.reshape(-1), ys.reshape(-1)], -1).to(torch.float64)
    dense = sum(dense_winding(grid, ring) for ring in rings)
    assert torch.equal(G.winding_numbers(grid, rings), dense)
