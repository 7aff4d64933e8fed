"""Drawings followed through the frames of a video (an AR marker's steady state).

:meth:`Locator.locate <deepmorph_detect.locate.Locator.locate>` treats every frame as new: the
detector, alignment from its rough outline, the payload reading and the payload's morph check.
In a video, the drawings of the last frame are almost where they were.
:class:`SequenceLocator` follows them with :meth:`Locator.track
<deepmorph_detect.locate.Locator.track>` and runs the whole search again only when a drawing
is lost, when the last frame showed none or one whose payload is not confirmed (unread
drawings are not followed, see :meth:`Locator.track <deepmorph_detect.locate.Locator.track>`),
and every :data:`REDETECT_EVERY` frames (drawings that came into view). ``bench/scenes.py``
measures both on filmed scenes with a moving camera.
"""

from __future__ import annotations

import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_detect.camera import Camera
from deepmorph_detect.locate import Located, Locator

REDETECT_EVERY = 10  # frames between full searches while every drawing is followed


class SequenceLocator:
    """Locates drawings in consecutive frames, following the ones already found.

    Args:
        locator: the model's locator.
        redetect_every: a full :meth:`~deepmorph_detect.locate.Locator.locate` at least this
            often (1: every frame, no tracking).

    Call it once per frame, in order. ``tracked`` and ``searched`` count the frames each way.
    """

    def __init__(self, locator: Locator, redetect_every: int = REDETECT_EVERY) -> None:
        if redetect_every < 1:
            raise DeepMorphError(f"redetect_every must be at least 1, got {redetect_every}")
        self.locator = locator
        self.redetect_every = redetect_every
        self.tracked = 0
        self.searched = 0
        self._previous: list[Located] = []
        self._since_search = 0

    def __call__(self, image: np.ndarray, camera: Camera | None = None, soft: bool = True) -> list[Located]:
        """The drawings in ``image``, the next frame (``(H, W)`` or ``(H, W, 3)``)."""
        if self._previous and self._since_search < self.redetect_every - 1 and all(f.confirmed for f in self._previous):
            found = self.locator.track(image, self._previous, camera, soft)
            if len(found) == len(self._previous):  # every drawing followed
                self._previous = found
                self._since_search += 1
                self.tracked += 1
                return found
        found = self.locator.locate(image, camera, soft)
        self._previous = found
        self._since_search = 0
        self.searched += 1
        return found

    def reset(self) -> None:
        """Forget the drawings followed (a cut in the video): the next frame is searched."""
        self._previous = []
        self._since_search = 0


__all__ = ["REDETECT_EVERY", "SequenceLocator"]
