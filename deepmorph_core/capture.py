"""A print-and-photo simulator for whole images (OpenCV, not differentiable).

Training corrupts decoder-sized images with the differentiable augmentations; this module
instead imitates what a user hands to ``deepmorph decode``: a real render printed on paper
with a margin, photographed at a slight angle, with uneven light, defocus, sensor noise and
JPEG. It is independent of the training augmentations, so decoding its output is a fair test
(demo, tests, ``bench/capacity.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError


@dataclass(frozen=True)
class CaptureSeverity:
    """Ranges of one severity level."""

    margin: float  # paper margin as a share of the drawing size
    corner_jitter: float  # perspective: corner moves as a share of the image size
    rotate_deg: float
    blur_sigma: float  # in pixels of the output
    noise_sigma: float
    light: float  # multiplicative lighting gradient amplitude
    contrast: tuple[float, float]
    jpeg_quality: tuple[int, int]


SEVERITIES = {
    "easy": CaptureSeverity(0.10, 0.01, 2, 0.4, 0.01, 0.08, (0.85, 1.0), (80, 95)),
    "medium": CaptureSeverity(0.12, 0.03, 5, 0.8, 0.025, 0.18, (0.6, 0.95), (50, 85)),
    "hard": CaptureSeverity(0.15, 0.05, 10, 1.3, 0.045, 0.3, (0.45, 0.85), (30, 70)),
}


def simulate_photo(render: np.ndarray, severity: str, rng: np.random.Generator, out_size: int = 240) -> np.ndarray:
    """Print ``render`` (``(H, W)`` float, 1 = white) on paper and photograph it.

    Returns:
        ``(out_size, out_size)`` uint8 grayscale photo in which the drawing roughly fills the frame.
    """
    if severity not in SEVERITIES:
        raise DeepMorphError(f"severity must be one of {', '.join(SEVERITIES)}, got {severity!r}")
    sv = SEVERITIES[severity]
    h, w = render.shape
    m = int(round(sv.margin * max(h, w)))
    paper = np.ones((h + 2 * m, w + 2 * m), np.float32)
    paper[m : m + h, m : m + w] = render
    ph, pw = paper.shape
    src = np.float32([[0, 0], [pw, 0], [pw, ph], [0, ph]])
    jitter = rng.uniform(-sv.corner_jitter, sv.corner_jitter, (4, 2)) * out_size
    angle = np.deg2rad(rng.uniform(-sv.rotate_deg, sv.rotate_deg))
    c, s = np.cos(angle), np.sin(angle)
    centred = np.float32([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * out_size * 0.5 * 0.95
    rotated = centred @ np.float32([[c, s], [-s, c]])
    dst = (rotated + out_size / 2 + jitter).astype(np.float32)
    homography = cv2.getPerspectiveTransform(src, dst)
    background = rng.uniform(0.55, 0.8)  # a desk darker than the paper
    photo = cv2.warpPerspective(
        paper, homography, (out_size, out_size), flags=cv2.INTER_AREA, borderValue=float(background)
    )
    yy, xx = np.mgrid[0:out_size, 0:out_size].astype(np.float32) / out_size - 0.5
    gx, gy = rng.uniform(-1, 1, 2)
    photo = photo * (1.0 + sv.light * (gx * xx + gy * yy))
    lo, hi = sv.contrast
    k = rng.uniform(lo, hi)
    photo = 0.5 + (photo - 0.5) * k + rng.uniform(-0.05, 0.05)
    sigma = rng.uniform(0.3, sv.blur_sigma)
    photo = cv2.GaussianBlur(photo, (0, 0), sigma)
    photo = photo + rng.normal(0, sv.noise_sigma, photo.shape).astype(np.float32)
    u8 = np.clip(photo * 255, 0, 255).astype(np.uint8)
    q = int(rng.integers(sv.jpeg_quality[0], sv.jpeg_quality[1] + 1))
    ok, buf = cv2.imencode(".jpg", u8, [cv2.IMWRITE_JPEG_QUALITY, q])
    if not ok:  # pragma: no cover - OpenCV always encodes a valid uint8 image
        raise DeepMorphError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
