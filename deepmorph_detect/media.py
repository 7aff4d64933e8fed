"""Inputs of ``deepmorph decode``: image files, folders of frames, and videos.

An image file is decoded on its own; a folder (its image files in name order) or a video (its
frames, read by OpenCV's bundled FFmpeg) is one sequence whose frames are fused per drawing.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.imaging import MAX_IMAGE_PIXELS

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm", ".pbm"}
VIDEO_SUFFIXES = {".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv"}
MAX_FRAMES = 100_000


def read_color(path: str | Path) -> np.ndarray:
    """An image file as ``(H, W, 3)`` uint8 BGR (transparency composited onto white).

    Raises:
        DeepMorphError: missing, empty, corrupt, too large or non-image files.
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
    if img.dtype == np.uint16:
        img = (img // 257).astype(np.uint8)
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:
        alpha = img[..., 3:4].astype(np.float32) / 255.0
        return (img[..., :3].astype(np.float32) * alpha + 255.0 * (1 - alpha)).astype(np.uint8)
    return img[..., :3]


def is_video(path: Path) -> bool:
    return path.suffix.lower() in VIDEO_SUFFIXES


def folder_frames(path: Path) -> list[Path]:
    """The image files of a folder in name order (at least one)."""
    files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise DeepMorphError(f"{path}: folder holds no image files ({', '.join(sorted(IMAGE_SUFFIXES))})")
    return files


def video_frames(path: Path, every: int = 1) -> Iterator[tuple[str, np.ndarray]]:
    """``(label, BGR frame)`` for every ``every``-th frame of a video.

    Raises:
        DeepMorphError: a missing, unreadable or empty video.
    """
    if not path.is_file():
        raise DeepMorphError(f"{path}: no such video file")
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise DeepMorphError(f"{path}: not a video OpenCV can read (corrupt, or an unsupported codec)")
        index = 0
        produced = 0
        while index < MAX_FRAMES:
            ok, frame = cap.read()
            if not ok or frame is None:
                break
            if index % every == 0:
                produced += 1
                yield f"{path.name}#{index}", frame
            index += 1
        if produced == 0:
            raise DeepMorphError(f"{path}: no frame could be read (corrupt, or an unsupported codec)")
    finally:
        cap.release()


__all__ = ["IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "check_video", "folder_frames", "is_video", "read_color", "video_frames"]


def check_video(path: Path) -> None:
    """Fail early (before any work) when a video cannot be opened or has no readable frame."""
    if not path.is_file():
        raise DeepMorphError(f"{path}: no such video file")
    cap = cv2.VideoCapture(str(path))
    try:
        ok, frame = cap.read() if cap.isOpened() else (False, None)
    finally:
        cap.release()
    if not ok or frame is None:
        raise DeepMorphError(f"{path}: not a video OpenCV can read (corrupt, or an unsupported codec)")
