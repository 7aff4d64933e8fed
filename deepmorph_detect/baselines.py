"""The baselines DeepMorph is measured against: OpenCV's ArUco markers and QR codes.

:class:`QrClock` times QR's ``detectAndDecode`` beside each frame of a benchmark, so that both
medians are taken over the same minutes (the machine's speed drifts by a fifth within a run).
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.scenes import ARUCO_DICT, SceneMaker

QR_TEXT = "https://deepmorph.example/0xA1B2C3"  # what the QR frames of the speed baseline hold


def aruco_detector() -> cv2.aruco.ArucoDetector:
    """OpenCV's ArUco detector for DICT_6X6_250 with sub-pixel corner refinement."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(ARUCO_DICT), params)


class QrClock:
    """OpenCV's QR ``detectAndDecode`` timed on ``frames`` same-size scenes (medium severity)
    holding one QR code, one call per :meth:`tick`, taking the frames in turn.

    A benchmark ticks it after each of its own frames, so that QR's median is taken over the
    same stretch of the run as the chain's: the machine's speed drifts within a minute, so
    timings taken in separate blocks do not compare.
    """

    def __init__(self, model: DeepMorphModel, size: tuple[int, int], frames: int) -> None:
        maker = SceneMaker(model, size, "medium", seed=99)
        self.frames = [maker.make(drawings=0, qr=QR_TEXT).image for _ in range(max(1, frames))]
        self.detector = cv2.QRCodeDetector()
        self.times: list[float] = []

    def warm(self) -> None:
        """One call left out of the timings (the first allocates)."""
        self.detector.detectAndDecode(self.frames[0])

    def tick(self) -> float:
        """Time one call on the next frame; its seconds."""
        frame = self.frames[len(self.times) % len(self.frames)]
        t0 = time.perf_counter()
        self.detector.detectAndDecode(frame)
        self.times.append(time.perf_counter() - t0)
        return self.times[-1]

    def median_ms(self) -> float | None:
        """The median call in milliseconds (``None`` before the first tick)."""
        return round(1000 * float(np.median(self.times)), 2) if self.times else None


__all__ = ["QR_TEXT", "QrClock", "aruco_detector"]
