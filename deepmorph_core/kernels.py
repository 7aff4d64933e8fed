"""Fast, exact numeric kernels of the photo chain: area shrinking, percentiles, component labels.

Each returns what its general library counterpart returns (OpenCV's ``INTER_AREA`` resize to
1e-7, ``np.percentile`` to the last bit) in a fraction of the time, for the sizes every photo
needs; where it cannot, it hands over to the library.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

# area_resize's own path: an axis shrunk by q/p in lowest terms with q at most this many (every
# p source pixels give q output pixels) is resampled with one small matrix per period
MAX_AREA_OUTPUTS_PER_PERIOD = 8
#: A 3x3 square structuring element (dilations by one pixel, 3x3 local maxima).
SQUARE_3X3 = np.ones((3, 3), np.uint8)


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
    others, such as the 640x480 -> 256x192 that every photo's detector input needs. The same
    averages, period by period, are two small matrix products (about 7x faster from a phone
    photo). Whole-number ratios, other images and long periods go to OpenCV.

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
    numpy's own interpolation formula, without its general machinery (about 5x faster on the
    192 px view every reading of a photo frames by its percentiles).

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


def component_label_type(height: int, width: int) -> int:
    """The OpenCV label type for the 8-connected components of a ``height`` x ``width`` mask:
    16 bits where they cannot run out, else 32. Two components never share a 2x2 block (its
    pixels all touch), so there are at most one per block; 16-bit labels take half the time of
    32-bit ones on the 192 px view every reading frames."""
    return cv2.CV_16U if ((height + 1) // 2) * ((width + 1) // 2) < 65535 else cv2.CV_32S


def label_set(labels: np.ndarray, n: int, chosen: list[int], dtype: type = bool) -> np.ndarray:
    """Where ``labels`` (``n`` components) is one of ``chosen`` (as ``dtype``: bool, or 0/1):
    a table lookup (``np.isin`` sorts, which costs a third of
    :func:`~deepmorph_core.photo.ink_mask`'s time)."""
    table = np.zeros(n, dtype=dtype)
    table[chosen] = 1
    return table[labels]
