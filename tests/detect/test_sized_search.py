"""The universal detector's outlines (``Candidate.sized``) skip the outline sweep: their size and
turn come from the print's ink, and on 400 scenes the sweep read no print more."""

from __future__ import annotations

import numpy as np
import pytest

from deepmorph_detect import refine as refine_module
from deepmorph_detect.locate import Locator
from deepmorph_detect.refine import ImagePyramid, refine


def test_only_an_outline_not_sized_by_ink_is_swept(locator: Locator, monkeypatch: pytest.MonkeyPatch) -> None:
    """On a photo of noise (nothing aligns, so every wider search runs), a sized outline takes
    the corner orders and the ink starts, and never the sweep; an unsized one takes the sweep."""
    photo = np.random.default_rng(0).uniform(0.2, 1.0, (480, 640)).astype(np.float32)
    start = locator.aligner.homography(np.array([[200.0, 120], [440, 120], [440, 360], [200, 360]]))
    swept: list[bool] = []
    inked: list[bool] = []
    sweep, ink = refine_module.outline_sweep, refine_module.ink_starts
    monkeypatch.setattr(refine_module, "outline_sweep", lambda *a, **k: swept.append(True) or sweep(*a, **k))
    monkeypatch.setattr(refine_module, "ink_starts", lambda *a, **k: inked.append(True) or ink(*a, **k))
    for sized in (True, False):
        swept.clear()
        inked.clear()
        found = refine(ImagePyramid(photo), start, locator.template, orders=4, accept=0.55, sized=sized)
        assert found is None or found.correlation < 0.6
        assert swept == ([] if sized else [True]) and inked == [True]
