"""Inputs of ``deepmorph decode``: image files, folders of frames, and videos.

An image file is decoded on its own; a folder (its image files in name order) or a video (its
frames, read by OpenCV's bundled FFmpeg) is one sequence whose frames are fused per drawing.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.image_io import MIN_IMAGE_SIDE

IMAGE_SUFFIXES = {
    ".png",
    ".jpg",
    ".jpeg",
    ".bmp",
    ".tif",
    ".tiff",
    ".webp",
    ".avif",
    ".heic",
    ".heif",
    ".pgm",
    ".ppm",
    ".pbm",
}
VIDEO_SUFFIXES = {".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv"}
MAX_FRAMES = 100_000

# FFmpeg's own log lines ("moov atom not found", ...) would print before our one clear error for a
# corrupt video; OpenCV reads this when it first opens a video. A user's own setting is kept.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


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


def video_frame_count(path: Path, every: int = 1) -> int | None:
    """How many frames :func:`video_frames` will give, from the container's count (for a
    progress bar: containers may miscount); ``None`` when it does not say."""
    cap = cv2.VideoCapture(str(path))
    try:
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
    finally:
        cap.release()
    return min(count, MAX_FRAMES) // every + (min(count, MAX_FRAMES) % every > 0) if count > 0 else None


__all__ = ["IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "check_video", "folder_frames", "is_video", "video_frame_count",
           "video_frames"]  # fmt: skip


def check_video(path: Path) -> tuple[int, int]:
    """Fail early (before any work) when a video cannot be opened or has no readable frame;
    the ``(width, height)`` of its frames."""
    if not path.is_file():
        raise DeepMorphError(f"{path}: no such video file")
    cap = cv2.VideoCapture(str(path))
    try:
        ok, frame = cap.read() if cap.isOpened() else (False, None)
    finally:
        cap.release()
    if not ok or frame is None:
        raise DeepMorphError(f"{path}: not a video OpenCV can read (corrupt, or an unsupported codec)")
    if min(frame.shape[:2]) < MIN_IMAGE_SIDE:
        h, w = frame.shape[:2]
        raise DeepMorphError(
            f"{path}: frames of {w}x{h} pixels are too small to hold a drawing"
            f" (at least {MIN_IMAGE_SIDE} pixels each way)"
        )
    return frame.shape[1], frame.shape[0]
