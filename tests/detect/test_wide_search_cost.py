"""What the wider searches spend on a candidate that is not the drawing: a blind quick path that
falls short ends there when flat light searches again (no OpenCV fallback), a wider search
carries only coarse solves that reach ``WIDE_CARRY_FROM`` to the finer level, and the ink's
starts never fall back on OpenCV; a clear print still aligns on the quick path alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from deepmorph_core.morphable import MorphableDrawing
from deepmorph_detect import refine as refine_module
from deepmorph_detect.align import Aligner, ink_thickness
from deepmorph_detect.locate import Locator
from deepmorph_detect.refine import WIDE_CARRY_FROM, ImagePyramid, Template, refine
from tests.detect.test_sized_search import _steep_photo

FEATHER = Path(__file__).parents[1] / "data" / "feather"
OUTLINE = np.array([[200.0, 120], [440, 120], [440, 360], [200, 360]])


def _noise() -> np.ndarray:
    return np.random.default_rng(0).uniform(0.2, 1.0, (480, 640)).astype(np.float32)


def _count_opencv(monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    """Patches ``_ecc_step`` to note each OpenCV (wide-basin) solve; the list it fills."""
    calls: list[bool] = []
    step = refine_module._ecc_step

    def noted(*args, wide_basin: bool = False, **kwargs):  # noqa: ANN002, ANN003, ANN202
        if wide_basin:
            calls.append(True)
        return step(*args, wide_basin=wide_basin, **kwargs)

    monkeypatch.setattr(refine_module, "_ecc_step", noted)
    return calls


def test_a_quick_path_without_fallback_ends_short_on_noise(locator: Locator, monkeypatch: pytest.MonkeyPatch) -> None:
    """On noise, the quick path with its fallback runs OpenCV's solves from both corner orders it
    tries; without, it runs none and returns nothing, for the caller to search on."""
    calls = _count_opencv(monkeypatch)
    start = locator.aligner.homography(OUTLINE)
    refine(ImagePyramid(_noise()), start, locator.template, orders=4, min_start=-1.0)
    assert calls
    calls.clear()
    assert refine(ImagePyramid(_noise()), start, locator.template, orders=4, min_start=-1.0, fallback=False) is None
    assert not calls


def test_a_clear_print_aligns_on_the_quick_path_without_fallback() -> None:
    """The Feather chip tilted 30 degrees, outlined at its true corners: the quick path reaches
    the bar by inverse composition, so ending short of OpenCV's fallback costs it nothing."""
    md = MorphableDrawing.load(FEATHER / "cpu.svg", move=0.5)
    svg, viewbox = md.to_svg(md.neutral_values()[0]), md.drawing.viewbox
    template = Template.from_svg(svg, viewbox)
    photo, truth = _steep_photo(svg, viewbox, 30.0, seed=1)
    aligner = Aligner(template, 0.55, ink_thickness(template, 256), 256)
    found = refine(ImagePyramid(photo), aligner.homography(truth), template, orders=4, fallback=False)
    assert found is not None and found.correlation > 0.9


def test_wider_searches_carry_only_coarse_solves_that_can_reach_the_bar(
    locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On noise every wider search runs: after the quick path, no coarse solve under
    ``WIDE_CARRY_FROM`` is carried to the finer level, and the ink's starts (the last stage) run
    no OpenCV solve."""
    carried: list[float] = []
    finish, ink, coarse_steps = refine_module._finish, refine_module.ink_starts, refine_module._coarse_steps
    solved: list[float] = []  # every coarse solve, quick path first
    opencv = _count_opencv(monkeypatch)
    opencv_before_ink: list[int] = []  # OpenCV's solves when the ink's starts were taken

    def noted_finish(pyramid, coarse, *args):  # noqa: ANN001, ANN002, ANN202
        carried.append(coarse[1])
        return finish(pyramid, coarse, *args)

    def noted_ink(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        opencv_before_ink.append(len(opencv))
        return ink(*args, **kwargs)

    def noted_coarse(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        out = coarse_steps(*args, **kwargs)
        solved.extend(s[1] for s in out if s is not None)
        return out

    monkeypatch.setattr(refine_module, "_finish", noted_finish)
    monkeypatch.setattr(refine_module, "ink_starts", noted_ink)
    monkeypatch.setattr(refine_module, "_coarse_steps", noted_coarse)
    photo = _noise()
    photo[150:330, 230:410] = 1.0  # a sheet of paper, so the ink's starts are found
    photo[200:280, 300:310] = 0.0
    photo[235:245, 260:380] = 0.0
    start = locator.aligner.homography(OUTLINE)
    found = refine(ImagePyramid(photo), start, locator.template, orders=4, accept=0.55, sized=True, min_start=-1.0)
    assert found is None or found.correlation < 0.6
    assert any(c < WIDE_CARRY_FROM for c in solved[2:])  # the wider searches' solves fell short ...
    assert all(c >= WIDE_CARRY_FROM for c in carried[1:])  # ... and were not carried
    assert opencv_before_ink  # the ink's starts were taken (the last stage) ...
    assert len(opencv) == opencv_before_ink[0]  # ... and their solves ran no OpenCV
