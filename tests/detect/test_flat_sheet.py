"""A print aligned again as a flat sheet: a cast shadow's edge bends a full homography away from
the print; an alignment without perspective stays on it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.align import BENT_OUTLINE, MIN_CORRELATION, WEAK_ALIGNMENT, Aligner, ink_thickness
from deepmorph_detect.camera import project, rigid_misfit, viewbox_corners
from deepmorph_detect.locate import BLIND_READ_CORRELATION, Locator
from deepmorph_detect.refine import ImagePyramid, nearest_affine, refine, refine_affine
from tests.conftest import easy_print_aligned
from tests.detect.colour_close_ups import VIEW_WIDTH, close_up, corner_error

DATA = Path(__file__).parents[1] / "data"
PHOTO = DATA / "photos" / "shadow_across_colour_close_up.png"
BENDING = DATA / "photos" / "shadow_bending_colour_close_up.png"
RUN_OFF = DATA / "photos" / "outline_run_off_colour_close_up.png"


def test_the_nearest_affine_map_keeps_an_affine_one_and_flattens_a_perspective(crystal) -> None:
    template, _ = crystal
    affine = np.array([[2.0, 0.3, 40.0], [-0.2, 1.8, 25.0], [0.0, 0.0, 1.0]])
    assert np.allclose(nearest_affine(affine, template), affine)
    seen = affine.copy()
    seen[2, :2] = (4e-4, -3e-4)  # the same sheet tilted
    flat = nearest_affine(seen, template)
    assert np.allclose(flat[2], (0.0, 0.0, 1.0))
    corners = viewbox_corners(template.viewbox)
    quad, fitted = project(seen, corners), project(flat, corners)
    # a least-squares parallelogram: the quad's centre kept, each corner moved less than the tilt
    assert np.allclose(quad.mean(0), fitted.mean(0), atol=1e-6)
    assert np.abs(fitted - quad).max() < np.abs(project(affine, corners) - quad).max()


def test_a_close_up_a_shadow_bends_the_alignment_of_is_aligned_again_as_a_flat_sheet(crystal) -> None:
    """A colour close-up from the simulator, a cast shadow's edge across the crystal's light
    body: from the universal detector's proposal the full homography bends a corner onto the
    shadow (a fifth of the print's width off) and still aligns above 0.8; aligned again as a
    flat sheet, its corners are within 3 % of its width of the truth (the sheet is tilted a
    little: no affine map fits it closer) and it aligns better."""
    template, aligner = crystal
    gray, truth, candidate = close_up(PHOTO)
    (aligned,) = aligner.verify(ImagePyramid(gray), [candidate], gray)
    assert aligned.alignment.correlation > 0.8
    assert corner_error(aligned.alignment.homography, template, truth) > 0.15
    # bent: no flat print makes that outline; the truth and the flat sheet are ones
    assert aligner.bent(aligned.alignment.homography, gray.shape)
    sheet = aligner.as_flat_sheet(aligned.pyramid, aligned.alignment)
    assert sheet is not None
    assert corner_error(sheet.homography, template, truth) < 0.03
    assert sheet.correlation > aligned.alignment.correlation
    assert not aligner.bent(sheet.homography, gray.shape)
    assert rigid_misfit(aligner.homography(truth), aligner.frame_corners, gray.shape[::-1]) < 0.002
    # aligned at the truth already: nothing moves far enough to be read again
    at_truth = refine_affine(aligned.pyramid, sheet.homography, template)
    assert at_truth is not None and corner_error(at_truth.homography, template, truth) < 0.03
    assert aligner.as_flat_sheet(aligned.pyramid, at_truth) is None


def test_an_alignment_no_flat_print_makes_is_aligned_again_in_flat_light(crystal) -> None:
    """A colour close-up from the simulator, a cast shadow across the crystal's lower half. In
    the photo alone the full homography bends the outline a third of the print's width off, and
    aligns above ``WEAK_ALIGNMENT``, so only its shape says it is wrong: no flat print makes it
    (its ``rigid_misfit`` is over ``BENT_OUTLINE``). So it is aligned in flat light too, which
    lands within 4 % of the truth and correlates better."""
    template, aligner = crystal
    gray, truth, candidate = close_up(BENDING)
    pyramid = ImagePyramid(gray)
    (in_photo,) = aligner.verify(pyramid, [candidate])
    assert in_photo.alignment.correlation > WEAK_ALIGNMENT and not in_photo.alignment.searched
    assert corner_error(in_photo.alignment.homography, template, truth) > 0.3
    assert rigid_misfit(in_photo.alignment.homography, aligner.frame_corners, gray.shape[::-1]) > BENT_OUTLINE
    (aligned,) = aligner.verify(pyramid, [candidate], gray)
    assert aligned.pyramid is not pyramid  # kept from flat light
    assert aligned.alignment.correlation > in_photo.alignment.correlation
    assert corner_error(aligned.alignment.homography, template, truth) < 0.04
    assert not aligner.bent(aligned.alignment.homography, gray.shape)


@pytest.mark.parametrize("sheet_reads", [True, False])
def test_a_print_aligned_and_not_read_is_read_again_as_a_flat_sheet_then_in_its_light(
    model: DeepMorphModel, monkeypatch: pytest.MonkeyPatch, sheet_reads: bool
) -> None:
    """The photo chain's order for a print aligned but not read: read again where it aligns as
    a flat sheet (when that aligns at ``BLIND_READ_CORRELATION`` or better); not read there
    either, aligned again in its template's light from the flat sheet's outline, not the bent
    one."""
    locator = Locator(model)
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    bent = replace(right, homography=right.homography @ np.diag([1.1, 1.0, 1.0]))
    read_at: list[np.ndarray] = []
    real = locator._decode_at

    def decode_at(gray, pyramid, alignment, *args, **kwargs):
        located = real(gray, pyramid, alignment, *args, **kwargs)
        if not kwargs.get("in_shadow"):  # the grid of light's step comes last (test_light_field.py)
            read_at.append(alignment.homography)
        if alignment is bent or not sheet_reads:
            located.result = replace(located.result, ok=False)
        return located

    lit_from: list[np.ndarray] = []
    monkeypatch.setattr(locator, "_decode_at", decode_at)
    monkeypatch.setattr(locator.aligner, "as_flat_sheet", lambda pyramid, alignment: right)
    monkeypatch.setattr(locator.light, "align", lambda gray, H, accepts: lit_from.append(H))
    read = locator.decode_drawing(gray, pyramid, bent, 1.0, cam, "detector", True)
    assert [id(h) for h in read_at[:2]] == [id(bent.homography), id(right.homography)]
    if sheet_reads:
        assert read.result.ok and np.array_equal(read.result.payload, placed.payload) and lit_from == []
    else:
        assert not read.result.ok and len(lit_from) == 1 and lit_from[0] is right.homography
    # a flat sheet that aligns worse than the bar is not read: the light starts from the bent outline
    read_at.clear(), lit_from.clear()
    weak = replace(right, correlation=BLIND_READ_CORRELATION - 0.01)
    monkeypatch.setattr(locator.aligner, "as_flat_sheet", lambda pyramid, alignment: weak)
    locator.decode_drawing(gray, pyramid, bent, 1.0, cam, "detector", True)
    assert len(read_at) == 1 and lit_from == [bent.homography]


def test_an_outline_neither_the_photo_nor_flat_light_aligns_is_aligned_as_a_flat_sheet(heart) -> None:
    """A clear medium colour close-up of the pink heart in soft light, outlined by the universal
    detector at another turn: ECC's full homography from that outline, searched at every corner
    order, runs off in the photo and in flat light alike (it does even from the truth), so
    nothing there is accepted. Aligned as a flat sheet from the same outline, the heart is
    accepted where an affine solve from the truth itself lands (the sheet is tilted: no affine
    map fits it closer than a tenth of its width at the frame's corners), and it is kept."""
    template, aligner = heart
    gray, truth, candidate = close_up(RUN_OFF)
    pyramid = ImagePyramid(gray)
    for seen_in in (pyramid, aligner.in_flat_light(gray, candidate.corners)):
        full = refine(seen_in, aligner.homography(candidate.corners), template, orders=4, accept=MIN_CORRELATION)
        assert not aligner.accepts(full)
    sheet = aligner.outline_as_flat_sheet(pyramid, candidate)
    assert sheet is not None and aligner.accepts(sheet)
    from_truth = refine_affine(pyramid, aligner.homography(truth), template)
    assert from_truth is not None
    off = corner_error(sheet.homography, template, truth)
    assert abs(off - corner_error(from_truth.homography, template, truth)) < 0.01 and off < 0.12
    (aligned,) = aligner.verify(pyramid, [candidate], gray)
    assert aligned.pyramid is pyramid and np.allclose(aligned.alignment.homography, sheet.homography)


def test_only_a_colour_drawing_aligns_an_outline_as_a_flat_sheet(heart, model: DeepMorphModel) -> None:
    """The flat sheet read more close-ups of colour drawings and none of black-and-white ones,
    while every other drawing's outline that reaches it costs a few milliseconds: the photo
    chain's aligner takes it for a colour drawing only. Without it the heart's outline that ran
    off everywhere else is not kept."""
    template, aligner = heart
    gray, _, candidate = close_up(RUN_OFF)
    pyramid = ImagePyramid(gray)
    assert aligner.flat_sheet and len(aligner.verify(pyramid, [candidate], gray)) == 1
    without = Aligner(template, MIN_CORRELATION, ink_thickness(template, VIEW_WIDTH), VIEW_WIDTH, flat_sheet=False)
    assert without.verify(pyramid, [candidate], gray) == []
    assert not Locator(model).aligner.flat_sheet  # the ghost, in black ink
