"""Reading images and bringing a drawing into the decoder's frame.

For images in which the drawing roughly fills the frame (a scan, a cropped photo, a rendered
PNG): normalise the contrast, find the ink by Otsu thresholding, and map the ink's bounding
box onto where the unmorphed drawing's ink sits in the decoder's frame. Residual shifts and
scalings (a morph moves the ink a little) are what training's geometric augmentations cover.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError

MAX_IMAGE_PIXELS = 80_000_000


def read_image(path: str | Path) -> np.ndarray:
    """Read an image file as a float32 grayscale array in ``[0, 1]`` (1 = white).

    Raises:
        DeepMorphError: missing, unreadable, corrupt or non-image files.
    """
    path = Path(path)
    if not path.is_file():
        raise DeepMorphError(f"{path}: no such image file")
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        raise DeepMorphError(f"{path}: empty file, not an image")
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DeepMorphError(f"{path}: not an image OpenCV can read (corrupt, or an unsupported format)")
    if img.shape[0] * img.shape[1] > MAX_IMAGE_PIXELS:
        raise DeepMorphError(f"{path}: {img.shape[1]}x{img.shape[0]} pixels is too large to decode")
    if img.ndim == 3 and img.shape[2] == 4:  # composite transparency onto white paper
        alpha = img[..., 3:4].astype(np.float32) / 255.0
        img = (img[..., :3].astype(np.float32) * alpha + 255.0 * (1 - alpha)).astype(np.uint8)
    return to_gray(img)


def to_gray(image: np.ndarray) -> np.ndarray:
    """Any ``(H, W)``, ``(H, W, 1|3|4)`` uint8/uint16/float image to float32 gray in ``[0, 1]``."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim == 3:
        img = img[..., :3]
        if img.dtype == np.uint8:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        else:
            img = img.astype(np.float32).mean(-1)
    if img.ndim != 2:
        raise DeepMorphError(f"expected a 2-D image or an image with channels, got shape {img.shape}")
    if img.dtype == np.uint8:
        return img.astype(np.float32) / 255.0
    if img.dtype == np.uint16:
        return img.astype(np.float32) / 65535.0
    out = img.astype(np.float32)
    if not np.isfinite(out).all():
        raise DeepMorphError("image has non-finite values")
    return np.clip(out, 0.0, 1.0)


def normalise_contrast(gray: np.ndarray) -> np.ndarray | None:
    """Stretch paper to 1 and ink to 0 (2nd/98th percentiles); ``None`` for a blank image."""
    lo, hi = np.percentile(gray, [1, 99])
    if hi - lo < 0.08:
        return None
    return np.clip((gray - lo) / (hi - lo), 0.0, 1.0)


def ink_box(gray: np.ndarray) -> tuple[int, int, int, int] | None:
    """Bounding box ``(x0, y0, x1, y1)`` of the ink (Otsu on a 3x3 blur), or ``None``."""
    u8 = np.clip(gray * 255, 0, 255).astype(np.uint8)
    blur = cv2.GaussianBlur(u8, (3, 3), 0.95)
    _, mask = cv2.threshold(blur, 0, 255, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None
    area = gray.shape[0] * gray.shape[1]
    keep = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= max(4, area * 2e-5)]
    if not keep:
        return None
    x0 = min(stats[i, cv2.CC_STAT_LEFT] for i in keep)
    y0 = min(stats[i, cv2.CC_STAT_TOP] for i in keep)
    x1 = max(stats[i, cv2.CC_STAT_LEFT] + stats[i, cv2.CC_STAT_WIDTH] for i in keep)
    y1 = max(stats[i, cv2.CC_STAT_TOP] + stats[i, cv2.CC_STAT_HEIGHT] for i in keep)
    ink = mask[y0:y1, x0:x1].mean() / 255.0
    if ink < 0.005 or (x1 - x0) < 4 or (y1 - y0) < 4:
        return None
    return int(x0), int(y0), int(x1), int(y1)


def align_to_frame(
    gray: np.ndarray, size: tuple[int, int], target_box: tuple[float, float, float, float]
) -> tuple[np.ndarray, tuple[int, int, int, int]] | None:
    """Map the image's ink box onto ``target_box`` in a white ``size`` = ``(H, W)`` frame.

    Returns:
        The ``(H, W)`` float32 frame and the ink box found in the input, or ``None`` when the
        image holds no drawing (blank, or no ink).
    """
    norm = normalise_contrast(gray)
    if norm is None:
        return None
    box = ink_box(norm)
    if box is None:
        return None
    x0, y0, x1, y1 = box
    tx0, ty0, tx1, ty1 = target_box
    sx = (tx1 - tx0) / (x1 - x0)
    sy = (ty1 - ty0) / (y1 - y0)
    matrix = np.array([[sx, 0.0, tx0 - sx * x0], [0.0, sy, ty0 - sy * y0]], dtype=np.float64)
    src = norm
    if min(sx, sy) < 0.5:  # shrink with area averaging first so that thin strokes survive
        factor = max(1, int(1 / max(min(sx, sy), 1e-6)) // 2)
        if factor > 1:
            src = cv2.resize(norm, (norm.shape[1] // factor, norm.shape[0] // factor), interpolation=cv2.INTER_AREA)
            matrix[:, :2] *= factor
    h, w = size
    frame = cv2.warpAffine(
        src.astype(np.float32), matrix, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0
    )
    return np.clip(frame, 0.0, 1.0), box
