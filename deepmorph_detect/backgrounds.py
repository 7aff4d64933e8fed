"""Backgrounds for synthetic scenes: real photos and procedural clutter.

The photos ship with the package (``data/backgrounds/``: 13 small JPEGs, 640 KB, from
scikit-image's sample data, each public domain or CC0; their sources are in the folder's
``LICENSE``): a desk, a cat, a rocket, a camera, bricks, gravel, grass, text ... Procedural
clutter adds what photos of real places hold and a detector must not fire on: hard edges,
text, line art, stripes and blobs of every tone.
"""

from __future__ import annotations

import functools
from pathlib import Path

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError

PHOTOS = Path(__file__).parent / "data" / "backgrounds"


@functools.lru_cache(maxsize=1)
def sample_photos() -> tuple[np.ndarray, ...]:
    """The shipped background photos as float32 BGR ``(H, W, 3)`` in ``[0, 1]``, by name.

    Raises:
        DeepMorphError: the photos are missing or unreadable (a broken installation): scenes
            without them would be a different benchmark.
    """
    photos = []
    for path in sorted(PHOTOS.glob("*.jpg")):
        img = cv2.imdecode(np.fromfile(path, dtype=np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            raise DeepMorphError(f"{path}: the background photo cannot be read; reinstall deepmorph")
        photos.append(img.astype(np.float32) / 255.0)
    if not photos:
        raise DeepMorphError(f"{PHOTOS}: the background photos are missing; reinstall deepmorph")
    return tuple(photos)


def photo_background(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """A random crop of a random sample photo, resized, flipped and tinted: ``(H, W, 3)``."""
    W, H = size
    photos = sample_photos()
    img = photos[int(rng.integers(len(photos)))]
    h, w = img.shape[:2]
    frac = rng.uniform(0.4, 1.0)
    ch = max(8, int(h * frac))
    cw = max(8, min(w, int(ch * W / H)))
    y0 = int(rng.integers(0, h - ch + 1))
    x0 = int(rng.integers(0, w - cw + 1))
    crop = cv2.resize(img[y0 : y0 + ch, x0 : x0 + cw], (W, H), interpolation=cv2.INTER_LINEAR)
    if rng.random() < 0.5:
        crop = crop[:, ::-1]
    tint = rng.uniform(0.8, 1.15, 3).astype(np.float32)
    return np.clip(crop * tint, 0, 1)


def clutter_background(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """A procedural scene: a toned gradient with shapes, lines, strokes and text on it."""
    W, H = size
    base = rng.uniform(0.15, 0.9, 3).astype(np.float32)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    grad = 1.0 + rng.uniform(-0.4, 0.4) * (xx / W - 0.5) + rng.uniform(-0.4, 0.4) * (yy / H - 0.5)
    img = np.clip(base[None, None, :] * grad[..., None], 0, 1).astype(np.float32)
    add_clutter(img, rng, int(rng.integers(4, 25)))
    return img


def add_clutter(img: np.ndarray, rng: np.random.Generator, count: int) -> None:
    """Draw ``count`` random shapes, lines, strokes and words onto ``img`` in place."""
    H, W = img.shape[:2]
    for _ in range(count):
        colour = tuple(float(c) for c in rng.uniform(0, 1, 3))
        kind = rng.integers(6)
        p = (int(rng.integers(0, W)), int(rng.integers(0, H)))
        q = (int(rng.integers(0, W)), int(rng.integers(0, H)))
        thick = int(rng.integers(1, max(2, W // 60)))
        if kind == 0:
            cv2.rectangle(img, p, q, colour, -1 if rng.random() < 0.6 else thick, cv2.LINE_AA)
        elif kind == 1:
            r = int(rng.integers(3, max(4, W // 6)))
            cv2.circle(img, p, r, colour, -1 if rng.random() < 0.5 else thick, cv2.LINE_AA)
        elif kind == 2:
            cv2.line(img, p, q, colour, thick, cv2.LINE_AA)
        elif kind == 3:  # line art: a dark polyline with round joins, like an icon's strokes
            n = int(rng.integers(3, 8))
            span = rng.uniform(0.03, 0.2) * W
            pts = np.asarray(p, np.float32) + np.cumsum(rng.normal(0, span / 3, (n, 2)), 0)
            dark = tuple(float(c) for c in rng.uniform(0, 0.3, 3))
            cv2.polylines(img, [pts.astype(np.int32)], bool(rng.random() < 0.3), dark, thick, cv2.LINE_AA)
        elif kind == 4:
            text = "".join(chr(int(c)) for c in rng.integers(65, 91, int(rng.integers(3, 10))))
            mask = np.zeros((H, W), np.uint8)  # putText draws on 8-bit images only
            cv2.putText(
                mask, text, p, int(rng.integers(0, 8)), rng.uniform(0.4, 2.0) * W / 640, 255, thick, cv2.LINE_AA
            )
            alpha = mask.astype(np.float32)[..., None] / 255.0
            img *= 1 - alpha
            img += alpha * np.asarray(colour, np.float32)
        else:  # stripes
            step = int(rng.integers(4, 20))
            x0, x1 = sorted((p[0], q[0]))
            y0, y1 = sorted((p[1], q[1]))
            for x in range(x0, x1, step):
                cv2.line(img, (x, y0), (x, y1), colour, max(1, step // 3))


def random_background(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """A photo (with some clutter on it) or a procedural scene, ``(H, W, 3)`` float32."""
    if rng.random() < 0.65:
        img = np.ascontiguousarray(photo_background(rng, size))
        if rng.random() < 0.5:
            add_clutter(img, rng, int(rng.integers(1, 8)))
        return img
    return clutter_background(rng, size)


__all__ = ["PHOTOS", "add_clutter", "clutter_background", "photo_background", "random_background", "sample_photos"]
