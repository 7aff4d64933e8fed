"""ECC by inverse composition: the same answers as OpenCV's findTransformECC, from close starts."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from deepmorph_core.bundled import BUNDLED_DRAWING
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.render import render_svg
from deepmorph_detect.camera import project, viewbox_corners
from deepmorph_detect.icalign import InverseECC, inverse3

WIDTH = 128


@pytest.fixture(scope="module")
def template() -> np.ndarray:
    md = MorphableDrawing.load(BUNDLED_DRAWING)
    return render_svg(md.to_svg(md.neutral_values()[0]), WIDTH)


def _photo(template: np.ndarray, warp: np.ndarray, gain: float = 1.0, offset: float = 0.0) -> np.ndarray:
    """The template seen through ``warp`` (template px -> photo px), relit, slightly blurred."""
    h, w = template.shape
    seen = cv2.warpPerspective(template, warp, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return (cv2.GaussianBlur(seen, (0, 0), 0.7) * gain + offset).astype(np.float32)


def _corners(warp: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The image's corners (``shape`` = ``(h, w)``) carried through ``warp``."""
    h, w = shape
    return project(warp, np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64))


def _known_warp() -> np.ndarray:
    """A shift of about 2 px, a 2-degree turn, 3 % scale and a little perspective."""
    a = np.deg2rad(2.0)
    return np.array([[1.03 * np.cos(a), -np.sin(a), 1.8], [np.sin(a), 1.03 * np.cos(a), -1.4], [4e-5, -3e-5, 1.0]])


def test_recovers_a_known_warp_under_other_light(template: np.ndarray) -> None:
    """Contrast halved and paper darkened: the warp is found to a tenth of a pixel."""
    truth = _known_warp()
    photo = _photo(template, truth, gain=0.5, offset=0.2)
    rho, warp = InverseECC(template, 3).align(photo, 30, 1e-6)
    assert rho > 0.98
    err = np.abs(_corners(warp, template.shape) - _corners(truth, template.shape)).max()
    assert err < 0.1, err


def test_agrees_with_opencv_ecc(template: np.ndarray) -> None:
    """The same start, iterations and smoothing: the same warp and correlation as OpenCV's."""
    photo = _photo(template, _known_warp())
    rho, warp = InverseECC(template, 3).align(photo, 6, 1e-5)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 6, 1e-5)
    cv_rho, cv_warp = cv2.findTransformECC(
        template, photo, np.eye(3, dtype=np.float32), cv2.MOTION_HOMOGRAPHY, criteria, None, 3
    )
    assert abs(rho - cv_rho) < 0.01
    diff = np.abs(_corners(warp, template.shape) - _corners(cv_warp.astype(np.float64), template.shape)).max()
    assert diff < 0.2, diff


def test_never_ends_worse_than_it_starts(template: np.ndarray) -> None:
    """Clutter that the drawing does not explain: the correlation returned is at least the
    start's (the best warp met is kept)."""
    rng = np.random.default_rng(0)
    clutter = cv2.GaussianBlur(rng.random(template.shape).astype(np.float32), (0, 0), 3)
    solver = InverseECC(template, 3)
    start = solver.align(clutter, 0, 1e-5)
    end = solver.align(clutter, 10, 1e-5)
    assert start is not None
    assert end is None or end[0] >= start[0]


def test_a_negative_does_not_align(template: np.ndarray) -> None:
    """White ink on black paper anti-correlates: the solve breaks down instead of fitting it."""
    assert InverseECC(template, 3).align(1.0 - _photo(template, _known_warp()), 6, 1e-5) is None


def _ghost_print(print_px: int = 160, margin: int = 60):
    """The unmorphed ghost printed ``print_px`` wide on white paper, its template (both
    levels), the frame's corners and the true homography (SVG units -> photo px)."""
    from deepmorph_detect.refine import Template

    md = MorphableDrawing.load(BUNDLED_DRAWING)
    svg = md.to_svg(md.neutral_values()[0])
    vx, vy, vw, _ = md.drawing.viewbox
    photo = np.pad(render_svg(svg, print_px), margin, constant_values=1.0)
    s = print_px / vw
    truth = np.array([[s, 0, margin - s * vx], [0, s, margin - s * vy], [0, 0, 1.0]])
    return photo, Template.from_svg(svg, md.drawing.viewbox), viewbox_corners(md.drawing.viewbox), truth


