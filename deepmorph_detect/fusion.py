"""Fusing a drawing's predictions over the frames of a sequence (the paper's future work).

Each frame's detections are matched to tracks by where the drawing is (its centre, relative to
its size); a track sums its frames' per-bit log-odds, which is the optimal combination for
independent frames, and the codec decodes the fused probabilities once more. Bits that one
blurry frame gets wrong are outvoted by the sharp ones. A fused payload that passes the CRC is
checked by synthesis like a single frame's (:meth:`~deepmorph_detect.locate.Locator.check_payload`),
on the last frame the drawing was seen in.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from deepmorph_core.codec import DecodeResult, PayloadCodec
from deepmorph_detect.check import PayloadCheck
from deepmorph_detect.results import Located, refused_result
from deepmorph_detect.synthesis import BIT_FIELDS

MorphCheck = Callable[[np.ndarray, np.ndarray, DecodeResult], PayloadCheck]
#: Whether a payload read at a detection is refused for the print's width (``Locator.refuses_reading``).
SizeRule = Callable[[Located], bool]

LOGIT_CLIP = 6.0  # no single frame may be more than ~99.75 % sure of a bit
MATCH_DISTANCE = 0.6  # centres within this share of the drawing's size belong to one track


@dataclass
class Track:
    """One drawing followed through a sequence."""

    logits: np.ndarray
    last: Located
    frames: list[str] = field(default_factory=list)
    centre: np.ndarray = field(default_factory=lambda: np.zeros(2))
    size: float = 1.0
    image: np.ndarray | None = None  # the last frame it was seen in (for the morph check)


def _where(det: Located) -> tuple[np.ndarray, float]:
    c = np.asarray(det.corners, dtype=np.float64)
    return c.mean(0), float(np.linalg.norm(c[2] - c[0]))


def _logits(p: np.ndarray) -> np.ndarray:
    q = np.clip(np.asarray(p, dtype=np.float64), 1e-6, 1 - 1e-6)
    return np.clip(np.log(q / (1 - q)), -LOGIT_CLIP, LOGIT_CLIP)


class FrameFuser:
    """Accumulates detections frame by frame; :meth:`results` decodes each track.

    Args:
        codec: the model's payload codec.
        check: the morph check (``Locator.check_payload``) run on a fused payload that passes
            the CRC; without it, the CRC alone decides ``ok``.
        refuses: the size rule (``Locator.refuses_reading``) asked of a fused payload that
            passed, at the track's last detection: a print too narrow for its model's readings
            (a ``--pixels`` model's narrower prints) gives no payload fused either, only
            ``too_small``.
    """

    def __init__(self, codec: PayloadCodec, check: MorphCheck | None = None, refuses: SizeRule | None = None) -> None:
        self.codec = codec
        self.check = check
        self.refuses = refuses
        self.tracks: list[Track] = []
        self.frames = 0

    def add(self, label: str, detections: list[Located], image: np.ndarray | None = None) -> None:
        """One frame's detections (``image``: the frame, kept per track for the morph check)."""
        self.frames += 1
        free = list(range(len(self.tracks)))
        for det in sorted(detections, key=lambda d: -d.correlation):
            centre, size = _where(det)
            best, best_d = None, None
            for i in free:
                tr = self.tracks[i]
                d = float(np.linalg.norm(centre - tr.centre)) / max(tr.size, size, 1e-6)
                if d < MATCH_DISTANCE and (best_d is None or d < best_d):
                    best, best_d = i, d
            if best is None:
                self.tracks.append(Track(_logits(det.probabilities), det, [label], centre, size, image))
            else:
                free.remove(best)
                tr = self.tracks[best]
                tr.logits = tr.logits + _logits(det.probabilities)
                tr.last, tr.centre, tr.size, tr.image = det, centre, size, image
                tr.frames.append(label)

    def results(self, soft: bool = True) -> list[dict[str, Any]]:
        """One JSON entry per track: the fused decode plus the last frame's geometry."""
        out = []
        for tr in self.tracks:
            probs = 1.0 / (1.0 + np.exp(-tr.logits))
            fused = self.codec.decode(probs.astype(np.float32), soft=soft)
            entry = tr.last.to_json()
            checked = PayloadCheck(fused, None, "not run")
            if self.check is not None and tr.image is not None and tr.last.homography is not None:
                checked = self.check(tr.image, tr.last.homography, fused)
            if self.refuses is not None and checked.result.ok and self.refuses(replace(tr.last, result=checked.result)):
                checked = replace(checked, result=refused_result(checked.result))
                entry["too_small"] = tr.last.size_json()  # the print's width, whatever was read there
            entry["morph_check"] = checked.status
            for key in ("morph_fit", *BIT_FIELDS):
                entry.pop(key, None)  # the last frame's own check, not the fused payload's
            if checked.fit is not None:
                entry["morph_fit"] = round(checked.fit.gain, 4)
            if checked.bits is not None:
                entry.update(checked.bits.to_json())
            entry.update(checked.result.to_json())
            entry["bit_probabilities"] = [round(float(p), 4) for p in probs]
            entry["frames"] = len(tr.frames)
            entry["first_frame"], entry["last_frame"] = tr.frames[0], tr.frames[-1]
            out.append(entry)
        return out


__all__ = ["FrameFuser", "MorphCheck", "SizeRule", "Track"]
