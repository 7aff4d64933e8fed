"""The culled soft rasterizer against an independent dense reference (values and gradients),
layering, and fidelity against the real renderer on drawings exercising every feature."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deepmorph_core.morph import MorphSpace
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.primitive import paint_sdf
from deepmorph_core.raster import RasterSettings, SoftRasterizer, normalised_squash, stroke_half_width
from deepmorph_core.render import render_svg_ink
from tests.conftest import FEATHER, make_svg


def naive_render(space: MorphSpace, values: torch.Tensor, settings: RasterSettings) -> torch.Tensor:
    """Straight from the method's description: every paint over every pixel, soft union of
    same-coloured runs, squash between runs. No culling, no shared outlines, no in-place ops."""
    B = values.shape[0]
    h, w = space.drawing.pixel_size(settings.width)
    ys, xs = torch.meshgrid(
        torch.arange(h, dtype=values.dtype) + 0.5, torch.arange(w, dtype=values.dtype) + 0.5, indexing="ij"
    )
    grid = torch.stack([xs.reshape(-1), ys.reshape(-1)], -1)
    frames = space.frames(values, settings.width)
    acc = None
    paints = [(p, mode, colour) for p in space.drawing.primitives for mode, colour in p.style.paints]
    runs: list[tuple[int, list]] = []
    for p, mode, colour in paints:
        if runs and runs[-1][0] == colour:
            runs[-1][1].append((p, mode))
        else:
            runs.append((colour, [(p, mode)]))
    for colour, members in runs:
        keep = torch.ones(B, h * w, dtype=values.dtype)
        for p, mode in members:
            frame = frames[p.index]
            hw = stroke_half_width(frame, p.style.stroke_width, mode)
            sdf = paint_sdf(p.primitive, frame, grid, mode, hw)
            keep = keep * (1 - torch.sigmoid(settings.sharpness * sdf))
        cover = colour.ink_sign * (1 - keep).reshape(B, h, w)
        acc = cover if acc is None else normalised_squash(acc, settings.squash) + cover
    return normalised_squash(acc, settings.squash)[:, None]


LAYERED = make_svg(
    """
<g stroke-width="2" stroke-linecap="round" fill="none" dm:move="0.7">
  <line x1="3" y1="12" x2="21" y2="12" stroke="black"/>
  <line x1="12" y1="3" x2="12" y2="21" stroke="black"/>
  <circle cx="12" cy="12" r="3" fill="white" stroke="none"/>
  <path d="M4 4 h6 a2 2 0 0 1 2 2 v2" stroke="black"/>
  <rect x="14" y="14" width="6" height="6" rx="1.5" fill="black" dm:rotate="-8 8"/>
  <polygon points="3 15 9 15 6 20" fill="white" stroke="black" stroke-width="1"/>
