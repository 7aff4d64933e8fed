"""Photo preprocessing: gray levels, contrast, light and the drawing's ink.

Every array a user hands in becomes float32 gray in ``[0, 1]`` (1 = white paper) here; the
contrast is stretched from paper to ink, shadows and light gradients are divided out where a
reading needs it, and the ink is found by Otsu's threshold without specks or the desk at the
border.
"""

from __future__ import annotations

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.kernels import SQUARE_3X3, component_label_type, label_set, percentiles
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, is_luma

# float images a little outside [0, 1] (noise, rounding) are clipped; beyond this they are on another scale
FLOAT_RANGE_SLACK = 2.0
#: The widest closing (px) :func:`paper_light` runs at full size; a wider one runs on the image shrunk.
PAPER_CLOSING_PX = 9


def to_gray(image: np.ndarray, channel: Channel = LUMA_WEIGHTS) -> np.ndarray:
    """Any ``(H, W)`` or ``(H, W, 1|3|4)`` (BGR or BGRA) image to float32 gray in ``[0, 1]``:
    luminance, or the gray of a model's reading ``channel`` (red, green and blue weights).

    Pixels may be uint8 (0-255), uint16 (0-65535), bool, or float in ``[0, 1]``; a float image
    on another scale (0-255, say) is an error rather than a silently white or black image. A
    2-D float32 image already in ``[0, 1]`` (say, this function's own output) comes back as it
    is, not copied: the photo chain passes its gray frame on, and each copy costs a fifth of a
    millisecond.

    Raises:
        DeepMorphError: another shape, another pixel type, non-finite or out-of-range floats.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] not in (1, 3, 4):
        raise DeepMorphError(f"expected 1, 3 (BGR) or 4 (BGRA) channels, got an image of shape {img.shape}")
    if img.ndim not in (2, 3):
        raise DeepMorphError(f"expected a 2-D image or an image with channels, got shape {img.shape}")
    if img.ndim == 3 and img.shape[2] > 1 and not is_luma(channel):
        weighted = img[..., :3].astype(np.float32) @ np.asarray(channel[::-1], np.float32)  # BGR order
        return to_gray(weighted / np.float32(_scale(img)))
    if img.dtype == np.uint8:
        if img.ndim == 3 and img.shape[2] > 1:  # photos: gray levels as OpenCV rounds them
            img = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_BGR2GRAY)
        out = img.astype(np.float32)
        out /= np.float32(255.0)  # in place: the same numbers without a second frame-sized array
        if out.ndim == 2:  # k / 255 lies in [0, 1]: no clip (a copy of the frame) needed
            return out
    elif img.dtype == np.uint16:
        out = img.astype(np.float32) / 65535.0
    elif img.dtype == np.bool_:
        out = img.astype(np.float32)
    elif np.issubdtype(img.dtype, np.floating):
        out = img.astype(np.float32, copy=False)  # np.clip below makes the copy
        lo, hi = (float(out.min()), float(out.max())) if out.size else (0.0, 0.0)
        if not (np.isfinite(lo) and np.isfinite(hi)):  # min and max carry any NaN or infinity
            raise DeepMorphError("image has non-finite values")
        if hi > FLOAT_RANGE_SLACK or lo < 1.0 - FLOAT_RANGE_SLACK:
            raise DeepMorphError(
                f"float pixels must lie in [0, 1], this image's lie in [{lo:g}, {hi:g}] (divide by 255, or pass uint8)"
            )
        if out.ndim == 2 and out.dtype == np.float32 and lo >= 0.0 and hi <= 1.0:
            return out
    else:
        raise DeepMorphError(f"{img.dtype} pixels are not supported: pass uint8, uint16, or float in [0, 1]")
    if out.ndim == 3:
        out = out[..., 0] if out.shape[2] == 1 else cv2.cvtColor(np.ascontiguousarray(out[..., :3]), cv2.COLOR_BGR2GRAY)
    return np.clip(out, 0.0, 1.0)


def _scale(img: np.ndarray) -> float:
    """What the pixels of ``img`` are divided by to lie in ``[0, 1]``."""
    return {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(img.dtype, 1.0)


def normalise_contrast(gray: np.ndarray) -> np.ndarray | None:
    """Stretch paper to 1 and ink to 0 (1st/99th percentiles); ``None`` for a blank image."""
    lo, hi = percentiles(gray, (1, 99))
    if hi - lo < 0.08:
        return None
    # in the image's own precision (float32 photos stay float32: half the memory traffic of
    # the float64 that numpy's scalars would promote them to, here and in ink_mask)
    kind = gray.dtype.type if np.issubdtype(gray.dtype, np.floating) else np.float64
    out = (gray - kind(lo)) * kind(1.0 / (hi - lo))
    return np.clip(out, 0.0, 1.0, out=out)


def flatten_illumination(gray: np.ndarray, feature_px: float) -> np.ndarray:
    """Divide out shadows and slow changes of light: paper becomes 1 everywhere.

    A shadow edge across a print otherwise reads as ink: it drags the ink framing off and the
    payload with it.

    Args:
        gray: ``(H, W)`` float image, 1 = white.
        feature_px: the thickest ink feature (stroke or fill) in pixels.

    Returns:
        ``(H, W)`` float32 in ``[0, 1]``.
    """
    return divided_by_paper(gray, paper_light(gray, feature_px))


def paper_light(gray: np.ndarray, feature_px: float) -> np.ndarray:
    """The paper's brightness under the ink: a grey closing (a max filter, then a min filter)
    wider than any ink feature, so that strokes vanish from it, then smoothed.

    Its cost grows with the square of the closing's width (49 px over a 640-px crop: 50 ms, 9 px:
    2 ms), so a closing wider than :data:`PAPER_CLOSING_PX` is done on the image shrunk by whole
    blocks until it is that wide, each block its brightest pixel, and the light enlarged back
    (``cv2.resize``): the light is smooth at that scale, and taking the blocks' maxima is the
    closing's own first step, where averaging them would mix the ink into the paper (a close-up's
    alignment in flat light then landed 5.7 % of the print off instead of 3.7 %; with maxima 3.0 %).

    Args:
        gray: ``(H, W)`` float image, 1 = white.
        feature_px: the thickest ink feature (stroke or fill) in pixels.
    """
    k = int(1.5 * feature_px) | 1
    k = max(5, min(k, (min(gray.shape) // 2) | 1))
    if k > PAPER_CLOSING_PX:
        h, w = gray.shape
        step = -(-k // PAPER_CLOSING_PX)
        # each step x step block's brightest pixel: the closing's own first move (a max filter),
        # so the paper between strokes is not averaged with their ink
        padded = np.pad(gray, ((0, -h % step), (0, -w % step)), mode="edge")
        small = padded.reshape(padded.shape[0] // step, step, padded.shape[1] // step, step).max(axis=(1, 3))
        light = paper_light(np.ascontiguousarray(small), feature_px / step)
        return cv2.resize(light, (padded.shape[1], padded.shape[0]), interpolation=cv2.INTER_LINEAR)[:h, :w]
    closed = cv2.morphologyEx(gray, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    return cv2.GaussianBlur(closed, (0, 0), k / 4)


def divided_by_paper(gray: np.ndarray, paper: np.ndarray) -> np.ndarray:
    """``gray`` in flat light: divided by :func:`paper_light`'s estimate, float32 in ``[0, 1]``."""
    return np.clip(gray / np.maximum(paper, 1e-3), 0.0, 1.0).astype(np.float32)


