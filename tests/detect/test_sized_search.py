"""The universal detector's outlines (``Candidate.sized``): their turn comes from the print's ink,
so their sweep is their corner orders only, enlarged (a print seen steeply from the side is
wider than its ink square); an outline from a detector that knows the drawing sweeps turns and
scales."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.protocols import Candidate
from deepmorph_core.render import render_svg
from deepmorph_detect import refine as refine_module
from deepmorph_detect.align import Aligner, ink_thickness
from deepmorph_detect.camera import Camera, homography_from_pose, project, viewbox_corners
from deepmorph_detect.locate import Locator
from deepmorph_detect.propose import quad_bbox
from deepmorph_detect.refine import SIZED_SWEEP_SCALES, SWEEP_TURNS, ImagePyramid, Template, refine
from tests.detect.colour_close_ups import close_up_proposals, corner_error

FEATHER = Path(__file__).parents[1] / "data" / "feather"


def test_a_sized_outline_sweeps_its_corner_orders_enlarged(locator: Locator, monkeypatch: pytest.MonkeyPatch) -> None:
    """On a photo of noise (nothing aligns, so every wider search runs), a sized outline takes
    the corner orders, its four orders enlarged and the ink starts; an unsized one takes the
    whole sweep of turns and scales."""
    photo = np.random.default_rng(0).uniform(0.2, 1.0, (480, 640)).astype(np.float32)
    start = locator.aligner.homography(np.array([[200.0, 120], [440, 120], [440, 360], [200, 360]]))
    swept: list[tuple[int, tuple[float, ...]]] = []
    inked: list[bool] = []
    sweep, ink = refine_module.outline_sweep, refine_module.ink_starts

    def recorded_sweep(homography, template, turns=SWEEP_TURNS, scales=refine_module.SWEEP_SCALES):  # noqa: ANN001, ANN202
        swept.append((turns, tuple(scales)))
        return sweep(homography, template, turns, scales)

    monkeypatch.setattr(refine_module, "outline_sweep", recorded_sweep)
    monkeypatch.setattr(refine_module, "ink_starts", lambda *a, **k: inked.append(True) or ink(*a, **k))
    for sized in (True, False):
        swept.clear()
        inked.clear()
        found = refine(ImagePyramid(photo), start, locator.template, orders=4, accept=0.55, sized=sized)
        assert found is None or found.correlation < 0.6
        assert swept == ([(4, SIZED_SWEEP_SCALES)] if sized else [(SWEEP_TURNS, refine_module.SWEEP_SCALES)])
        assert inked == [True]


def _steep_photo(svg: str, viewbox: tuple[float, float, float, float], tilt_deg: float, seed: int):  # noqa: ANN202
    """A 640x480 photo of a print of ``svg`` tilted ``tilt_deg`` from head-on about a random axis,
    turned at random, over dark stripes; and the drawing frame's true corners in it."""
    rng = np.random.default_rng(seed)
    width, height = 640, 480
    camera = Camera.default(width, height)
    art, margin = render_svg(svg, 400), 60
    paper = np.pad(art, margin, constant_values=1.0)
    side = paper.shape[1]
    axis, spin = rng.uniform(0, 2 * math.pi, 2)
    tilt, _ = cv2.Rodrigues(np.array([math.cos(axis), math.sin(axis), 0.0]) * math.radians(tilt_deg))
    turn, _ = cv2.Rodrigues(np.array([0.0, 0.0, spin]))
    rvec, _ = cv2.Rodrigues(tilt @ turn)
    sheet = homography_from_pose(camera, rvec.ravel(), np.array([0.0, 0.0, camera.fx / (0.45 * width)]))
    paper_to_photo = sheet @ np.array([[1 / side, 0, -0.5], [0, 1 / side, -0.5], [0, 0, 1]])
    photo = np.full((height, width), 0.4, np.float32)
    photo[:, ::20] = 0.2
    seen = cv2.warpPerspective(paper, paper_to_photo, (width, height), borderValue=-1)
    photo = np.where(seen >= 0, seen * 0.85 + 0.08, photo).astype(np.float32)
    photo = cv2.GaussianBlur(photo, (3, 3), 0) + rng.normal(0, 0.02, photo.shape).astype(np.float32)
    s = 400 / viewbox[2]
    svg_to_paper = np.array([[s, 0, margin - viewbox[0] * s], [0, s, margin - viewbox[1] * s], [0, 0, 1]])
    return np.clip(photo, 0, 1), project(paper_to_photo @ svg_to_paper, viewbox_corners(viewbox))