</g>"""
)


@pytest.mark.parametrize("flat_fills", [True, None], ids=["fills-near-outlines", "fills-over-their-box"])
@pytest.mark.parametrize("width", [24, 40])
def test_culled_matches_naive_reference_values_and_gradients(width: int, flat_fills: bool | None) -> None:
    """Both ways of culling a black-and-white drawing's fills (near their outlines, as new models
    do; over their whole box, as bundles written before do) match the reference."""
    md = MorphableDrawing.load(LAYERED)
    settings = RasterSettings(width=width, flat_fills=flat_fills)
    gen = torch.Generator().manual_seed(1)
    unit = torch.rand(3, md.n_variables, generator=gen, dtype=torch.float64).requires_grad_(True)
    weights = torch.rand(3, 1, width, width, generator=gen, dtype=torch.float64)

    fast = SoftRasterizer(md.space, settings)(md.values_from_unit(unit))
    (g_fast,) = torch.autograd.grad((fast * weights).sum(), unit)
    slow = naive_render(md.space, md.values_from_unit(unit), settings)
    (g_slow,) = torch.autograd.grad((slow * weights).sum(), unit)

    assert fast.shape == (3, 1, width, width)
    # culling drops terms below sigmoid(-8) = 3.4e-4 per paint; squashes between runs can double
    # that. Fills near their outlines also round a fill's cover up to 1 where no edge reaches
    # (the same 3.4e-4 inside), which a squash's slope of about 3 can take to 2.04e-3 here.
    torch.testing.assert_close(fast, slow, atol=2e-3 if flat_fills is None else 2.5e-3, rtol=0)
    torch.testing.assert_close(g_fast, g_slow, atol=2e-3 * g_slow.abs().max().item(), rtol=1e-3)
    assert g_fast.abs().sum() > 0


def test_white_over_black_shows_white_and_black_over_white_shows_black() -> None:
    body = """<g stroke-width="4" fill="none">
      <line x1="2" y1="12" x2="22" y2="12" stroke="black"/>
      <line x1="2" y1="12" x2="22" y2="12" stroke="black"/>
      <line x1="12" y1="2" x2="12" y2="22" stroke="white"/>
      <line x1="2" y1="4" x2="22" y2="4" stroke="white"/>
      <line x1="12" y1="2" x2="12" y2="8" stroke="black"/>
    </g>"""
    md = MorphableDrawing.load(make_svg(body))
    ink = md.render_soft(md.neutral_values(), 24)[0, 0]
    assert ink[12, 6] > 0.95  # two black strokes: black
    assert ink[12, 12] < 0.05  # white over two black: white
    assert ink[4, 12] > 0.95  # black over white: black


FEATURES = {
    "nested-transforms": """<g transform="translate(12 12) rotate(30)" stroke="black" stroke-width="1.5" fill="none">
        <g transform="scale(1.2 0.8) skewX(10)"><rect x="-6" y="-4" width="12" height="8" rx="2"/></g>
        <line x1="-8" y1="0" x2="8" y2="0" transform="matrix(1 0.2 0 1 0 2)"/></g>""",
    "fills-and-evenodd": """<path d="M3 3 h18 v18 h-18 Z M7 7 v10 h10 v-10 Z" fill="black" fill-rule="evenodd"/>
        <circle cx="12" cy="12" r="2" fill="black"/>""",
    "caps": """<g stroke="black" stroke-width="3"><line x1="4" y1="5" x2="20" y2="5"/>
        <line x1="4" y1="12" x2="20" y2="12" stroke-linecap="square"/>
        <line x1="4" y1="19" x2="20" y2="19" stroke-linecap="round"/></g>""",
    "ellipse-and-half-circles": """<g stroke="black" stroke-width="1.5" fill="none">
        <ellipse cx="12" cy="7" rx="9" ry="3"/><path d="M4 18 A4 4 0 0 1 12 18"/>
        <path d="M13 18 A4 4 0 0 0 21 18 Z" fill="black"/></g>""",
    "dots-and-arcs": """<g stroke="black" stroke-width="2" stroke-linecap="round" fill="none">
        <path d="M12 17h.01"/><line x1="5" y1="5" x2="5" y2="5"/>
        <path d="M3 12a9 9 0 1 0 18 0a9 9 0 0 0-18 0"/><path d="M9 9a3 3 0 0 1 6 0c0 0 0 0 0 0"/></g>""",
}


@pytest.mark.parametrize("name", sorted(FEATURES))
def test_soft_render_matches_resvg(name: str, with_bezier) -> None:
    svg = make_svg(FEATURES[name])
    md = MorphableDrawing.load(svg)
    for width in (96, 160):
        soft = md.render_soft(md.neutral_values(), width).detach()[0, 0].numpy()
        hard = render_svg_ink(svg.decode(), width)
        assert np.abs(soft - hard).mean() < 0.03, (name, width)


@pytest.mark.parametrize(
    "icon",
    [
        "activity",
        "airplay",
        "film",
        "aperture",
        "cpu",
        "anchor",
        "loader",
        "x-circle",
        "umbrella",
        "unlock",
        "cloud-lightning",
    ],
)
def test_feather_icons_match_resvg(icon: str) -> None:
    text = (FEATHER / f"{icon}.svg").read_text()
    md = MorphableDrawing.load(text.encode())
    soft = md.render_soft(md.neutral_values(), 96).detach()[0, 0].numpy()
    assert np.abs(soft - render_svg_ink(text, 96)).mean() < 0.03


def test_morphed_soft_render_matches_resvg_of_written_svg() -> None:
    """The soft raster of a morph and the real render of the SVG written for it agree."""
    md = MorphableDrawing.load(LAYERED)
    values = md.values_from_unit(md.random_unit(4, seed=5))
    soft = md.render_soft(values, 96).detach()[:, 0].numpy()
    for k in range(4):
        hard = render_svg_ink(md.to_svg(values[k]), 96)
        assert np.abs(soft[k] - hard).mean() < 0.03


def _rendered_with_gradient(md: MorphableDrawing, width: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """A soft render of two random morphs of ``md`` and the gradient of its squares' sum."""
    rasterizer = SoftRasterizer(md.space, RasterSettings(width=width), channel=md.channel)
    unit = torch.rand(2, md.n_variables, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    unit.requires_grad_(True)
    values = md.values_from_unit(unit)
    image = rasterizer.render_rgb(values) if md.colour else rasterizer(values)
    (grad,) = torch.autograd.grad(image.square().sum(), unit)
    return image.detach(), grad


@pytest.mark.parametrize("chunk", [1, 50, 4000])
def test_culling_in_chunks_of_any_size_renders_exactly_the_same(
    chunk: int, monkeypatch: pytest.MonkeyPatch, with_bezier: object
) -> None:
    """Culling evaluates every piece's box at once, :data:`~deepmorph_core.flat.CULL_CHUNK`
    distances at a time: a chunk of one piece (1), of a few, or of all gives the same render and
    gradients, bit for bit, on a layered drawing with arcs and on a colour emoji of fills."""
    from deepmorph_core import flat

    emoji = FEATHER.parent / "fluent-emoji-flat" / "eleven-oclock.svg"
    for md in (MorphableDrawing.load(LAYERED), MorphableDrawing.load(emoji, move=0.5)):
        whole = _rendered_with_gradient(md, 48, seed=3)
        monkeypatch.setattr(flat, "CULL_CHUNK", chunk)
        chunked = _rendered_with_gradient(md, 48, seed=3)
        monkeypatch.undo()
        assert torch.equal(whole[0], chunked[0]) and torch.equal(whole[1], chunked[1])


def test_a_bundle_renders_its_fills_as_it_was_trained(tmp_path) -> None:
    """A new model records that its fills are culled near their outlines, and renders so after
    loading; a bundle that records nothing (written before) renders a black-and-white drawing's
    fills over their whole box, bit for bit as it was trained."""
    from deepmorph_core.codec import CodecSpec
    from deepmorph_core.model import DeepMorphModel

    def created(raster: dict) -> DeepMorphModel:
        spec = CodecSpec(payload_bits=4, crc_bits=8, bch_t=0)
        model = DeepMorphModel.create(LAYERED.decode(), "layered.svg", {}, spec, 40, raster, {}, {})
        path = tmp_path / f"{len(raster)}.dmm"
        model.save(path)
        return DeepMorphModel.load(path)

    new, old = created({"flat_fills": True}), created({})
    values = new.drawing.values_from_unit(new.drawing.random_unit(3, seed=2))
    near = SoftRasterizer(new.drawing.space, RasterSettings(width=40, flat_fills=True))(values)
    whole = SoftRasterizer(new.drawing.space, RasterSettings(width=40, flat_fills=False))(values)
    assert not torch.equal(near, whole)  # the two ways differ (by less than the culling's 2e-3)
    assert torch.equal(new.rasterizer()(values), near)
    assert torch.equal(old.rasterizer()(values), whole)
    assert old.raster_settings(96).width == 96 and old.raster_settings().flat_fills is None
