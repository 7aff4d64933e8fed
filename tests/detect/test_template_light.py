"""The light on a print, estimated from its template: a cast shadow divided out, a print the
shadow bends the alignment of aligned again, and the photo chain's use of it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import deepmorph_detect.check as check_module
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.camera import project, viewbox_corners
from deepmorph_detect.fastrender import template_renderer
from deepmorph_detect.locate import BLIND_READ_CORRELATION, Locator
from deepmorph_detect.refine import LEVELS, ImagePyramid, Template, refine
from deepmorph_detect.synthesis import BitEvidence
from deepmorph_detect.template_light import EDGE_MARGINS, SMOOTHING_GRID_SIGMA, TemplateLight, smoothed_light
from tests.conftest import easy_print_aligned

FACE = Path(__file__).parents[1] / "data" / "fluent-emoji-flat" / "face-without-mouth.svg"
PRINT_PX, OFFSET, PAGE = 192, 64, 320


def printed_face() -> tuple[Template, np.ndarray, np.ndarray, np.ndarray]:
    """A yellow face (one large fill) printed 192 px wide on white paper: its template, its
    render at that width, the page and the homography (SVG units -> page pixels) it sits at."""
    from deepmorph_core.morphable import MorphableDrawing

    svg = FACE.read_text()
    viewbox = MorphableDrawing.load(FACE, move=0.5).drawing.viewbox
    _, renderer = template_renderer(svg, viewbox, LEVELS)
    template = Template.from_svg(svg, viewbox, LEVELS, renderer)
    render = renderer(svg, PRINT_PX, viewbox)
    page = np.ones((PAGE, PAGE), np.float32)
    page[OFFSET : OFFSET + PRINT_PX, OFFSET : OFFSET + PRINT_PX] = render
    k = PRINT_PX / viewbox[2]
    H = np.array([[k, 0, OFFSET - k * viewbox[0]], [0, k, OFFSET - k * viewbox[1]], [0, 0, 1]])
    return template, render, page, H


@pytest.fixture(scope="module")
def face() -> tuple[Template, TemplateLight, np.ndarray, np.ndarray]:
    """The printed face: its template, its light, the page and its homography."""
    template, render, page, H = printed_face()
    return template, TemplateLight(template, render), page, H


def _shadowed(page: np.ndarray, turn: float) -> np.ndarray:
    """The page under dim light (0.85) with a sharp shadow (half as bright, 1.5 px penumbra)
    whose edge crosses the print near its middle at angle ``turn``."""
    y, x = np.mgrid[0 : page.shape[0], 0 : page.shape[1]]
    side = (x - 170) * np.cos(turn) + (y - 150) * np.sin(turn)
    return (0.85 * page * (1 - 0.5 / (1 + np.exp(-side / 1.5)))).astype(np.float32)


@pytest.mark.parametrize("turn", [0.4, 1.9])
def test_a_cast_shadow_is_divided_out_of_the_print(face, turn: float) -> None:
    """At the print's alignment the photo divided by the drawing's reflectance is the light;
    divided out, the print is its render again: nine pixels in ten within 0.1 of it, where the
    shadowed photo is half a unit off over the shadow's side."""
    _, light, page, H = face
    photo = _shadowed(page, turn)
    lit = light.lit(photo, H, EDGE_MARGINS[-1])
    assert lit is not None
    region = (slice(OFFSET, OFFSET + PRINT_PX),) * 2
    before, after = np.abs(photo / 0.85 - page)[region], np.abs(lit - page)[region]
    assert np.percentile(before, 90) > 0.45
    assert np.percentile(after, 90) < 0.1 and np.median(after) < 0.01
    beyond = np.ones(page.shape, bool)
    beyond[(slice(OFFSET - 3, OFFSET + PRINT_PX + 3),) * 2] = False
    assert np.array_equal(lit[beyond], photo[beyond])  # the photo beyond the print as it was


@pytest.mark.parametrize("turn", [0.4, 1.2, 1.9, 2.8])
def test_a_print_the_shadow_bends_the_alignment_of_is_aligned_again_in_its_light(face, turn: float) -> None:
    """ECC in the photo bends to the shadow's edge and leaves the print (from the true outline,
    or 4 px off it); in the light the template shows it stays on the print within 1.5 px."""
    template, light, page, H = face
    photo = _shadowed(page, turn)
    corners = viewbox_corners(template.viewbox)
    truth = project(H, corners)
    for shift in (0.0, 4.0):
        start = H.copy()
        start[:2, 2] += (shift, -shift)
        plain = refine(ImagePyramid(photo), start, template)
        assert plain is None or np.abs(project(plain.homography, corners) - truth).max() > 20
        pyramid, alignment = light.align(photo, start, lambda a: a is not None and a.correlation > 0.55)
        assert alignment.correlation > 0.95
        assert np.abs(project(alignment.homography, corners) - truth).max() < 1.5
        assert pyramid.levels[0].shape == photo.shape