def _count_opencv_solves(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    import deepmorph_detect.refine as refine_module

    calls = {"opencv": 0}
    real = cv2.findTransformECC

    def spy(*args, **kwargs):
        calls["opencv"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(refine_module.cv2, "findTransformECC", spy)
    return calls


@pytest.mark.parametrize("wide_basin", [False, True])
def test_refits_take_the_inverse_form_unless_a_wide_basin_is_asked_for(
    wide_basin: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A refit from a start a pixel off solves by inverse composition, or by OpenCV's ECC
    when asked for its wider basin; both land on the print, 80 px (enlarged to the 128 px
    template) or 256 px wide."""
    from deepmorph_detect.refine import ImagePyramid, refine_at

    calls = _count_opencv_solves(monkeypatch)
    calls["inverse"] = 0
    real_align = InverseECC.align

    def spy_align(self, *args, **kwargs):
        calls["inverse"] += 1
        return real_align(self, *args, **kwargs)

    monkeypatch.setattr(InverseECC, "align", spy_align)
    for print_px in (80, 256):
        photo, template, corners, truth = _ghost_print(print_px, margin=40)
        s = truth[0, 0]  # photo px per SVG unit
        start = truth @ np.array([[1.01, 0.01, 0.8], [-0.01, 0.99, -0.6], [0, 0, 1.0]])
        found = refine_at(ImagePyramid(photo), start, template, 128, 20, wide_basin=wide_basin)
        err = np.abs(project(found.homography, corners) - project(truth, corners)).max()
        assert found.correlation > 0.95 and err < 0.3 * s, (print_px, found.correlation, err)
    assert calls == ({"inverse": 0, "opencv": 2} if wide_basin else {"inverse": 2, "opencv": 0})


def test_inverse3_is_the_inverse_and_refuses_singular_matrices() -> None:
    rng = np.random.default_rng(0)
    for _ in range(200):
        m = rng.normal(size=(3, 3))
        np.testing.assert_allclose(inverse3(m) @ m, np.eye(3), atol=1e-9)
        np.testing.assert_allclose(inverse3(m), np.linalg.inv(m), rtol=1e-9, atol=1e-12)
    for bad in (np.zeros((3, 3)), np.array([[1.0, 2, 3], [2, 4, 6], [0, 1, 1]]), np.full((3, 3), np.nan)):
        with pytest.raises(np.linalg.LinAlgError):
            inverse3(bad)


def test_the_runner_up_corner_order_is_not_solved_by_opencv_once_one_order_aligns(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A detector outline a little off, in its right corner order and a quarter turn from it:
    the right order's fast solve clears the bar, so neither takes OpenCV's slower solve, and
    the right one wins."""
    from deepmorph_detect.refine import COARSE_FAST_BAR, ImagePyramid, _coarse_steps, corner_orders, warp_to_template

    photo, template, corners, truth = _ghost_print()
    start = truth @ np.array([[1.03, 0.02, 1.0], [-0.02, 0.98, -0.8], [0, 0, 1.0]])
    pyramid, width = ImagePyramid(photo), min(template.images)
    right, turned = corner_orders(start, template)[:2]
    calls = _count_opencv_solves(monkeypatch)
    starts = [(H, warp_to_template(pyramid, H, template, width)) for H in (turned, right)]
    steps = _coarse_steps(pyramid, starts, template, width, 15, 5)
    assert calls["opencv"] == 0
    assert steps[1] is not None and steps[1][1] >= COARSE_FAST_BAR
    assert steps[0] is None or steps[0][1] < steps[1][1]
    off = np.abs(project(start, corners) - project(truth, corners)).max()
    err = np.abs(project(steps[1][0], corners) - project(truth, corners)).max()
    assert err < 2.0 and err < off / 4, (err, off)  # under a pixel of the 48 px template


def test_opencv_solves_each_order_when_no_fast_solve_clears_the_bar(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two starts on clutter (no drawing): both go on to OpenCV's wider basin."""
    from deepmorph_detect.refine import ImagePyramid, _coarse_steps, warp_to_template

    _, template, _, truth = _ghost_print()
    rng = np.random.default_rng(3)
    clutter = cv2.GaussianBlur(rng.random((280, 280)).astype(np.float32), (0, 0), 2)
    pyramid, width = ImagePyramid(clutter), min(template.images)
    calls = _count_opencv_solves(monkeypatch)
    starts = [(H, warp_to_template(pyramid, H, template, width)) for H in (truth, truth @ np.diag([1.1, 1.1, 1.0]))]
    _coarse_steps(pyramid, starts, template, width, 15, 5)
    assert calls["opencv"] == 2


def test_wider_searches_take_opencvs_solve_once_per_stage(monkeypatch: pytest.MonkeyPatch) -> None:
    """A candidate on clutter, with a bar to reach: every wider search runs (other corner
    orders, the outline sweep, starts from the ink) and fails. OpenCV's solver runs for the
    quick path's orders (two at most) and then once per stage of the wider search, from the
    start whose fast solve came closest, not from every start (six here, before)."""
    from deepmorph_detect.refine import ImagePyramid, refine

    _, template, _, truth = _ghost_print()
    rng = np.random.default_rng(4)
    clutter = np.ones((280, 280), np.float32)
    for _ in range(40):  # dark strokes at random: ink for the sweep and the ink starts to try
        p, q = rng.integers(20, 260, size=(2, 2))
        cv2.line(clutter, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), 0.0, 3)
    calls = _count_opencv_solves(monkeypatch)
    found = refine(ImagePyramid(clutter), truth, template, orders=4, accept=0.55)
    assert found is None or found.correlation < 0.6
    assert 3 <= calls["opencv"] <= 2 + 3