def ink_mask(gray: np.ndarray) -> tuple[np.ndarray, tuple[int, int, int, int]] | None:
    """The drawing's ink: Otsu on a 3x3 blur, minus specks and anything touching the border
    (a desk or a shadow at the edge of a cropped photo is not ink).

    Returns:
        A boolean ``(H, W)`` mask and its bounding box ``(x0, y0, x1, y1)``, or ``None``.
    """
    u8 = np.clip(gray * 255, 0, 255).astype(np.uint8)
    blur = cv2.GaussianBlur(u8, (3, 3), 0.95)
    _, mask = cv2.threshold(blur, 0, 255, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
    H, W = gray.shape
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8, ltype=component_label_type(H, W))
    if n <= 1:
        return None
    keep = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= max(4, H * W * 2e-5)]

    def touches_border(i: int) -> bool:
        x, y = stats[i, cv2.CC_STAT_LEFT], stats[i, cv2.CC_STAT_TOP]
        return x == 0 or y == 0 or x + stats[i, cv2.CC_STAT_WIDTH] >= W or y + stats[i, cv2.CC_STAT_HEIGHT] >= H

    inner = [i for i in keep if not touches_border(i)]
    border = [i for i in keep if touches_border(i)]
    if inner and border:
        # A border component is a desk or a shadow when it is clearly lighter than the ink
        # inside; strokes of a drawing that runs to the edge of a render are kept.
        ink_level = float(np.median(gray[label_set(labels, n, inner)]))
        border = [i for i in border if float(np.median(gray[labels == i])) <= ink_level + 0.2]
    keep = inner + border
    if not keep:
        return None
    x0 = min(stats[i, cv2.CC_STAT_LEFT] for i in keep)
    y0 = min(stats[i, cv2.CC_STAT_TOP] for i in keep)
    x1 = max(stats[i, cv2.CC_STAT_LEFT] + stats[i, cv2.CC_STAT_WIDTH] for i in keep)
    y1 = max(stats[i, cv2.CC_STAT_TOP] + stats[i, cv2.CC_STAT_HEIGHT] for i in keep)
    if (x1 - x0) < 4 or (y1 - y0) < 4:
        return None
    # the kept components fill this share of their bounding box (each lies wholly inside it)
    if sum(int(stats[i, cv2.CC_STAT_AREA]) for i in keep) / ((x1 - x0) * (y1 - y0)) < 0.005:
        return None
    # The moments must see what training sees: pixels darker than 0.5 (here within the kept
    # components, grown by a pixel to undo the blur's shift of their edges).
    grown = cv2.dilate(label_set(labels, n, keep, np.uint8), SQUARE_3X3) > 0
    return grown & (gray < 0.5), (int(x0), int(y0), int(x1), int(y1))
