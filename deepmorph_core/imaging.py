"""Reading images and bringing a drawing into the decoder's frame.

For images in which the drawing roughly fills the frame (a scan, a cropped photo, a rendered
PNG): normalise the contrast, find the ink by Otsu thresholding, and map the ink's bounding
box onto where the unmorphed drawing's ink sits in the decoder's frame. Residual shifts and
scalings (a morph moves the ink a little) are what training's geometric augmentations cover.
"""

from __future__ import annotations

import functools
import io
import math
import warnings
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image
from torch import Tensor

from deepmorph_core.errors import DeepMorphError

MAX_IMAGE_PIXELS = 80_000_000
# float images a little outside [0, 1] (noise, rounding) are clipped; beyond this they are on another scale
FLOAT_RANGE_SLACK = 2.0
EXIF_ORIENTATION = 0x0112  # the EXIF tag of how a viewer turns the stored pixels
MIN_IMAGE_SIDE = 16  # pixels: smaller images cannot hold a drawing the detector or decoder could read


def read_image(path: str | Path) -> np.ndarray:
    """Read an image file as a float32 grayscale array in ``[0, 1]`` (1 = white).

    Raises:
        DeepMorphError: missing, unreadable, corrupt or non-image files.
    """
    path = Path(path)
    if path.is_dir():
        raise DeepMorphError(f"{path}: is a folder; pass image files (the CLI reads folders as frame sequences)")
    return to_gray(read_image_bgr(path))


def read_image_bgr(path: str | Path) -> np.ndarray:
    """Read an image file as ``(H, W, 3)`` uint8 BGR (gray expanded, transparency on white).

    Raises:
        DeepMorphError: missing, empty, corrupt, too large, too small or non-image files.
    """
    path = Path(path)
    if not path.is_file():
        raise DeepMorphError(f"{path}: no such image file")
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        raise DeepMorphError(f"{path}: empty file, not an image")
    size, orientation = _peek_header(data, path)
    if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:  # refused before it is decoded
        raise DeepMorphError(f"{path}: {size[0]}x{size[1]} pixels is too large to decode")
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DeepMorphError(f"{path}: not an image OpenCV can read (corrupt, or an unsupported format)")
    if img.shape[0] * img.shape[1] > MAX_IMAGE_PIXELS:
        raise DeepMorphError(f"{path}: {img.shape[1]}x{img.shape[0]} pixels is too large to decode")
    img = _upright(img, orientation)
    if min(img.shape[:2]) < MIN_IMAGE_SIDE:
        raise DeepMorphError(
            f"{path}: {img.shape[1]}x{img.shape[0]} pixels is too small to hold a drawing"
            f" (at least {MIN_IMAGE_SIDE} pixels each way)"
        )
    if img.dtype == np.uint16:
        img = (img // 257).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise DeepMorphError(f"{path}: {img.dtype} pixels are not supported (8 or 16 bits per channel)")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:  # composite transparency onto white paper
        alpha = img[..., 3:4].astype(np.float32) / 255.0
        return (img[..., :3].astype(np.float32) * alpha + 255.0 * (1 - alpha)).astype(np.uint8)
    return np.ascontiguousarray(img[..., :3])


def _peek_header(data: np.ndarray, path: Path) -> tuple[tuple[int, int] | None, int]:
    """``((width, height), EXIF orientation)`` from an image file's header, without decoding
    its pixels (Pillow opens lazily); ``(None, 1)`` where Pillow cannot tell, and then OpenCV's
    decoder alone judges the file.

    Raises:
        DeepMorphError: a header beyond Pillow's own bomb limit (far more than
            :data:`MAX_IMAGE_PIXELS`), before any pixel is decoded.
    """
    try:
        with warnings.catch_warnings():  # the size is judged by the caller, not by Pillow's warning
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data.tobytes())) as img:
                return img.size, int(img.getexif().get(EXIF_ORIENTATION, 1) or 1)
    except Image.DecompressionBombError:
        raise DeepMorphError(f"{path}: its header claims far too many pixels to decode") from None
    except Exception:  # not a format Pillow knows, or a header it cannot parse: OpenCV decides
        return None, 1


def _upright(img: np.ndarray, orientation: int) -> np.ndarray:
    """The image as a viewer shows it, following its EXIF orientation (phone cameras store
    pixels as the sensor saw them and the turn in this tag); keypoints, boxes, overlays and the
    pose are then in the frame the user sees, where a calibration for it applies."""
    turns = {
        2: lambda a: a[:, ::-1],
        3: lambda a: a[::-1, ::-1],
        4: lambda a: a[::-1],
        5: lambda a: np.swapaxes(a, 0, 1),
        6: lambda a: np.rot90(a, -1),
        7: lambda a: np.rot90(np.swapaxes(a, 0, 1), 2),
        8: lambda a: np.rot90(a, 1),
    }
    turn = turns.get(orientation)
    return img if turn is None else np.ascontiguousarray(turn(img))


