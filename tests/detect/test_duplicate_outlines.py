"""Two outlines of one print: a detector can outline part of a print above the whole print, and
the drawing squeezed into the part can still pass the alignment's bar. Of the same drawing
aligned from both, the aligner keeps the alignment that correlates better, whichever outline
came first, where that one's outline is one a flat print makes."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from deepmorph_detect.refine import ImagePyramid
from tests.detect.colour_close_ups import close_up_proposals, corner_error

DATA = Path(__file__).parents[1] / "data"
PHOTO = DATA / "photos" / "part_outlined_above_colour_close_up.png"
BENT = DATA / "photos" / "half_outlined_bent_colour_close_up.png"


def test_the_whole_prints_outline_wins_over_a_parts_outline_above_it(reading) -> None:
    """A hard colour close-up from the simulator, blurred: the universal detector outlines the
    reader's head first and the whole print second. Each outline alone aligns, the head's a
    whole print's width off; together the print is aligned once, from the whole print's outline,
    within 5 % of the truth."""
    template, aligner = reading
    gray, truth, candidates = close_up_proposals(PHOTO)
    part, whole = candidates
    assert part.score > whole.score
    (head,) = aligner.verify(ImagePyramid(gray), [part], gray)
    assert corner_error(head.alignment.homography, template, truth) > 0.5
    (aligned,) = aligner.verify(ImagePyramid(gray), candidates, gray)
    assert aligned.candidate is whole
    assert corner_error(aligned.alignment.homography, template, truth) < 0.05
    assert aligned.alignment.correlation > head.alignment.correlation


def test_a_bent_alignment_does_not_replace_one_of_the_same_print(heart) -> None:
    """A hard close-up of the pink heart: the detector outlines the whole heart and its left half.
    From the half the heart aligns stretched over the sheet into an outline no flat print makes,
    and correlates better than from the whole heart: it does not replace the whole heart's."""
    template, aligner = heart
    gray, truth, (whole, half) = close_up_proposals(BENT)
    (stretched,) = aligner.verify(ImagePyramid(gray), [half], gray)
    (first,) = aligner.verify(ImagePyramid(gray), [whole], gray)
    assert stretched.alignment.correlation > first.alignment.correlation
    assert aligner.bent(stretched.alignment.homography, gray.shape)
    assert not aligner.replaces(stretched.alignment, [first.alignment], gray.shape)


def test_an_alignment_centred_outside_the_photo_replaces_nothing(reading) -> None:
    """The whole print's alignment moved two photo widths to the right, correlating better than
    anything: another drawing aligned so far out cannot be the print in the photo."""
    _, aligner = reading
    gray, _, (part, whole) = close_up_proposals(PHOTO)
    (aligned,) = aligner.verify(ImagePyramid(gray), [whole], gray)
    (head,) = aligner.verify(ImagePyramid(gray), [part], gray)
    assert aligner.replaces(aligned.alignment, [head.alignment], gray.shape)
    moved = np.array([[1.0, 0.0, 2.0 * gray.shape[1]], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ aligned.alignment.homography
    away = replace(aligned.alignment, homography=moved, correlation=0.99)
    assert not aligner.replaces(away, [head.alignment], gray.shape)
