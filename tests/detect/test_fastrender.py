"""Skia, the fast template renderer, against resvg, the reference renderer."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.render import render_svg
from deepmorph_detect.check import MORPH_WIDTH
from deepmorph_detect.fastrender import (
    MAX_MEAN_DIFFERENCE,
    render_svg_resvg,
    render_svg_skia,
    renders_alike,
    template_renderer,
)
from deepmorph_detect.locate import Locator
from deepmorph_detect.synthesis import morph_template

DATA = Path(__file__).parent.parent / "data"
FEATHER = sorted((DATA / "feather").glob("*.svg"))


def _viewbox(svg: str) -> tuple[float, float, float, float]:
    x, y, w, h = (float(v) for v in re.search(r'viewBox="([^"]+)"', svg).group(1).split())
    return x, y, w, h


@pytest.mark.parametrize("path", FEATHER[::12], ids=lambda p: p.stem)
def test_skia_draws_feather_icons_as_resvg_does(path: Path) -> None:
    svg = path.read_text()
    for width in (48, 128):
        fast, reference = render_svg_skia(svg, width, _viewbox(svg)), render_svg(svg, width)
        assert fast.shape == reference.shape and fast.dtype == np.float32
        assert np.abs(fast - reference).mean() <= MAX_MEAN_DIFFERENCE
        # the same ink, to within the anti-aliased edge
        assert abs(float((fast < 0.5).mean()) - float((reference < 0.5).mean())) < 0.01
    assert template_renderer(svg, _viewbox(svg), (48, 128))[0] == "skia"


def test_every_bundled_feather_icon_keeps_skia() -> None:
    worst = max(renders_alike(p.read_text(), _viewbox(p.read_text()), (48,)) for p in FEATHER)
    assert worst <= MAX_MEAN_DIFFERENCE


SQUARE = '<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64" viewBox="0 0 64 64">{}</svg>'


@pytest.mark.parametrize(
    "body",
    [
        # markers at the ends of a line: resvg draws them, Skia's SVG module does not
        '<defs><marker id="m" markerWidth="10" markerHeight="10" refX="5" refY="5"><circle cx="5" cy="5" r="5"/>'
        '</marker></defs><line x1="8" y1="32" x2="56" y2="32" stroke="#000" marker-start="url(#m)" marker-end="url(#m)"/>',
        # transform-origin: resvg turns the bar about it, Skia about the origin (off the page)
        '<rect x="16" y="16" width="32" height="8" transform="rotate(90)" transform-origin="32 20"/>',
    ],
    ids=["markers", "transform-origin"],
)
def test_a_drawing_skia_draws_differently_is_rendered_by_resvg(body: str) -> None:
    svg = SQUARE.format(body)
    assert renders_alike(svg, (0, 0, 64, 64), (48, 128)) > MAX_MEAN_DIFFERENCE
    name, renderer = template_renderer(svg, (0, 0, 64, 64), (48, 128))
    assert name == "resvg" and renderer is render_svg_resvg
    assert np.array_equal(renderer(svg, 64, (0, 0, 64, 64)), render_svg(svg, 64))


def test_size_comes_from_the_viewbox_without_width_and_height() -> None:
    svg = (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 40 20">'
        '<line x1="2" y1="10" x2="38" y2="10" stroke="#000" stroke-width="2"/></svg>'
    )
    fast, reference = render_svg_skia(svg, 120, (0, 0, 40, 20)), render_svg(svg, 120)
    assert fast.shape == reference.shape == (60, 120)
    assert np.abs(fast - reference).mean() <= MAX_MEAN_DIFFERENCE


@pytest.mark.parametrize("text", ["", "not an svg", "<svg", "\x00\x01binary"])
def test_an_unreadable_document_is_one_clear_error(text: str) -> None:
    with pytest.raises(DeepMorphError, match="refused the drawing"):
        render_svg_skia(text, 64, (0, 0, 64, 64))
    with pytest.raises(DeepMorphError, match="refused the drawing"):  # resvg refuses it too
        template_renderer(text, (0, 0, 64, 64), (48,))


def test_the_ghost_locator_renders_templates_and_morphs_with_skia(model: DeepMorphModel, locator: Locator) -> None:
    assert locator.renderer_name == "skia"
    code = model.codec.encode(np.random.default_rng(3).integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8))
    fast = locator.morphs.of_code(code).images[MORPH_WIDTH]
    reference = morph_template(model, locator.viewbox, code, MORPH_WIDTH).images[MORPH_WIDTH]  # resvg
    assert np.abs(fast - reference).mean() <= MAX_MEAN_DIFFERENCE
    # the morph moved the drawing: what the check compares differs far more than the renderers do
    unmorphed = locator.template.images[MORPH_WIDTH]
    assert np.abs(fast - unmorphed).mean() > 3 * np.abs(fast - reference).mean()


def test_supersampling_puts_skias_edges_where_exact_coverage_does() -> None:
    """At its final size Skia's anti-aliasing misplaces edges by up to a tenth of a pixel (poses
    aligned to such templates were worse); drawn at 4x and averaged, it is close to the exact
    coverage of each pixel (resvg at 8x, averaged)."""
    import cv2

    from deepmorph_core.bundled import BUNDLED_DRAWING

    svg = BUNDLED_DRAWING.read_text()
    exact = cv2.resize(render_svg(svg, 1024), (128, 128), interpolation=cv2.INTER_AREA)
    plain = render_svg_skia(svg, 128, (0, 0, 64, 64), supersample=1)
    fine = render_svg_skia(svg, 128, (0, 0, 64, 64))
    assert np.abs(fine - exact).mean() < 0.6 * np.abs(plain - exact).mean()


def test_without_skia_every_template_is_rendered_by_resvg(monkeypatch: pytest.MonkeyPatch) -> None:
    """The wheel needs the system's libGL/libEGL; where it cannot load, decoding still works."""
    import deepmorph_detect.fastrender as fastrender

    monkeypatch.setattr(fastrender, "skia", None)
    monkeypatch.setattr(fastrender, "SKIA_UNAVAILABLE", "skia-python cannot be loaded (libEGL.so.1: missing)")
    svg = FEATHER[0].read_text()
    assert fastrender.template_renderer(svg, _viewbox(svg), (48, 128))[0] == "resvg"
    with pytest.raises(DeepMorphError, match="Skia is not available.*libEGL"):
        render_svg_skia(svg, 64, _viewbox(svg))


@pytest.mark.parametrize("k", [2, 3, 4, 8])
def test_supersampled_renders_are_averaged_over_whole_blocks(k: int) -> None:
    """Halved in 8 bits while an even factor above 2 is left, then averaged in float: at most
    one 8-bit rounding away from the exact block average."""
    from deepmorph_detect.fastrender import _area_average

    big = np.random.default_rng(k).integers(0, 256, (40 * k, 56 * k), dtype=np.uint8)
    exact = big.reshape(40, k, 56, k).astype(np.float64).mean((1, 3)) / 255
    got = _area_average(big, k)
    assert got.shape == (40, 56) and got.dtype == np.float32
    assert np.abs(got - exact).max() <= 0.5 / 255 + 1e-6
