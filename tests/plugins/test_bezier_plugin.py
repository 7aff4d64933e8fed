"""Tests of the ``deepmorph-bezier`` plugin (``plugins/deepmorph-bezier``): cubic and quadratic
Bézier path segments.

The registry is always built explicitly from the built-in primitives and the plugin module, so
these tests do not depend on what is installed (``test_bezier_install.py`` checks that).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import deepmorph_bezier.plugin as bez
import numpy as np
import pytest
import torch
from deepmorph_bezier.segments import (
    CubicBezierSegment,
    QuadraticBezierSegment,
    evaluate_bezier,
    wang_piece_count,
)
from svg.path import CubicBezier, Move, QuadraticBezier, parse_path

import deepmorph_primitives.plugin as builtin
from deepmorph_core.bounds import BoundSpec
from deepmorph_core.drawing import Drawing, PlacedPrimitive, load_drawing
from deepmorph_core.errors import UnsupportedFeatureError
from deepmorph_core.geometry import CAP_BUTT, CAP_ROUND, CAP_SQUARE
from deepmorph_core.morph import MorphSpace
from deepmorph_core.outline import Frame, OutlineBuilder
from deepmorph_core.plugins import Registry, load_registry
from deepmorph_core.primitive import paint_sdf
from deepmorph_core.protocols import ElementMorph, PathSegment

DATA = Path(__file__).parent.parent / "data" / "feather_bezier"
ICONS = sorted(p.name for p in DATA.glob("*.svg"))
#: The accuracy target: polyline within this many pixels of the true curve at 256 px.
TOLERANCE_PX = 0.05
RENDER_WIDTH = 256


@pytest.fixture(scope="module")
def reg() -> Registry:
    return load_registry([builtin, bez], entry_points=False)


@pytest.fixture(scope="module")
def reg_builtin_only() -> Registry:
    return load_registry([builtin], entry_points=False)


def svg_doc(body: str, view: str = "0 0 24 24") -> bytes:
    """A small SVG document; ``body`` starts on line 3."""
    return (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="' + view + '"\n'
        '     fill="none" stroke="black" stroke-width="2">\n' + body + "\n</svg>\n"
    ).encode()


def single_path(reg: Registry, d: str, extra: str = "") -> PlacedPrimitive:
    drawing = load_drawing(svg_doc(f'<path d="{d}" {extra}/>'), registry=reg)
    assert len(drawing.primitives) == 1
    return drawing.primitives[0]


def pixel_affine(scale: float, batch: int = 1) -> torch.Tensor:
    """``(B, 3, 3)`` float64 map from 24-unit icon space to a ``RENDER_WIDTH`` raster."""
    a = torch.eye(3, dtype=torch.float64)
    a[0, 0] = a[1, 1] = scale
    return a.expand(batch, 3, 3).clone()


SCALE = RENDER_WIDTH / 24.0


def bezier_segments(drawing: Drawing):
    """Every (segment object, local points (k+1, 2), matching svg.path segment) in the drawing."""
    out = []
    for placed in drawing.primitives:
        prim = placed.primitive
        if placed.primitive.kind != "path":
            continue
        pts = prim.control_points()
        svg_segs = [s for s in parse_path(placed.element.get("d")) if isinstance(s, (CubicBezier, QuadraticBezier))]
        ours = [(seg, idx) for sub in prim.subpaths for seg, idx in sub.segments if seg.kind.endswith("bezier")]
        assert len(ours) == len(svg_segs)
        for (seg, idx), ref in zip(ours, svg_segs):
            out.append((seg, pts[idx], ref))
    return out


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points ``p`` to segments ``a``-``b`` (broadcasting ``(..., 2)`` arrays)."""
    pa, ba = p - a, b - a
    h = np.clip((pa * ba).sum(-1) / np.maximum((ba * ba).sum(-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(pa - ba * h[..., None], axis=-1)


def polyline_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from each of ``points`` (P, 2) to the polyline of pieces ``a``-``b`` (K, 2)."""
    return segment_distance(points[:, None], a[None], b[None]).min(1)


def hausdorff_to_curve(seg, local: torch.Tensor) -> float:
    """Symmetric Hausdorff distance (pixels) between the drawn pieces and the exact curve.

    The true curve (from the same control points) is sampled densely, and the polyline is
    sampled too, so both directions are measured.
    """
    frame = Frame(local[None], pixel_affine(SCALE))
    b = OutlineBuilder(1, torch.float64, torch.device("cpu"))
    seg.add_pieces(b, frame, local[None], (CAP_ROUND, CAP_ROUND))
    outline = b.build()
    a_px = outline.line_a[0].numpy()
    b_px = outline.line_b[0].numpy()
    true = de_casteljau(local.numpy() * SCALE, np.linspace(0.0, 1.0, 4001))
    curve_to_poly = polyline_distance(true, a_px, b_px).max()
    s = np.linspace(0.0, 1.0, 9)[:, None, None]
    poly = (a_px[None] * (1 - s) + b_px[None] * s).reshape(-1, 2)
    # distance from polyline samples to the dense true curve: nearest sample, then the exact
    # distance to the two dense chords around it (sampling alone would overestimate)
    nearest = np.concatenate(
        [np.linalg.norm(chunk[:, None] - true[None], axis=-1).argmin(1) for chunk in np.array_split(poly, 8)]
    )
    lo, hi = np.maximum(nearest - 1, 0), np.minimum(nearest + 1, len(true) - 1)
    poly_to_curve = np.minimum(
        segment_distance(poly, true[lo], true[nearest]), segment_distance(poly, true[nearest], true[hi])
    ).max()
    return float(max(curve_to_poly, poly_to_curve))


# -- registration ------------------------------------------------------------------------


def test_plugin_registers_both_segment_kinds(reg: Registry) -> None:
    assert reg.path_segments["cubic-bezier"].obj is CubicBezierSegment
    assert reg.path_segments["quadratic-bezier"].obj is QuadraticBezierSegment
    assert reg.path_segments["cubic-bezier"].plugin == bez.__name__
    assert set(CubicBezierSegment.commands) == set("CcSs")
    assert set(QuadraticBezierSegment.commands) == set("QqTt")
    assert isinstance(CubicBezierSegment(), PathSegment)
    assert isinstance(QuadraticBezierSegment(), PathSegment)
    assert reg.segment_for(CubicBezier(0j, 1j, 2j, 3j)) is CubicBezierSegment
    assert reg.segment_for(QuadraticBezier(0j, 1j, 2j)) is QuadraticBezierSegment


# -- (a) without the plugin ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("d", "letter"),
    [
        ("M2 2c1 1 2 2 3 3", "c"),
        ("M2 2C4 4 5 5 6 6", "C"),
        ("M2 2L4 4s1 1 3 3", "s"),
        ("M2 2q1 1 2 2", "q"),
        ("M2 2T5 5", "T"),
    ],
)
def test_without_plugin_curves_are_unsupported(reg_builtin_only: Registry, d: str, letter: str) -> None:
    doc = svg_doc(f'<path d="{d}"/>')
    with pytest.raises(UnsupportedFeatureError) as info:
        load_drawing(doc, registry=reg_builtin_only, label="curves.svg")
    err = info.value
    assert f"path command {letter}" in str(err)
    assert err.line == 3
    assert "curves.svg:3:" in str(err)


def test_without_plugin_feather_icon_is_unsupported(reg_builtin_only: Registry) -> None:
    with pytest.raises(UnsupportedFeatureError, match="path command c"):
        load_drawing(DATA / "mail.svg", registry=reg_builtin_only)


# -- (b) Feather icons parse ---------------------------------------------------------------


@pytest.mark.parametrize("name", ICONS)
def test_feather_icons_with_curves_parse(reg: Registry, name: str) -> None:
    drawing = load_drawing(DATA / name, registry=reg)
    segs = bezier_segments(drawing)
    assert segs, f"{name} should contain Bézier segments"
    for _seg, pts, ref in segs:
        # every handle and the end point are control points, in svg.path's absolute form
        want = (
            [ref.start, ref.control1, ref.control2, ref.end]
            if isinstance(ref, CubicBezier)
            else [ref.start, ref.control, ref.end]
        )
        np.testing.assert_allclose(pts.numpy(), [[p.real, p.imag] for p in want], atol=1e-12)
    for placed in drawing.primitives:
        frame = Frame(placed.primitive.control_points()[None], pixel_affine(SCALE))
        outline = placed.primitive.outline(frame)
        assert torch.isfinite(outline.line_a).all()


def test_smooth_commands_resolve_to_reflected_handles(reg: Registry) -> None:
    placed = single_path(reg, "M0 0C1 1 2 1 3 0S5 -1 6 0T8 8")
    pts = placed.primitive.control_points().numpy()
    # M, C(3 points), S(3 points: reflected c1, c2, end), T(2 points: control, end)
    np.testing.assert_allclose(
        pts, [[0, 0], [1, 1], [2, 1], [3, 0], [4, -1], [5, -1], [6, 0], [6, 0], [8, 8]], atol=1e-12
    )
    kinds = [seg.kind for sub in placed.primitive.subpaths for seg, _ in sub.segments]
    assert kinds == ["cubic-bezier", "cubic-bezier", "quadratic-bezier"]
    smooth = [seg.smooth for sub in placed.primitive.subpaths for seg, _ in sub.segments]
    assert smooth == [False, True, True]


# -- (c) flattening accuracy -----------------------------------------------------------------


def test_flattening_accuracy_on_feather_icons(reg: Registry) -> None:
    worst = 0.0
    count = 0
    for name in ICONS:
        drawing = load_drawing(DATA / name, registry=reg)
        for seg, pts, _ref in bezier_segments(drawing):
            err = hausdorff_to_curve(seg, pts)
            worst = max(worst, err)
            count += 1
    assert count > 50
    assert worst <= TOLERANCE_PX, f"worst flattening error {worst:.4f} px over {count} curves"


def _random_curves(degree: int, count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(0.0, 24.0, size=(degree + 1, 2)) for _ in range(count)]


def de_casteljau(control: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Exact Bézier points by de Casteljau's construction (independent of the plugin's
    Bernstein code).

    Shape:
        control ``(d + 1, 2)``, t ``(T,)`` -> ``(T, 2)``.
    """
    p = np.broadcast_to(control[None], (len(t), *control.shape))
    tt = t[:, None, None]
    while p.shape[1] > 1:
        p = p[:, :-1] + (p[:, 1:] - p[:, :-1]) * tt
    return p[:, 0]


@pytest.mark.parametrize(("seg_cls", "degree"), [(CubicBezierSegment, 3), (QuadraticBezierSegment, 2)])
def test_flattening_accuracy_on_random_curves(seg_cls: type, degree: int) -> None:
    """Icon-sized curves (spans up to 12 units) meet the target; huge ones meet Wang's bound."""
    seg = seg_cls()
    for k, control in enumerate(_random_curves(degree, 12, seed=degree)):
        if k % 2 == 0:  # icon-sized: a few units across, like Feather's curves
            control = control[0] + (control - control[0]) * 0.5
        local = torch.as_tensor(control)
        err = hausdorff_to_curve(seg, local)
        px = torch.as_tensor(control * SCALE)[None]
        n = wang_piece_count(px, seg.tolerance_px, seg.min_pieces, seg.max_pieces)
        second = control[:-2] - 2 * control[1:-1] + control[2:]
        bound = degree * (degree - 1) / 8 * np.linalg.norm(second * SCALE, axis=-1).max() / n**2
        assert err <= bound + 1e-9
        if n < seg.max_pieces:
            assert err <= TOLERANCE_PX


def test_evaluation_matches_svgpath_exactly() -> None:
    ref = CubicBezier(1 + 2j, 7 - 3j, -2 + 9j, 11 + 4j)
    control = torch.tensor([[[1.0, 2.0], [7.0, -3.0], [-2.0, 9.0], [11.0, 4.0]]], dtype=torch.float64)
    pts = evaluate_bezier(control, 10)[0].numpy()
    want = [ref.point(t) for t in np.linspace(0, 1, 11)]
    np.testing.assert_allclose(pts, [[p.real, p.imag] for p in want], atol=1e-12)
    qref = QuadraticBezier(1 + 2j, 7 - 3j, 11 + 4j)
    qpts = evaluate_bezier(control[:, [0, 1, 3]], 7)[0].numpy()
    qwant = [qref.point(t) for t in np.linspace(0, 1, 8)]
    np.testing.assert_allclose(qpts, [[p.real, p.imag] for p in qwant], atol=1e-12)


# -- pieces, caps, batching -------------------------------------------------------------------


@pytest.mark.parametrize("caps", [(CAP_BUTT, CAP_SQUARE), (CAP_ROUND, CAP_BUTT)])
def test_pieces_are_joined_and_only_the_ends_get_caps(caps: tuple[int, int]) -> None:
    seg = CubicBezierSegment()
    local = torch.tensor([[2.0, 12.0], [6.0, 2.0], [18.0, 22.0], [22.0, 12.0]], dtype=torch.float64)
    local = torch.stack([local, local + 0.5])  # B = 2, slightly different curves
    frame = Frame(local, pixel_affine(SCALE, 2))
    b = OutlineBuilder(2, torch.float64, torch.device("cpu"))
    seg.add_pieces(b, frame, local, caps)
    out = b.build()
    k = out.line_a.shape[1]
    assert seg.min_pieces <= k <= seg.max_pieces
    assert out.cap_start[0].item() == caps[0] and out.cap_end[-1].item() == caps[1]
    assert (out.cap_start[1:] == CAP_ROUND).all() and (out.cap_end[:-1] == CAP_ROUND).all()
    torch.testing.assert_close(out.line_b[:, :-1], out.line_a[:, 1:])
    px = frame.to_pixels(local)
    torch.testing.assert_close(out.line_a[:, 0], px[:, 0], rtol=0, atol=1e-12)
    torch.testing.assert_close(out.line_b[:, -1], px[:, -1], rtol=0, atol=1e-12)
    flat = seg.flatten(frame, local)
    assert flat.shape == (2, k, 2)  # excludes the start point
    torch.testing.assert_close(flat, out.line_b)


def test_piece_count_adapts_to_size() -> None:
    seg = QuadraticBezierSegment()
    straight = torch.tensor([[[0.0, 0.0], [5.0, 5.0], [10.0, 10.0]]], dtype=torch.float64)
    tiny = torch.tensor([[[0.0, 0.0], [0.05, 0.1], [0.1, 0.0]]], dtype=torch.float64)
    big = torch.tensor([[[0.0, 0.0], [12.0, 24.0], [24.0, 0.0]]], dtype=torch.float64)
    counts = [seg.flatten(Frame(p, pixel_affine(SCALE)), p).shape[1] for p in (straight, tiny, big)]
    assert counts[0] == seg.min_pieces
    assert counts[1] == seg.min_pieces
    assert seg.min_pieces < counts[2] <= seg.max_pieces


def test_float32_and_batch_max_resolution() -> None:
    seg = CubicBezierSegment()
    small = torch.tensor([[0.0, 0.0], [0.2, 0.3], [0.4, 0.3], [0.6, 0.0]])
    large = torch.tensor([[0.0, 0.0], [4.0, 9.0], [9.0, 9.0], [12.0, 0.0]])
    both = torch.stack([small, large])
    frame = Frame(both, pixel_affine(SCALE, 2).float())
    flat = seg.flatten(frame, both)
    alone = seg.flatten(Frame(large[None], pixel_affine(SCALE).float()), large[None])
    assert flat.dtype == torch.float32
    assert flat.shape[1] == alone.shape[1]  # the batch's largest curve sets the resolution


# -- (d) gradients -----------------------------------------------------------------------------


def _grid_near_curve(control: np.ndarray, n_pieces: int, offsets: list[float]) -> torch.Tensor:
    """Pixel points offset along the normal from the curve at piece mid-parameters (no joints)."""
    pts = []
    for i in range(1, n_pieces, max(1, n_pieces // 5)):
        t = (i + 0.5) / n_pieces
        p, before, after = de_casteljau(control * SCALE, np.array([t, t - 1e-6, t + 1e-6]))
        tangent = (after - before) / np.linalg.norm(after - before)
        normal = np.array([-tangent[1], tangent[0]])
        pts.extend(p + off * normal for off in offsets)
    return torch.tensor(np.array(pts), dtype=torch.float64)


@pytest.mark.parametrize(
    "d",
    ["M2 12C6 2 18 22 22 12", "M3 20Q12 -4 21 20"],
    ids=["cubic", "quadratic"],
)
@pytest.mark.parametrize("linecap", ["round", "butt"])
def test_stroke_sdf_gradcheck(reg: Registry, d: str, linecap: str) -> None:
    placed = single_path(reg, d, f'stroke-linecap="{linecap}"')
    prim = placed.primitive
    control = prim.control_points().numpy()
    seg = prim.subpaths[0].segments[0][0]
    n = wang_piece_count(torch.as_tensor(control * SCALE)[None], seg.tolerance_px, seg.min_pieces, seg.max_pieces)
    grid = _grid_near_curve(control, n, [-4.0, -0.7, 2.5, 13.0])
    affine = pixel_affine(SCALE)
    half_width = torch.tensor([placed.style.stroke_width / 2 * SCALE], dtype=torch.float64)
    local = torch.as_tensor(control, dtype=torch.float64)[None].clone().requires_grad_(True)

    def sdf(points: torch.Tensor) -> torch.Tensor:
        return paint_sdf(prim, Frame(points, affine), grid, "stroke", half_width)

    value = sdf(local)
    assert value.shape == (1, grid.shape[0])
    inside = value[0] > 0
    assert inside.any() and (~inside).any()
    assert torch.autograd.gradcheck(sdf, (local,), eps=1e-6, atol=1e-6, rtol=1e-4)
    value.sum().backward()
    assert local.grad is not None and (local.grad[0, 1:-1].abs() > 0).any()  # handles get gradient


def test_rasterizer_gradient_reaches_curve_handles(reg: Registry) -> None:
    from deepmorph_core.raster import RasterSettings, SoftRasterizer

    drawing = load_drawing(DATA / "eye.svg", registry=reg, defaults=BoundSpec(move=0.5))
    space = MorphSpace(drawing)
    raster = SoftRasterizer(space, RasterSettings(width=48))
    unit = torch.rand(2, space.n_variables, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    unit.requires_grad_(True)
    ink = raster(space.values_from_unit(unit))
    assert ink.shape == (2, 1, 48, 48) and torch.isfinite(ink).all()
    (ink * torch.linspace(0, 1, 48, dtype=torch.float64)).sum().backward()
    assert unit.grad is not None and torch.isfinite(unit.grad).all()
    path_vars = [i for i, v in enumerate(space.variables) if v.index == 0]
    assert (unit.grad[:, path_vars].abs() > 0).float().mean() > 0.5


# -- (e) write-back ----------------------------------------------------------------------------


def _sample(d: str) -> np.ndarray:
    segs = [s for s in parse_path(d) if not isinstance(s, Move)]
    t = np.linspace(0.0, 1.0, 17)
    return np.array([[s.point(x).real, s.point(x).imag] for s in segs for x in t])


@pytest.mark.parametrize("name", ICONS)
def test_write_back_unchanged_points_round_trip(reg: Registry, name: str) -> None:
    drawing = load_drawing(DATA / name, registry=reg)
    for placed in drawing.primitives:
        if placed.primitive.kind != "path":
            continue
        element = copy.deepcopy(placed.element)
        points = placed.primitive.control_points().numpy()
        placed.primitive.write(element, points, ElementMorph(centre=(0.0, 0.0)))
        d_old, d_new = placed.element.get("d"), element.get("d")
        assert not set("SsTt") & set(d_new)  # smooth commands are written with explicit handles
        np.testing.assert_allclose(_sample(d_new), _sample(d_old), atol=1e-3)


def test_write_back_applies_element_morph(reg: Registry) -> None:
    d = "M2 12C6 2 18 22 22 12S10 30 4 20Q0 14 2 12T8 4Z"
    placed = single_path(reg, d)
    element = copy.deepcopy(placed.element)
    morph = ElementMorph(centre=(12.0, 12.0), shift=(1.5, -2.0), scale=0.8, rotate=30.0)
    placed.primitive.write(element, placed.primitive.control_points().numpy(), morph)
    m = morph.matrix()
    want = _sample(d) @ m[:2, :2].T + m[:2, 2]  # Béziers are affine-invariant
    np.testing.assert_allclose(_sample(element.get("d")), want, atol=1e-3)


def test_to_d_format() -> None:
    morph = ElementMorph(centre=(0.0, 0.0))
    cubic = np.array([[0.0, 0.0], [1.0, 2.5], [3.25, -4.0], [5.0, 6.00001]])
    assert CubicBezierSegment(smooth=True).to_d(cubic, morph) == "C1 2.5 3.25 -4 5 6"
    assert QuadraticBezierSegment(smooth=True).to_d(cubic[[0, 1, 3]], morph) == "Q1 2.5 5 6"


def test_morphed_drawing_writes_morphed_curves(reg: Registry) -> None:
    """End to end: the SVG written for a morph holds exactly the morphed control points."""
    drawing = load_drawing(DATA / "github.svg", registry=reg, defaults=BoundSpec(move=0.4))
    space = MorphSpace(drawing)
    unit = torch.rand(1, space.n_variables, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    values = space.values_from_unit(unit)
    morphed = space.frames(values, RENDER_WIDTH)[0].local[0].numpy()
    text = space.write_svg(values)
    again = load_drawing(text.encode(), registry=reg)
    np.testing.assert_allclose(again.primitives[0].primitive.control_points().numpy(), morphed, atol=1e-3)
    assert not np.allclose(morphed, drawing.primitives[0].primitive.control_points().numpy(), atol=1e-2)


def test_soft_raster_agrees_with_resvg(reg: Registry) -> None:
    """The curves land where a real renderer draws them (thresholded ink overlap)."""
    from deepmorph_core.raster import RasterSettings, SoftRasterizer
    from deepmorph_core.render import render_svg_ink

    for name in ("github.svg", "eye.svg", "slack.svg"):
        drawing = load_drawing(DATA / name, registry=reg)
        space = MorphSpace(drawing)
        with torch.no_grad():
            values = space.values_from_unit(space.neutral_unit(1, torch.float64))
            soft = SoftRasterizer(space, RasterSettings(width=64))(values)
        hard = render_svg_ink((DATA / name).read_text(), 64)
        a, b = soft[0, 0].numpy() > 0.5, hard > 0.5
        iou = (a & b).sum() / max(1, (a | b).sum())
        assert iou > 0.85, f"{name}: IoU {iou:.3f}"
        assert math.isfinite(float(soft.sum()))