def test_a_print_seen_steeply_is_aligned_from_an_outline_that_falls_short_of_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The Feather chip tilted 55 degrees, outlined at 0.8 of its size as the universal detector
    outlines such prints in 1280x720 scenes: ECC diverges from each corner order as it is, and
    aligns to within 2 px from the enlarged ones."""
    md = MorphableDrawing.load(FEATHER / "cpu.svg", move=0.5)
    svg, viewbox = md.to_svg(md.neutral_values()[0]), md.drawing.viewbox
    template = Template.from_svg(svg, viewbox)
    aligner = Aligner(template, 0.55, ink_thickness(template, 256), 256)

    def aligned_off(photo: np.ndarray, truth: np.ndarray) -> float:
        short = truth.mean(0) + 0.8 * (truth - truth.mean(0))
        cand = Candidate(short, 0.5, quad_bbox(short, 640, 480), source="universal", sized=True, blind=True)
        _, alignment = aligner.align_outline(ImagePyramid(photo), cand, photo)
        if not aligner.accepts(alignment):
            return math.inf
        found = project(alignment.homography, viewbox_corners(viewbox))
        # the chip looks the same turned: the corners in any cyclic order
        return min(float(np.abs(np.roll(found, k, 0) - truth).max()) for k in range(4))

    photos = [_steep_photo(svg, viewbox, 55.0, seed) for seed in range(3)]
    assert all(aligned_off(photo, truth) < 2.0 for photo, truth in photos)
    monkeypatch.setattr(refine_module, "SIZED_SWEEP_SCALES", (1.0,))
    assert all(aligned_off(photo, truth) == math.inf for photo, truth in photos)


def test_a_black_and_white_drawing_s_blind_outline_mostly_goes_without_opencvs_fallback(
    locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a photo of noise (nothing aligns, so every search runs), a blind proposer's outline of a
    black-and-white drawing is solved without OpenCV's wider-basin ECC on its quick paths, in the
    photo and in flat light, and in its sweep (with it only from its other corner orders). An
    outline from a detector that knows the drawing falls back on it everywhere, and a colour
    drawing's blind outline everywhere but the photo's quick path."""
    import deepmorph_detect.align as align_module

    photo = np.random.default_rng(1).uniform(0.2, 1.0, (480, 640)).astype(np.float32)
    corners = np.array([[200.0, 120], [440, 120], [440, 360], [200, 360]])
    asked: list[tuple[bool, bool]] = []
    opencv_solves: list[int] = []
    ecc = cv2.findTransformECC

    def recorded(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        asked.append((kwargs.get("fallback", True), kwargs.get("sweep_fallback", True)))
        return refine(*args, **kwargs)

    monkeypatch.setattr(align_module, "refine", recorded)
    monkeypatch.setattr(refine_module.cv2, "findTransformECC", lambda *a: opencv_solves.append(1) or ecc(*a))
    solves = {}
    for blind in (True, False):
        asked.clear()
        opencv_solves.clear()
        cand = Candidate(corners, 0.9, quad_bbox(corners, 640, 480), source="test", sized=blind, blind=blind)
        locator.aligner.align_outline(ImagePyramid(photo), cand, photo)
        assert asked == [(not blind, not blind)] * 2  # the photo, then flat light
        solves[blind] = len(opencv_solves)
    assert solves[True] < solves[False]
    # an aligner for a colour drawing keeps the fallback in a blind outline's flat light
    asked.clear()
    cand = Candidate(corners, 0.9, quad_bbox(corners, 640, 480), source="test", sized=True, blind=True)
    colour = Aligner(locator.aligner.template, locator.aligner.min_correlation, 4.0, 256, blind_fallback=True)
    colour.align_outline(ImagePyramid(photo), cand, photo)
    assert asked == [(False, True), (True, True)]


@pytest.mark.parametrize(
    "photo", ["ink_square_on_badge_colour_close_up", "ink_square_on_badge_misaligned_colour_close_up"]
)
def test_a_colour_print_squared_by_its_dark_badge_aligns_from_a_shifted_sweep(
    add_row: tuple[Template, Aligner], photo: str
) -> None:
    """Hard close-ups of the Icons8 add-row, whose dark badge the universal detector squares
    instead of the whole print: with its square's centre swept too (a colour drawing's aligner)
    the print aligns within 3 % of its width; from turns and scales alone it aligns nowhere, or at
    a wrong pose."""
    template, aligner = add_row
    gray, truth, candidates = close_up_proposals(Path(__file__).parents[1] / "data" / "photos" / f"{photo}.png")

    def errors(shifted: bool) -> list[float]:
        aligner.shifted_sweep = shifted
        kept = aligner.verify(ImagePyramid(gray), candidates, gray)
        # add-row looks nothing like itself turned: the corners in their own order
        return [corner_error(a.alignment.homography, template, truth) for a in kept]

    try:
        unshifted, shifted = errors(False), errors(True)
    finally:
        aligner.shifted_sweep = True  # as the fixture made it
    assert all(error > 0.15 for error in unshifted)
    assert min(shifted) < 0.03


def test_a_colour_drawing_s_ink_square_is_moved_off_its_centre_last(
    add_row: tuple[Template, Aligner], monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a photo of noise (nothing aligns, so every wider search runs), a colour drawing's ink
    square is swept as any ink square is (its corner orders enlarged, the ink starts), and only
    then moved off its centre, the place it started from left out; without ``shifted`` it is not."""
    template, _ = add_row
    photo = np.random.default_rng(2).uniform(0.2, 1.0, (480, 640)).astype(np.float32)
    start = Aligner(template, 0.55, 4.0, 256).homography(np.array([[200.0, 120], [440, 120], [440, 360], [200, 360]]))
    steps: list[str] = []
    sweep, ink = refine_module.outline_sweep, refine_module.ink_starts

    def recorded_sweep(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        starts = sweep(*args, **kwargs)
        steps.append(f"sweep of {len(starts)}")
        return starts

    monkeypatch.setattr(refine_module, "outline_sweep", recorded_sweep)
    monkeypatch.setattr(refine_module, "ink_starts", lambda *a, **k: steps.append("ink") or ink(*a, **k))
    for shifted in (True, False):
        steps.clear()
        refine(ImagePyramid(photo), start, template, orders=4, accept=0.55, sized=True, shifted=shifted)
        moved = len(refine_module.SHIFTED_SWEEP_SCALES) * (len(refine_module.SHIFTED_SWEEP_SHIFTS) ** 2 - 1) * 4
        centred = [f"sweep of {4 * len(SIZED_SWEEP_SCALES)}", "ink"]
        assert steps == ([*centred, f"sweep of {moved}"] if shifted else centred)
