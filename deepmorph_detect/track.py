"""Drawings followed through the frames of a video (an AR marker's steady state).

:meth:`Locator.locate <deepmorph_detect.locate.Locator.locate>` treats every frame as new: the
detector, alignment from its rough outline, the payload reading and the payload's morph check.
In a video, the drawings of the last frame are almost where they were. :func:`track` follows
them into the next frame; :class:`SequenceLocator` runs it frame after frame and runs the
whole search again only when a drawing is lost, when the last frame showed none or one whose
payload is not confirmed (unread drawings are not followed, see :func:`track`), and every
:data:`REDETECT_EVERY` frames (drawings that came into view). ``bench/scenes.py`` measures
both on filmed scenes with a moving camera.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_detect.camera import Camera
from deepmorph_detect.check import MORPH_WIDTH, PayloadCheck
from deepmorph_detect.refine import ImagePyramid, refine, refine_at
from deepmorph_detect.results import Located

if TYPE_CHECKING:
    from deepmorph_detect.locate import Locator

REDETECT_EVERY = 10  # frames between full searches while every drawing is followed
TRACK_ITERATIONS = 10  # ECC iterations following a read drawing's morph from the previous frame


def track(
    locator: Locator, image: np.ndarray, previous: list[Located], camera: Camera | None = None, soft: bool = True
) -> list[Located]:
    """The read drawings of ``previous`` (the last frame's results) followed into ``image``,
    the next frame of a video: no detector, and no second payload check. Only drawings
    whose payload is confirmed (``ok``, ``morph_check`` ``passed`` or ``tracked``) are
    followed. A drawing not found again is left out, and one that newly entered the view
    is not looked for: :class:`SequenceLocator` runs :meth:`Locator.locate
    <deepmorph_detect.locate.Locator.locate>` then.

    Each drawing is aligned straight to its payload's morph from its last homography
    (:data:`TRACK_ITERATIONS` of ECC at the morph check's width). When the correlation clears
    the bar and the rectified view reads the same payload with a passing CRC, that is the
    result (``morph_check`` ``tracked``): the morph was confirmed on this print before, and
    a payload read twice is no CRC collision. Otherwise the drawing goes the whole way of
    ``locate`` from there, without the detector, and a payload other than the track's loses
    its ``ok`` (``morph_check`` ``track conflict``): a print does not change.

    Drawings whose payload was not read are not followed: every poor frame in which an
    unread drawing is aligned is one more chance for a wrong reading to pass CRC-8 and the
    morph check.
    """
    gray, cam, pyramid = locator.frame(image, camera)
    found: list[Located] = []
    for prev in previous:
        if prev.homography is None or not prev.confirmed:
            continue
        located = _follow(locator, gray, pyramid, prev.homography, prev.result.payload, prev.score, cam, soft)
        if located is None or located.homography is None:
            continue
        if locator.aligner.seen(located.homography, [f.homography for f in found]):
            continue  # two tracks converged on one drawing
        found.append(located)
    return found


def _follow(
    locator: Locator,
    gray: np.ndarray,
    pyramid: ImagePyramid,
    start: np.ndarray,
    confirmed: np.ndarray,
    score: float,
    cam: Camera,
    soft: bool,
) -> Located | None:
    """The drawing last seen at ``start`` with payload ``confirmed``, in this frame, or ``None``."""
    fit = refine_at(pyramid, start, locator.morphs.of_payload(confirmed), MORPH_WIDTH, TRACK_ITERATIONS)
    if locator.aligner.accepts(fit):
        reading = locator.reader.read(locator.reader.rectify(pyramid, fit.homography), soft)
        if reading is not None and reading.result.ok and np.array_equal(reading.result.payload, confirmed):
            checked = PayloadCheck(reading.result, None, "tracked")
            return locator.placer.place(
                gray.shape, fit.homography, checked, reading.probabilities, fit.correlation, score, cam, "tracked"
            )
        start = fit.homography
    alignment = refine(pyramid, start, locator.template)
    if not locator.aligner.accepts(alignment):
        return None
    located = locator.decode_drawing(gray, pyramid, alignment, score, cam, "tracked", soft)
    if located.result.ok and not np.array_equal(located.result.payload, confirmed):
        # a CRC collision on a poor frame; the next full search reads the drawing afresh
        located.result = replace(located.result, ok=False)
        located.morph_check = "track conflict"
    return located


class SequenceLocator:
    """Locates drawings in consecutive frames, following the ones already found.

    Args:
        locator: the model's locator.
        redetect_every: a full :meth:`~deepmorph_detect.locate.Locator.locate` at least this
            often (1: every frame, no tracking).
        first: each search stops at the first print read (:meth:`~deepmorph_detect.locate.Locator.locate`'s
            ``first``), and that one is followed.

    Call it once per frame, in order. ``tracked`` and ``searched`` count the frames each way.
    """

    def __init__(self, locator: Locator, redetect_every: int = REDETECT_EVERY, first: bool = False) -> None:
        if redetect_every < 1:
            raise DeepMorphError(f"redetect_every must be at least 1, got {redetect_every}")
        self.locator = locator
        self.redetect_every = redetect_every
        self.first = first
        self.tracked = 0
        self.searched = 0
        self._previous: list[Located] = []
        self._since_search = 0

    def __call__(self, image: np.ndarray, camera: Camera | None = None, soft: bool = True) -> list[Located]:
        """The drawings in ``image``, the next frame (``(H, W)`` or ``(H, W, 3)``)."""
        if self._previous and self._since_search < self.redetect_every - 1 and all(f.confirmed for f in self._previous):
            found = track(self.locator, image, self._previous, camera, soft)
            if len(found) == len(self._previous):  # every drawing followed
                self._previous = found
                self._since_search += 1
                self.tracked += 1
                return found
        found = self.locator.locate(image, camera, soft, first=self.first)
        self._previous = found
        self._since_search = 0
        self.searched += 1
        return found

    def reset(self) -> None:
        """Forget the drawings followed (a cut in the video): the next frame is searched."""
        self._previous = []
        self._since_search = 0


__all__ = ["REDETECT_EVERY", "TRACK_ITERATIONS", "SequenceLocator", "track"]