def to_gray(image: np.ndarray) -> np.ndarray:
    """Any ``(H, W)`` or ``(H, W, 1|3|4)`` (BGR or BGRA) image to float32 gray in ``[0, 1]``.

    Pixels may be uint8 (0-255), uint16 (0-65535), bool, or float in ``[0, 1]``; a float image
    on another scale (0-255, say) is an error rather than a silently white or black image. A
    2-D float32 image already in ``[0, 1]`` (say, this function's own output) comes back as it
    is, not copied: the photo chain passes its gray frame on, and each copy cost a fifth of a
    millisecond.

    Raises:
        DeepMorphError: another shape, another pixel type, non-finite or out-of-range floats.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] not in (1, 3, 4):
        raise DeepMorphError(f"expected 1, 3 (BGR) or 4 (BGRA) channels, got an image of shape {img.shape}")
    if img.ndim not in (2, 3):
        raise DeepMorphError(f"expected a 2-D image or an image with channels, got shape {img.shape}")
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


# area_resize's own path: an axis shrunk by q/p in lowest terms with q at most this many (every
# p source pixels give q output pixels) is resampled with one small matrix per period
MAX_AREA_OUTPUTS_PER_PERIOD = 8


@functools.lru_cache(maxsize=32)
def _area_weights(src: int, dst: int) -> np.ndarray | None:
    """``(q, p)`` float32 weights of one period of an area resample from ``src`` to ``dst``
    pixels (row ``j``: how much of each of ``p`` source pixels output pixel ``j`` covers,
    summing to 1), or ``None`` where ``dst`` does not shrink ``src`` or ``q`` exceeds
    :data:`MAX_AREA_OUTPUTS_PER_PERIOD`."""
    g = math.gcd(src, dst)
    p, q = src // g, dst // g
    if dst >= src or q > MAX_AREA_OUTPUTS_PER_PERIOD:
        return None
    edges = np.arange(q + 1) * (p / q)  # output pixel j covers [edges[j], edges[j + 1]) source px
    pixels = np.arange(p)
    lo = np.maximum(edges[:-1, None], pixels[None, :])
    hi = np.minimum(edges[1:, None], pixels[None, :] + 1)
    weights = (np.clip(hi - lo, 0.0, None) * (q / p)).astype(np.float32)
    weights.flags.writeable = False  # shared by every call (cached)
    return weights


def area_resize(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``cv2.resize(image, size, interpolation=cv2.INTER_AREA)`` for a 2-D float32 image
    shrunk by a ratio like 640 -> 256 (to float rounding: 1e-7), in a fraction of the time.

    OpenCV's area resampling is quick at whole-number ratios but takes a slow general path at
    others: 0.37 ms for the 640x480 -> 256x192 that every photo's detector input needs, 3.6 ms
    from 1920x1080 and 28 ms from a 4032x3024 phone photo. The same averages, period by period,
    are two small matrix products: 0.15, 0.63 and 4.1 ms. Whole-number ratios, other images and
    long periods go to OpenCV.

    Args:
        size: ``(width, height)`` as OpenCV takes it.
    """
    w, h = size
    src_h, src_w = image.shape[:2]
    if image.ndim != 2 or image.dtype != np.float32 or w > src_w or h > src_h:
        return cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    across = None if w == src_w else _area_weights(src_w, w)
    down = None if h == src_h else _area_weights(src_h, h)
    long_period = (across is None and w != src_w) or (down is None and h != src_h)
    whole_numbers = all(weights is None or weights.shape[0] == 1 for weights in (across, down))
    if long_period or whole_numbers:  # OpenCV's general path, or its quick one
        return cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    out = np.ascontiguousarray(image)
    if across is not None:  # (rows, periods, p) @ (p, q) -> (rows, w)
        out = (out.reshape(-1, across.shape[1]) @ across.T).reshape(src_h, w)
    if down is not None:  # (q, p) @ (periods, p, w) -> (periods, q, w)
        out = np.matmul(down, out.reshape(-1, down.shape[1], w)).reshape(h, w)
    return out


