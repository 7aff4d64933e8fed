"""Scoring detections against scene truth: which drawing a detection found, and how far off.

Pose errors (rotation, translation) are :mod:`deepmorph_detect.camera`'s
(:func:`~deepmorph_detect.camera.rotation_error_deg`,
:func:`~deepmorph_detect.camera.translation_error`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from deepmorph_detect.scenes import Placement


def corner_error(found: np.ndarray, truth: np.ndarray) -> float:
    """Mean distance (pixels) between ``(4, 2)`` found corners and the true ones."""
    return float(np.linalg.norm(np.asarray(found) - truth, axis=1).mean())


def match_placement(det_corners: np.ndarray, truths: list[Placement]) -> Placement | None:
    """The placement whose centre lies within a quarter of its diagonal of the detection's."""
    centre = det_corners.mean(0)
    for p in truths:
        size = float(np.linalg.norm(p.corners[2] - p.corners[0]))
        if np.linalg.norm(centre - p.corners.mean(0)) < 0.25 * size:
            return p
    return None


def matched_detections(dets: list[Any], drawings: list[Placement]) -> Iterator[tuple[Any, Placement | None, bool]]:
    """Each detection with the drawing it found (``None``: a false detection, or a second one of
    a drawing already found) and whether its payload is that drawing's."""
    matched: set[int] = set()
    for det in dets:
        p = match_placement(det.corners, drawings)
        if p is None or id(p) in matched:
            yield det, None, False
            continue
        matched.add(id(p))
        yield det, p, p.payload is not None and np.array_equal(det.result.payload, p.payload)


@dataclass
class SceneTally:
    """Detections scored against their scenes' truth, added up over scenes (:meth:`add`).

    Attributes:
        prints: drawings placed in the scenes.
        found: detections of a placed drawing (the first of each).
        read: of those, payloads read (``ok``) and right.
        unread: of those, payloads not read.
        wrong: payloads reported ``ok`` that are not the drawing's, on a placed drawing or not.
        false: detections of nothing placed, or a second one of a drawing.
    """

    prints: int = 0
    found: int = 0
    read: int = 0
    unread: int = 0
    wrong: int = 0
    false: int = 0

    def add(self, dets: list[Any], drawings: list[Placement]) -> list[tuple[Any, Placement | None, bool]]:
        """Score one scene's detections against its drawings; each detection with the drawing it
        found and whether its payload is that drawing's (:func:`matched_detections`)."""
        self.prints += len(drawings)
        scored = list(matched_detections(dets, drawings))
        for det, p, right in scored:
            ok = bool(det.result.ok)
            if p is None:
                self.false += 1
                self.wrong += ok
                continue
            self.found += 1
            self.read += ok and right
            self.unread += not ok
            self.wrong += ok and not right
        return scored


__all__ = ["SceneTally", "corner_error", "match_placement", "matched_detections"]
