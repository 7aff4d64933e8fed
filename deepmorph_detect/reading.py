"""Reading a sequence of frames (a folder of images, a video, a live camera): every frame through
the photo chain, drawings followed from one frame to the next, their readings fused.

:class:`SequenceReader` reads frames one at a time (the studio's camera stream);
:func:`read_sequence` reads a whole sequence with it (``deepmorph decode`` on a folder or a
video). Single images go straight to :meth:`~deepmorph_detect.locate.Locator.locate`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deepmorph_core.errors import DeepMorphError

if TYPE_CHECKING:
    import numpy as np

    from deepmorph_detect.camera import Camera
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.results import Located

#: ``on_skip(message)``: a frame that could not be read or located was skipped (the message
#: names it and says why).
SkipHook = Callable[[str], None]


@dataclass
class SequenceReading:
    """What a sequence of frames gave.

    Attributes:
        frames: frames read.
        detections: the fused detections as JSON (``decode --json``'s ``detections``).
        skipped: ``{"frame", "error"}`` for each frame skipped.
        last: the last frame read (BGR) and its detections, for an overlay.
    """

    frames: int
    detections: list[dict[str, Any]]
    skipped: list[dict[str, str]] = field(default_factory=list)
    last: tuple[np.ndarray, list[Located]] | None = None


def folder_images(files: Iterable[Path]) -> Iterator[tuple[str, np.ndarray | DeepMorphError]]:
    """``(name, BGR image)`` of a folder's frames in order; ``(name, error)`` for a file that is
    not a readable image (truncated while copying, say): :func:`read_sequence` skips it, and the
    frames before and after it still count."""
    from deepmorph_core.image_io import read_image_bgr

    for path in files:
        try:
            yield path.name, read_image_bgr(path)
        except DeepMorphError as exc:
            yield path.name, exc


@dataclass
class FrameSource:
    """A sequence on disk, checked before any work: a folder of frames or a video.

    Attributes:
        path: the folder or the video.
        files: a folder's image files in name order; ``None`` for a video.
        frame_size: a video's ``(width, height)``; ``None`` for a folder (its images may differ).
    """

    path: Path
    files: list[Path] | None = None
    frame_size: tuple[int, int] | None = None

    @classmethod
    def open(cls, path: str | Path) -> FrameSource | None:
        """The sequence at ``path``; ``None`` when it is neither a folder nor a video (a single
        image, read by :meth:`~deepmorph_detect.locate.Locator.locate`).

        Raises:
            DeepMorphError: a folder without image files; a missing or unreadable video.
        """
        from deepmorph_detect.media import check_video, folder_frames, is_video

        path = Path(path)
        if path.is_dir():
            return cls(path, files=folder_frames(path))
        if is_video(path):
            return cls(path, frame_size=check_video(path))
        return None

    def frames(self, every: int = 1) -> Iterator[tuple[str, np.ndarray | DeepMorphError]]:
        """``(label, BGR frame)`` in order (every ``every``-th frame of a video); ``(label,
        error)`` for a folder's file that cannot be read."""
        from deepmorph_detect.media import video_frames

        return folder_images(self.files) if self.files is not None else video_frames(self.path, every)

    def count(self, every: int = 1) -> int | None:
        """How many frames :meth:`frames` gives (a video's container may not say: ``None``)."""
        from deepmorph_detect.media import video_frame_count

        return len(self.files) if self.files is not None else video_frame_count(self.path, every)


class SequenceReader:
    """Frames read one at a time (a camera's stream, or a folder's files in order): each drawing
    read in a frame is followed into the next, and the readings of a drawing are fused over the
    frames.

    Args:
        locator: the photo chain of one model.
        camera: calibrated intrinsics, or ``None`` (an assumed phone camera).
        soft: soft-decision (Chase) decoding.
        first: each frame's search stops at the first print read (:meth:`Locator.locate
            <deepmorph_detect.locate.Locator.locate>`'s ``first``).
    """

    def __init__(
        self, locator: Locator, *, camera: Camera | None = None, soft: bool = True, first: bool = False
    ) -> None:
        from deepmorph_detect.fusion import FrameFuser
        from deepmorph_detect.track import SequenceLocator

        self.camera = camera
        self.soft = soft
        self._fuser = FrameFuser(locator.model.codec, locator.check_payload, locator.refuses_reading)
        self._follow = SequenceLocator(locator, first=first)
        self.last: tuple[np.ndarray, list[Located]] | None = None

    @property
    def frames(self) -> int:
        """Frames read so far."""
        return self._fuser.frames

    def add(self, label: str, frame: np.ndarray) -> list[Located]:
        """Read one BGR frame: its drawings, followed from the previous frame.

        Raises:
            DeepMorphError: a frame the chain refuses (another size than the calibration's, say).
        """
        dets = self._follow(frame, camera=self.camera, soft=self.soft)
        self._fuser.add(label, dets, frame)
        self.last = (frame, dets)
        return dets

    def fused(self) -> list[dict[str, Any]]:
        """Every drawing seen so far, its readings fused over the frames (as JSON)."""
        return self._fuser.results(self.soft)


def read_sequence(
    locator: Locator,
    frames: Iterable[tuple[str, np.ndarray | DeepMorphError]],
    *,
    camera: Camera | None = None,
    soft: bool = True,
    on_frame: Callable[[], None] | None = None,
    on_skip: SkipHook | None = None,
    name: str = "sequence",
    first: bool = False,
) -> SequenceReading:
    """Read ``frames`` in order with a :class:`SequenceReader`: what ``deepmorph decode`` does
    with a folder or a video.

    Args:
        locator: the photo chain of one model.
        frames: ``(label, BGR image)`` pairs; ``(label, error)`` for a frame that could not be
            read (skipped, as :func:`folder_images` yields them).
        camera: calibrated intrinsics, or ``None`` (an assumed phone camera).
        soft: soft-decision (Chase) decoding.
        on_frame: called once per frame taken (progress bars).
        on_skip: called with a message for each frame skipped: unreadable, or one the chain
            refused (a frame of another size than the calibration's, say).
        name: the sequence's name in errors.
        first: each frame's search stops at the first print read (:class:`SequenceReader`).

    Returns:
        A :class:`SequenceReading`.

    Raises:
        DeepMorphError: not one frame could be read.
    """
    reader = SequenceReader(locator, camera=camera, soft=soft, first=first)
    skipped: list[dict[str, str]] = []
    for label, frame in frames:
        if on_frame is not None:
            on_frame()
        if isinstance(frame, DeepMorphError):
            skipped.append({"frame": label, "error": str(frame)})
            if on_skip is not None:
                on_skip(f"skipped frame {frame}")
            continue
        try:
            reader.add(label, frame)
        except DeepMorphError as exc:
            skipped.append({"frame": label, "error": str(exc)})
            if on_skip is not None:
                on_skip(f"skipped frame {label}: {exc}")
    if reader.last is None:
        why = f" ({skipped[0]['error']})" if skipped else ""
        raise DeepMorphError(f"{name}: no frame could be read{why}")
    return SequenceReading(reader.frames, reader.fused(), skipped, reader.last)


__all__ = ["FrameSource", "SequenceReader", "SequenceReading", "SkipHook", "folder_images", "read_sequence"]