def percentiles(values: np.ndarray, qs: tuple[float, ...]) -> np.ndarray:
    """``np.percentile(values, qs)`` (linear interpolation), to the last bit, in a fraction of
    the time: the order statistics the percentiles fall between (:func:`order_statistics`) and
    numpy's own interpolation formula, without its general machinery (0.44 against 0.08 ms for
    a 192 px view, which every reading of a photo frames by its percentiles).

    Returns:
        ``(len(qs),)`` float64.
    """
    flat = np.asarray(values).reshape(-1)
    n = flat.size
    virtual = (n - 1) * (np.asarray(qs, dtype=np.float64) / 100)
    below = np.floor(virtual).astype(np.intp)
    above = np.minimum(below + 1, n - 1)
    ranks = np.unique(np.concatenate([below, above]))
    ranked = order_statistics(flat, ranks)
    a, b = ranked[np.searchsorted(ranks, below)], ranked[np.searchsorted(ranks, above)]
    t = virtual - below
    diff = b - a  # in the values' own precision, as numpy's _lerp takes it
    return np.where(t >= 0.5, b - diff * (1 - t), a + diff * t)


# order_statistics guesses where its ranks lie from a sorted sample of about this many values
SELECTION_SAMPLE = 512


def order_statistics(flat: np.ndarray, ranks: np.ndarray) -> np.ndarray:
    """The values of ``ranks`` (sorted, unique) in ``flat`` sorted ascending, as
    ``np.partition(flat, ranks)[ranks]`` gives them (NaN sorting last), exactly.

    A partition of the whole array costs a pass per rank group and more. For a large float
    array, a strided sample sorted says between which two values each group of nearby ranks
    lies (with a margin of several standard deviations of the sample's rank); only the values
    between them are partitioned, once it is counted that the ranks lie among them. When a
    guess misses (or the array holds NaN), the whole array is partitioned: the answer is the
    same either way.
    """
    n = flat.size
    ranks = np.asarray(ranks, dtype=np.intp)
    if n < 32 * SELECTION_SAMPLE or flat.dtype.kind != "f" or len(ranks) == 0:
        return np.partition(flat, ranks)[ranks]
    sample = np.sort(flat[:: n // SELECTION_SAMPLE])
    m = sample.size
    if np.isnan(sample[-1]):
        return np.partition(flat, ranks)[ranks]
    out = np.empty(len(ranks), dtype=flat.dtype)
    accounted = 0  # values below, inside or above the first window: n unless NaN hides somewhere
    done = 0
    while done < len(ranks):
        # ranks within one window: those whose sample positions lie close together
        first = int(ranks[done])
        p = first / max(n - 1, 1)
        margin = int(4.0 * math.sqrt(m * p * (1.0 - p))) + 3
        centre = p * (m - 1)
        lo_i, hi_i = int(centre) - margin, int(math.ceil(centre)) + margin
        group_end = done + 1
        while group_end < len(ranks) and int(ranks[group_end]) / max(n - 1, 1) * (m - 1) + margin <= hi_i:
            group_end += 1
        group = ranks[done:group_end]
        lo = sample[lo_i] if lo_i >= 0 else None
        hi = sample[hi_i] if hi_i < m else None
        inside = np.ones(n, dtype=bool) if lo is None else flat >= lo
        if hi is not None:
            inside &= flat <= hi
        window = flat[inside]
        under = 0 if lo is None else int(np.count_nonzero(flat < lo))
        if not accounted:
            over = 0 if hi is None else int(np.count_nonzero(flat > hi))
            accounted = under + window.size + over
        if accounted != n or not (under <= int(group[0]) and int(group[-1]) < under + window.size):
            return np.partition(flat, ranks)[ranks]
        out[done:group_end] = np.partition(window, group - under)[group - under]
        done = group_end
    return out


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

    The paper's brightness under the ink is estimated by a grey closing (a max filter, then a
    min filter) wider than any ink feature, so that strokes vanish from it, then smoothed. A
    shadow edge across a print otherwise reads as ink: it drags the ink framing off and the
    payload with it.

    Args:
        gray: ``(H, W)`` float image, 1 = white.
        feature_px: the thickest ink feature (stroke or fill) in pixels.

    Returns:
        ``(H, W)`` float32 in ``[0, 1]``.
    """
    k = int(1.5 * feature_px) | 1
    k = max(5, min(k, (min(gray.shape) // 2) | 1))
    closed = cv2.morphologyEx(gray, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    paper = cv2.GaussianBlur(closed, (0, 0), k / 4)
    return np.clip(gray / np.maximum(paper, 1e-3), 0.0, 1.0).astype(np.float32)


def paper_preprocess(gray: np.ndarray, region: np.ndarray | None = None) -> np.ndarray:
    """The paper's preprocessing of a rectified cutout, for comparison: a 3x3 Gaussian blur
    (sigma 0.95), Otsu's threshold, everything outside a coarse ``region`` around the graphic
    set to paper, and the same blur again.

    The decoder does not use it. ``bench/preprocess.py`` measures it against the plain
    rectified view: on 100 scenes per severity it read as many payloads at easy and medium and
    fewer at hard (85.1 % against 87.2 %); dividing out the light (:func:`flatten_illumination`)
    read more than either (``docs/detection.md``).

    Args:
        gray: ``(H, W)`` float image, 1 = white.
        region: ``(H, W)`` bool, where the graphic may lie; ``None`` keeps everything.

    Returns:
        ``(H, W)`` float32 in ``[0, 1]``.
    """
    u8 = np.clip(gray * 255, 0, 255).astype(np.uint8)
    _, binary = cv2.threshold(cv2.GaussianBlur(u8, (3, 3), 0.95), 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    if region is not None:
        binary[~region] = 255
    return cv2.GaussianBlur(binary, (3, 3), 0.95).astype(np.float32) / 255.0


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
        ink_level = float(np.median(gray[_label_set(labels, n, inner)]))
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
    grown = cv2.dilate(_label_set(labels, n, keep, np.uint8), _SQUARE_3X3) > 0
    return grown & (gray < 0.5), (int(x0), int(y0), int(x1), int(y1))


_SQUARE_3X3 = np.ones((3, 3), np.uint8)


def component_label_type(height: int, width: int) -> int:
    """The OpenCV label type for the 8-connected components of a ``height`` x ``width`` mask:
    16 bits where they cannot run out, else 32. Two components never share a 2x2 block (its
    pixels all touch), so there are at most one per block; 16-bit labels take half the time of
    32-bit ones on the 192 px view every reading frames."""
    return cv2.CV_16U if ((height + 1) // 2) * ((width + 1) // 2) < 65535 else cv2.CV_32S


def _label_set(labels: np.ndarray, n: int, chosen: list[int], dtype: type = bool) -> np.ndarray:
    """Where ``labels`` (``n`` components) is one of ``chosen`` (as ``dtype``: bool, or 0/1):
    a table lookup (``np.isin`` sorts and took a third of :func:`ink_mask`'s time)."""
    table = np.zeros(n, dtype=dtype)
    table[chosen] = 1
    return table[labels]


def mask_moments(mask: Tensor) -> Tensor:
    """Centre and spread of ink masks: ``(B, H, W)`` bool -> ``(B, 4)`` = cx, cy, sx, sy (pixels).

    Moments average over every ink pixel, so one moved control point shifts them only a
    little: a far steadier frame than a bounding box, which any extreme point drags along.
    An empty mask gives the frame's own centre and spread.
    """
    B, H, W = mask.shape
    w = mask.to(torch.float64)
    total = w.sum((1, 2)).clamp_min(1.0)
    xs = torch.arange(W, dtype=torch.float64, device=mask.device) + 0.5
    ys = torch.arange(H, dtype=torch.float64, device=mask.device) + 0.5
    cx = (w.sum(1) * xs).sum(1) / total
    cy = (w.sum(2) * ys).sum(1) / total
    sx = torch.sqrt((w.sum(1) * (xs - cx[:, None]) ** 2).sum(1) / total).clamp_min(1.0)
    sy = torch.sqrt((w.sum(2) * (ys - cy[:, None]) ** 2).sum(1) / total).clamp_min(1.0)
    empty = mask.flatten(1).sum(1) == 0
    frame = torch.tensor([W / 2, H / 2, W / 4, H / 4], dtype=torch.float64, device=mask.device)
    return torch.where(empty[:, None], frame, torch.stack([cx, cy, sx, sy], 1))


def ink_moments(mask: np.ndarray) -> np.ndarray:
    """:func:`mask_moments` of one ``(H, W)`` mask, by OpenCV: ``(4,)`` float64 cx, cy, sx, sy.
    The same numbers (to float rounding) about six times faster, for decoding one photo."""
    H, W = mask.shape
    m = cv2.moments(np.asarray(mask, dtype=np.uint8), binaryImage=True)
    if m["m00"] == 0:
        return np.array([W / 2, H / 2, W / 4, H / 4], dtype=np.float64)
    spread = np.sqrt(np.array([m["mu20"], m["mu02"]]) / m["m00"])
    return np.array([m["m10"] / m["m00"] + 0.5, m["m01"] / m["m00"] + 0.5, *np.maximum(spread, 1.0)])


def canonicalize(images: Tensor, moments: Tensor, target: Tensor, size: tuple[int, int]) -> Tensor:
    """Resample so that each image's ink moments land on ``target`` in a white ``size`` frame.

    Used identically in training (on renders) and in decoding (on photos), so the decoder
    always sees drawings framed the same way. Differentiable w.r.t. ``images`` (bilinear).

    Shape:
        images ``(B, 1, h, w)``, moments ``(B, 4)`` (cx, cy, sx, sy in input pixels),
        target ``(4,)`` in output pixels -> ``(B, 1, H, W)``.
    """
    H, W = size
    h_in, w_in = images.shape[-2:]
    dtype, device = images.dtype, images.device
    m = moments.to(dtype=dtype, device=device)
    t = target.to(dtype=dtype, device=device)
    u = torch.arange(W, dtype=dtype, device=device) + 0.5
    v = torch.arange(H, dtype=dtype, device=device) + 0.5
    x = m[:, 0:1] + (u[None] - t[0]) * (m[:, 2:3] / t[2])  # (B, W) input coordinates
    y = m[:, 1:2] + (v[None] - t[1]) * (m[:, 3:4] / t[3])  # (B, H)
    gx = (x / w_in * 2 - 1)[:, None, :].expand(-1, H, -1)
    gy = (y / h_in * 2 - 1)[:, :, None].expand(-1, -1, W)
    grid = torch.stack([gx, gy], -1)
    # sample (image - 1) with zero padding so that everything outside the photo reads as white paper
    out = F.grid_sample(images - 1.0, grid, mode="bilinear", padding_mode="zeros", align_corners=False) + 1.0
    return out.clamp(0.0, 1.0)


def render_moments(images: Tensor) -> Tensor:
    """Ink moments of clean renders ``(B, 1, H, W)`` (ink = darker than 0.5): ``(B, 4)``."""
    with torch.no_grad():
        return mask_moments(images[:, 0] < 0.5)


def align_to_frame(
    gray: np.ndarray, size: tuple[int, int], target: Tensor
) -> tuple[np.ndarray, tuple[int, int, int, int]] | None:
    """Bring a photo or scan into the decoder's frame, as training frames its renders.

    Args:
        gray: ``(h, w)`` float image, 1 = white.
        size: ``(H, W)`` of the decoder's frame.
        target: ``(4,)`` ink moments of the unmorphed drawing in that frame.

    Returns:
        The ``(H, W)`` float32 frame and the ink's bounding box in the input, or ``None`` when
        the image holds no drawing (blank, or no ink).
    """
    norm = normalise_contrast(gray)
    if norm is None:
        return None
    found = ink_mask(norm)
    if found is None:
        return None
    mask, box = found
    moments = ink_moments(mask)
    goal = target.detach().cpu().numpy() if isinstance(target, Tensor) else np.asarray(target)
    src = norm
    shrink = float(goal[2]) / float(moments[2])
    factor = int(1 / max(shrink, 1e-6)) // 2
    if factor > 1:  # area-average large photos first so that thin strokes survive
        src = cv2.resize(norm, (norm.shape[1] // factor, norm.shape[0] // factor), interpolation=cv2.INTER_AREA)
        moments = moments * np.array([src.shape[1] / norm.shape[1], src.shape[0] / norm.shape[0]] * 2)
    return canonicalize_one(np.ascontiguousarray(src, dtype=np.float32), moments, goal, size), box


def canonicalize_one(
    gray: np.ndarray, moments: np.ndarray, target: Tensor | np.ndarray, size: tuple[int, int]
) -> np.ndarray:
    """:func:`canonicalize` of one ``(h, w)`` float32 image by OpenCV: the same map (a scale
    and a shift) and the same bilinear sampling with white beyond the edges, in a quarter of the
    time. It differs by about 1e-4 in intensity on average and by up to 0.02 on the steepest
    edges (OpenCV rounds sample positions to 1/32 pixel).

    Args:
        moments: ``(4,)`` cx, cy, sx, sy of the ink in ``gray``'s pixels.
        target: ``(4,)`` where they go in the ``size`` = ``(H, W)`` output.
    """
    H, W = size
    cx, cy, sx, sy = (float(v) for v in moments)
    tx, ty, tsx, tsy = (float(v) for v in target)
    ax, ay = sx / tsx, sy / tsy
    # output pixel u (centre u + 0.5) samples input position cx + (u + 0.5 - tx) * ax, whose
    # pixel-centre coordinate (OpenCV's) is half a pixel less
    M = np.array([[ax, 0.0, cx + (0.5 - tx) * ax - 0.5], [0.0, ay, cy + (0.5 - ty) * ay - 0.5]])
    out = cv2.warpAffine(
        gray, M, (W, H), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0
    )
    return np.clip(out, 0.0, 1.0, out=out)