def test_a_wide_light_is_smoothed_on_a_shrunk_grid_as_at_full_resolution() -> None:
    """A print's light spans many pixels of a large print: smoothed on a grid shrunk to
    :data:`SMOOTHING_GRID_SIGMA` px per sigma it is the full-resolution normalised convolution
    within 0.005 on 99 % of the pixels it is read at, and as close to the true light."""
    import cv2

    rng = np.random.default_rng(0)
    size, sigma = 480, 30.0
    y, x = np.mgrid[0:size, 0:size]
    truth = (0.6 + 0.3 * np.sin(x / 110) + 0.1 * np.cos(y / 70)).astype(np.float32)
    weight = (rng.random((size, size)) > 0.4).astype(np.float32)
    weight[100:220, 120:360] = 0  # a large fill's edges: no light read there
    ratio = truth * (1 + 0.02 * rng.standard_normal((size, size))).astype(np.float32) * weight
    full = cv2.GaussianBlur(ratio, (0, 0), sigma) / cv2.GaussianBlur(weight, (0, 0), sigma)
    assert sigma > 2 * SMOOTHING_GRID_SIGMA
    light = smoothed_light(ratio, weight, sigma)
    assert light.shape == ratio.shape and light.dtype == np.float32
    read = weight > 0
    assert np.percentile(np.abs(light - full)[read], 99) < 0.005
    assert np.abs(light - truth)[read].mean() < 1.2 * np.abs(full - truth)[read].mean()


def test_a_tiny_print_has_no_light_of_its_own(face) -> None:
    _, light, page, H = face
    tiny = np.diag([0.02, 0.02, 1.0]) @ H
    assert light.lit(page, tiny, EDGE_MARGINS[0]) is None


def test_a_drawing_aligned_well_and_not_read_is_read_again_in_its_light(
    model: DeepMorphModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The photo chain asks the template's light only for a drawing that aligned at
    ``BLIND_READ_CORRELATION`` or better and was not read, and reads it again there; a weak
    reading there counts only where the whole per-bit check passes."""
    from dataclasses import replace

    locator = Locator(model)
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    assert right is not None and right.correlation > BLIND_READ_CORRELATION
    asked: list[float] = []
    real = locator.light.align

    def align(gray: np.ndarray, H: np.ndarray, accepts) -> object:
        asked.append(1.0)
        return real(gray, H, accepts)

    monkeypatch.setattr(locator.light, "align", align)
    read = locator.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True)
    assert read.result.ok and asked == []  # read at once: no second alignment
    unread = locator._decode_at
    # as if the photo itself had not read it: read again in its light, and read there
    first = []

    def decode_at(gray, pyramid, alignment, *args, **kwargs):
        located = unread(gray, pyramid, alignment, *args, **kwargs)
        if not first:
            first.append(located)
            located.result = replace(located.result, ok=False)
        return located

    monkeypatch.setattr(locator, "_decode_at", decode_at)
    # a print whose alignment no flat sheet moves (tests/detect/test_flat_sheet.py has those)
    monkeypatch.setattr(locator.aligner, "as_flat_sheet", lambda pyramid, alignment: None)
    read = locator.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True)
    assert asked == [1.0] and read.result.ok and np.array_equal(read.result.payload, placed.payload)
    first.clear()
    with monkeypatch.context() as m:  # a weak reading there (corrections, or not confident) counts
        m.setattr(check_module, "is_weak", lambda result: True)  # where the whole per-bit check passes
        evidence = locator.checker.synthesis.evidence
        asked_bits: list[int] = []
        m.setattr(locator.checker.synthesis, "evidence", lambda *a: asked_bits.append(1) or evidence(*a))
        read = locator.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True)
        assert read.result.ok and np.array_equal(read.result.payload, placed.payload) and asked_bits
        first.clear()

        def contradicted(*args: object) -> BitEvidence:
            real = evidence(*args)
            return BitEvidence(real.code, -real.evidence, real.fit, real.blur_px)

        m.setattr(locator.checker.synthesis, "evidence", contradicted)  # and not where the bits are contradicted
        assert not locator.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True).result.ok
    first.clear()
    asked.clear()
    low = replace(right, correlation=BLIND_READ_CORRELATION - 0.01)
    assert not locator.decode_drawing(gray, pyramid, low, 1.0, cam, "detector", True).result.ok
    assert asked == []  # aligned too poorly to be worth it
