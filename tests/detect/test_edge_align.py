"""A print aligned on its edges alone: a light that falls off across the sheet as much as a
colour drawing's fills differ from its paper bends the photo's own alignment; with the slow
light subtracted from both images the print aligns."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from deepmorph_core.model import DeepMorphModel
from deepmorph_core.protocols import Candidate
from deepmorph_detect.edge_align import EDGE_ALIGNMENT, photo_edges, without_slow_light
from deepmorph_detect.locate import Locator
from deepmorph_detect.refine import ImagePyramid
from tests.conftest import easy_print_aligned
from tests.detect.colour_close_ups import close_up, corner_error

DATA = Path(__file__).parents[1] / "data"
PHOTO = DATA / "photos" / "light_falling_across_colour_close_up.png"


def test_the_slow_light_goes_and_the_edges_stay() -> None:
    """A ramp of light across a sheet with one dark square on it: the ramp is gone away from the
    image's border, the square's edge is still there, each side of it as it was."""
    ys, xs = np.mgrid[0:120, 0:120].astype(np.float32)
    light = 0.5 + 0.4 * xs / 119.0
    sheet = np.ones((120, 120), np.float32)
    sheet[40:80, 40:80] = 0.6
    edges = without_slow_light(sheet * light, sigma=8.0)
    assert np.abs(edges[:12, 25:95]).max() < 0.005  # paper under the ramp, three sigmas from the square
    assert edges[60, 45] < -0.05 and edges[60, 35] > 0.02  # just inside the square, just outside


def test_the_photo_is_filtered_around_the_outline_alone() -> None:
    gray = np.full((100, 200), 0.8, np.float32)
    quad = np.array([[20.0, 20.0], [60.0, 20.0], [60.0, 60.0], [20.0, 60.0]])
    edges = photo_edges(gray, quad).levels[0]
    assert edges.shape == gray.shape and np.abs(edges).max() < 1e-5
    gray[30:50, 150:170] = 0.2  # far from the outline: not filtered, left at 0
    assert np.abs(photo_edges(gray, quad).levels[0][:, 100:]).max() == 0.0


def test_a_close_up_the_light_bends_aligns_on_its_edges(heart) -> None:
    """A hard colour close-up from the simulator: the pink heart's fills are little darker than
    its paper in luminance, and the light falls off across the sheet about as much. From the
    universal detector's proposal the photo's own ECC, in flat light too, bends the outline a
    quarter of the print's width off; on the edges alone it aligns within 4 %, above the bar."""
    template, aligner = heart
    gray, truth, candidate = close_up(PHOTO)
    (in_photo,) = aligner.verify(ImagePyramid(gray), [candidate], gray)
    assert corner_error(in_photo.alignment.homography, template, truth) > 0.15  # 0.24 of its width
    edged = aligner.on_edges(gray, candidate)
    assert edged is not None and edged.correlation >= EDGE_ALIGNMENT
    assert corner_error(edged.homography, template, truth) < 0.06  # 0.04
    assert edged.width == 0  # the morph check aligns the unmorphed drawing in the photo afresh


def test_a_detector_outline_not_read_is_read_again_on_its_edges(
    model: DeepMorphModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The chain's order: a detector's outline whose colour print the photo's own alignment does
    not read is aligned again on its edges and read there (the ghost read as a colour drawing
    would be); a black-and-white drawing's is not, nor the whole image framed by its ink (which
    has no outline of a detector)."""
    locator = Locator(model)
    assert not locator.realigns_on_edges  # the ghost is black on white
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    (aligned,) = locator.aligner.verify(pyramid, locator.detector.detect(gray), gray)
    real = locator.decode_drawing

    def unread(*args, **kwargs):
        located = real(*args, **kwargs)
        located.result = replace(located.result, ok=False)
        return located

    asked: list[Candidate] = []

    def on_edges(gray, cand):
        asked.append(cand)
        return right

    monkeypatch.setattr(locator, "decode_drawing", unread)
    monkeypatch.setattr(locator.aligner, "on_edges", on_edges)
    assert all(not r.result.ok for r in locator.decode_each(gray, [aligned], cam, True)) and asked == []
    locator.realigns_on_edges = True  # as for a colour drawing
    (read,) = locator.decode_each(gray, [aligned], cam, True)
    assert asked == [aligned.candidate]
    assert read.result.ok and np.array_equal(read.result.payload, placed.payload)
    # nothing aligns on the edges: the unread reading stays what it was (a blind one unreported)
    monkeypatch.setattr(locator.aligner, "on_edges", lambda gray, cand: None)
    assert all(not r.result.ok for r in locator.decode_each(gray, [aligned], cam, True))
    # the whole image framed by its ink is never aligned on its edges
    asked.clear()
    monkeypatch.setattr(locator.aligner, "on_edges", on_edges)
    framed = replace(aligned, candidate=replace(aligned.candidate, homography=right.homography))
    locator.decode_each(gray, [framed], cam, True)
    assert asked == []
