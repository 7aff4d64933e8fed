"""The light across a print as a grid (deepmorph_detect.light_field): a print under a cast
shadow aligned in it, where ECC's one light bends to the shadow's edge; and the per-bit check's
grid light, read off the flat of the print so that it cannot take up the bits' own edges."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import random_payloads
from deepmorph_detect.camera import project, viewbox_corners
from deepmorph_detect.check import SHADOW_GRID
from deepmorph_detect.light_field import align_in_light_field, grid_fields, hats, realign_in_light_field
from deepmorph_detect.locate import Locator
from deepmorph_detect.refine import ImagePyramid, Template, refine_at
from tests.conftest import easy_print_aligned
from tests.detect.test_synthesis import (  # the face model's fixtures, shared
    _face_synthesis,
    _near_payloads,
    _shadowed_colour_photo,
    face,  # noqa: F401
    face_bundle,  # noqa: F401
)
from tests.detect.test_template_light import OFFSET, PAGE, PRINT_PX, _shadowed, printed_face


@pytest.fixture(scope="module")
def face_print() -> tuple[Template, np.ndarray, np.ndarray]:
    """The yellow face printed 192 px wide on white paper (``test_template_light``): its
    template, the page and the homography (SVG units -> page pixels) it sits at."""
    template, _, page, H = printed_face()
    return template, page, H


def test_the_grid_fields_share_out_the_light_everywhere() -> None:
    """Each pixel's knots' weights add up to 1, and each knot's field peaks at 1 on its knot."""
    fields = grid_fields(37, 50, 6)
    assert fields.shape == (37 * 50, 36)
    assert np.allclose(fields.sum(axis=1), 1.0)
    assert fields.min() >= 0 and np.isclose(fields.max(), 1.0)
    assert np.array_equal(hats(9, 1), np.ones((9, 1)))


@pytest.mark.parametrize("turn", [0.4, 1.2, 1.9, 2.8])
def test_a_print_under_a_cast_shadow_stays_aligned_in_a_grid_of_light(face_print, turn: float) -> None:
    """From the true outline or 3 px off it, ECC at the check's width follows the shadow's edge
    off the print (11-18 px at some corner), while the alignment in a grid of light stays within
    a pixel of the print. The correlation it reports is ECC's at that pose."""
    template, page, H = face_print
    photo = _shadowed(page, turn)
    pyramid = ImagePyramid(photo)
    corners = viewbox_corners(template.viewbox)
    truth = project(H, corners)
    ecc_off = []
    for shift in (0.0, 3.0):
        start = H.copy()
        start[:2, 2] += (shift, -shift)
        plain = refine_at(pyramid, start, template, 128, iterations=20)
        ecc_off.append(np.inf if plain is None else np.abs(project(plain.homography, corners) - truth).max())
        aligned = align_in_light_field(pyramid, start, template, 128)
        assert aligned is not None and aligned.width == 128
        assert np.abs(project(aligned.homography, corners) - truth).max() < 1.0
        assert 0.0 < aligned.correlation < 1.0
    assert max(ecc_off) > 10


@pytest.mark.parametrize("turn", [0.4, 1.9])
def test_a_print_ecc_bent_to_a_shadows_edge_is_aligned_again_in_a_grid_of_light(face_print, turn: float) -> None:
    """From where ECC ended, bent 11-45 px off the print by the shadow's edge, the chain's
    realignment comes back within a pixel of it."""
    template, page, H = face_print
    pyramid = ImagePyramid(_shadowed(page, turn))
    corners = viewbox_corners(template.viewbox)
    truth = project(H, corners)
    for shift in (3.0, 6.0):
        start = H.copy()
        start[:2, 2] += (shift, -shift)
        bent = refine_at(pyramid, start, template, 128, iterations=20)
        assert bent is not None and np.abs(project(bent.homography, corners) - truth).max() > 10
        again = realign_in_light_field(pyramid, bent, template)
        assert again is not None and again.width == 128
        assert np.abs(project(again.homography, corners) - truth).max() < 1.0


def test_asked_in_a_grid_of_light_the_printed_word_agrees_and_near_words_do_not(
    face: DeepMorphModel,  # noqa: F811
) -> None:
    """Under a cast shadow's band, the face's printed word agrees in a grid of light, and each
    near word is still refused: a grid fitted everywhere would take up the bits' own edges and
    show every bit of any word at +1."""
    synthesis = _face_synthesis(face)
    rng = np.random.default_rng(7)
    for k, payload in enumerate(random_payloads(3, 12, rng)):
        code = face.codec.encode(payload)
        photo, H = _shadowed_colour_photo(face, code, k, angle=0.6 + 0.7 * k, offset=0.05 * (k - 1))
        pyramid = ImagePyramid(photo)
        assert synthesis.evidence(pyramid, H, code, light_grid=SHADOW_GRID).agrees
        for near in _near_payloads(payload)[k : k + 3]:
            asked = synthesis.evidence(pyramid, H, face.codec.encode(near), light_grid=SHADOW_GRID)
            assert not asked.agrees
            assert asked.contradicted > 0


def _half_shadowed_photo(model: DeepMorphModel, code: np.ndarray, seed: int, angle: float, offset: float):
    """A 192-px print of ``code``'s morph on a 320-px page, half of it under a cast shadow
    (55 % of the light taken, a 4-px penumbra) whose edge lies at angle ``angle``, ``offset``
    print widths from the centre; blurred and noisy (by ``seed``), in the model's reading
    channel; and its homography (SVG units -> px)."""
    import cv2
    import torch

    from deepmorph_core.render import render_svg_rgb

    values = model.morph_values(torch.from_numpy(code[None].astype(np.float32)))[0]
    page = np.ones((PAGE, PAGE, 3), np.float32)
    page[OFFSET : OFFSET + PRINT_PX, OFFSET : OFFSET + PRINT_PX] = render_svg_rgb(
        model.drawing.to_svg(values), PRINT_PX
    )
    y, x = np.mgrid[0:PAGE, 0:PAGE].astype(np.float32)
    side = (x - PAGE / 2) * np.cos(angle) + (y - PAGE / 2) * np.sin(angle) - offset * PRINT_PX
    light = 1 - 0.55 / (1 + np.exp(-side / 4.0))
    photo = cv2.GaussianBlur((page * light[..., None]) @ np.asarray(model.drawing.channel, np.float32), (0, 0), 1.0)
    photo = photo * 0.8 + 0.1 + np.random.default_rng(seed).normal(0, 0.01, photo.shape)
    x0, y0, vw, _ = model.drawing.drawing.viewbox
    s = PRINT_PX / vw
    return np.clip(photo, 0, 1).astype(np.float32), np.array(
        [[s, 0, OFFSET - x0 * s], [0, s, OFFSET - y0 * s], [0, 0, 1]]
    )


def test_a_right_word_under_a_cast_shadow_passes_the_check_in_its_light_and_near_words_do_not(
    face: DeepMorphModel,  # noqa: F811
) -> None:
    """Under half a page of shadow, one of four right words fails the morph check in ECC's one
    light (the shadow's edge bends its morph fit); asked again in the shadow's grid of light,
    it passes, as the other three do. No word one payload bit away passes, asked either way."""
    from deepmorph_core.codec import DecodeResult

    checker = Locator(face).checker
    rng = np.random.default_rng(1)
    smooth_failed = 0
    for k, payload in enumerate(random_payloads(4, 12, rng)):
        photo, H = _half_shadowed_photo(face, face.codec.encode(payload), k, 0.3 + 0.5 * k, 0.15 * (k - 2))
        pyramid = ImagePyramid(photo)
        read = DecodeResult(payload=payload, ok=True, corrected_bits=1, confidence=0.9)
        smooth = checker._verdict(pyramid, H, read, None, True, False, False, None)
        smooth_failed += smooth.status != "passed"
        assert checker.check(pyramid, H, read).status == "passed"
        for near in _near_payloads(payload)[k : k + 3]:
            assert not checker.check(pyramid, H, replace(read, payload=near)).result.ok
    assert smooth_failed >= 1


def test_an_unread_print_is_aligned_again_in_a_grid_of_light_and_checked_only_there(
    model: DeepMorphModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The chain's last step: a print aligned well, read neither in the photo nor in its
    template's light, is aligned again in a grid of light and read there. A reading there is
    checked in the shadow's light alone, and in full even when confident (ECC's morph fit,
    started there, slides back to the bent pose, and would compare with an alignment that ECC
    did not make); where its bits are contradicted there it is not read."""
    from deepmorph_detect.synthesis import BitEvidence

    locator = Locator(model)
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    real_decode, real_verdict = locator._decode_at, locator.checker._verdict
    steps: list[bool] = []
    grids: list[tuple[bool, int]] = []

    def decode_at(*args, in_shadow: bool = False, **kwargs):
        steps.append(in_shadow)
        located = real_decode(*args, in_shadow=in_shadow, **kwargs)
        if not in_shadow:  # as if neither the photo nor its template's light had read it
            located.result = replace(located.result, ok=False)
        return located

    def verdict(pyramid, H, result, unmorphed, bitwise, *args, **kwargs):
        grids.append((bitwise, args[3] if len(args) >= 4 else 0))  # blind, whole_frame, relit_from, light_grid, ...
        return real_verdict(pyramid, H, result, unmorphed, bitwise, *args, **kwargs)

    monkeypatch.setattr(locator, "_decode_at", decode_at)
    monkeypatch.setattr(locator.checker, "_verdict", verdict)
    monkeypatch.setattr(locator.aligner, "as_flat_sheet", lambda pyramid, alignment: None)
    read = locator.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True)
    assert steps[-1] is True and read.result.ok and np.array_equal(read.result.payload, placed.payload)
    assert grids[-1] == (True, SHADOW_GRID)  # asked bit by bit, in the shadow's grid, and only so
    assert np.abs(read.corners - placed.corners).max() < 2
    evidence = locator.checker.synthesis.evidence

    def contradicted(*args: object) -> BitEvidence:
        real = evidence(*args)
        return BitEvidence(real.code, -real.evidence, real.fit, real.blur_px)

    monkeypatch.setattr(locator.checker.synthesis, "evidence", contradicted)
    assert not locator.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True).result.ok
