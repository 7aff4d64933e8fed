"""Image files: reading photos and scans (EXIF orientation, pixel limits), writing PNGs.

OpenCV decodes every format but HEIF/HEIC, the format iPhones take photos in; those are
decoded by libheif (``pillow-heif``, registered with Pillow here), which also applies the
photo's stored turn.

Reading refuses, with one clear error, what is not an image, what is too large to decode
(judged from the header, before any pixel is decoded) and what is too small to hold a
drawing. Writing encodes in memory and then writes atomically, so a failed write never leaves
half an image behind.
"""

from __future__ import annotations

import io
import os
import re
import sys
import tempfile
import textwrap
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Union

import cv2
import numpy as np
import pillow_heif
from PIL import Image

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write
from deepmorph_core.photo import to_gray

MAX_IMAGE_PIXELS = 80_000_000  # also OpenCV's own limit (OPENCV_IO_MAX_IMAGE_PIXELS, set by deepmorph_core)
MAX_IMAGE_BYTES = 256 * 1024 * 1024


EXIF_ORIENTATION = 0x0112  # the EXIF tag of how a viewer turns the stored pixels

#: The brands of an ISO media file's ``ftyp`` box that say HEIF: an iPhone's ``heic``, its
#: sequences and the generic image brands. Pillow opens them through libheif, which applies the
#: stored turn (``irot``/``imir``) and reports the EXIF orientation as 1, so it is not turned twice.
HEIF_BRANDS = (b"heic", b"heix", b"heim", b"heis", b"hevc", b"hevx", b"hevm", b"hevs", b"mif1", b"msf1")
pillow_heif.register_heif_opener()


MIN_IMAGE_SIDE = 16  # pixels: smaller images cannot hold a drawing the detector or decoder could read

#: What a user hands in as a photo (:func:`image_input`): a path, a PIL image or an array.
ImageLike = Union[str, Path, Image.Image, np.ndarray]


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
    try:
        if not path.is_file():
            raise DeepMorphError(f"{path}: no such image file")
        if path.stat().st_size > MAX_IMAGE_BYTES:
            raise DeepMorphError(f"{path}: {path.stat().st_size} bytes is larger than any photo DeepMorph reads")
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise DeepMorphError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if data.size == 0:
        raise DeepMorphError(f"{path}: empty file, not an image")
    size, orientation = _peek_header(data, path)
    if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:  # refused before it is decoded
        raise DeepMorphError(f"{path}: {size[0]}x{size[1]} pixels is too large to decode")
    with _stderr_captured() as said:
        try:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        except cv2.error:  # OpenCV's own pixel limit, from the header (deepmorph_core sets it)
            raise DeepMorphError(f"{path}: its header claims too many pixels to decode") from None
    if img is None and is_heif(data):
        img = _heif_bgr(data, path)
    if img is None:
        why = library_said(said[0]) if said else ""
        raise DeepMorphError(
            f"{path}: not an image OpenCV can read (corrupt, or an unsupported format{': ' + why if why else ''})"
        )
    if img.shape[0] * img.shape[1] > MAX_IMAGE_PIXELS:
        raise DeepMorphError(f"{path}: {img.shape[1]}x{img.shape[0]} pixels is too large to decode")
    img = upright(img, orientation)
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


def is_heif(data: np.ndarray) -> bool:
    """Whether the file's bytes ``data`` start as a HEIF image (an ISO media ``ftyp`` box with a
    brand of :data:`HEIF_BRANDS`)."""
    head = data[:12].tobytes()
    return len(head) == 12 and head[4:8] == b"ftyp" and head[8:12] in HEIF_BRANDS


def _heif_bgr(data: np.ndarray, path: Path) -> np.ndarray:
    """A HEIF file's bytes decoded by libheif, turned as stored: ``(H, W, 3|4)`` uint8 BGR(A)
    (10- and 12-bit photos brought to 8 bits).

    Raises:
        DeepMorphError: a file libheif cannot decode, saying what it said.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(io.BytesIO(data.tobytes())) as img:
                rgb = np.asarray(img.convert("RGBA" if "A" in img.getbands() else "RGB"))
    except Exception as exc:  # libheif's errors come as several types; each is a bad file
        # (a header past the pixel limits was refused by _peek_header, which opens it the same way)
        said = textwrap.shorten(str(exc), 120, placeholder=" ...")
        raise DeepMorphError(f"{path}: a HEIF image libheif cannot decode{': ' + said if said else ''}") from None
    return np.ascontiguousarray(rgb[..., [2, 1, 0, 3][: rgb.shape[2]]])


def image_input(source: ImageLike, bgr: bool = False) -> np.ndarray:
    """What a user hands in as a photo, as the photo chain takes it: a path (read with
    :func:`read_image_bgr`), a PIL image, or an array.

    Colour arrays are RGB (PIL's and most libraries' order) unless ``bgr`` says they are
    OpenCV's BGR; a 4th channel is transparency. Gray arrays and float arrays in ``[0, 1]``
    pass as they are.

    Returns:
        ``(H, W)`` gray or ``(H, W, 3|4)`` BGR(A) array.

    Raises:
        DeepMorphError: a path that is not a readable image, or another type.
    """
    if isinstance(source, (str, Path)):
        if Path(source).is_dir():
            raise DeepMorphError(f"{source}: is a folder, not an image file")
        return read_image_bgr(source)
    if isinstance(source, Image.Image):
        source = np.asarray(source.convert("RGBA" if "A" in source.getbands() else "RGB"))
    if not isinstance(source, np.ndarray):
        what = "None" if source is None else f"a {type(source).__name__}"
        raise DeepMorphError(f"an image is a path, a PIL image or an array, not {what}")
    if source.ndim == 3 and source.shape[2] in (3, 4) and not bgr:
        source = source[..., [2, 1, 0, 3][: source.shape[2]]]
    return np.ascontiguousarray(source)


#: OpenCV's log line before its message: ``[ERROR:0@1.514] global loadsave.cpp:1377 imdecode_ ``
_OPENCV_LOG_PREFIX = re.compile(r"^\[\w+:[^\]]*\]\s+global\s+\S+:\d+\s+\S+\s+")
#: the function ``imdecode_('')`` names itself with, and an exception's source location, code and function
_OPENCV_NOISE = (
    re.compile(r"^\w+\('[^']*'\):\s*"),
    re.compile(r"OpenCV\([^)]*\)\s+\S+:\d+:\s+error:\s+\([^)]*\)\s*"),
    re.compile(r"\s+in function '[^']*'"),
)


def library_said(stderr: str) -> str:
    """The last thing an image library wrote on stderr (:func:`_stderr_captured`), as a user
    reads it: OpenCV's log prefix, source file and function names left out (``[ERROR:0@1.5]
    global loadsave.cpp:1377 imdecode_ imdecode_(''): can't read header: OpenCV(5.1.0)
    .../bitstrm.cpp:59: error: (-2:Unspecified error) Unexpected end of input stream in function
    'readBlock'`` says "can't read header: Unexpected end of input stream"); at most 120
    characters, ``""`` when it wrote nothing."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    if not lines:
        return ""
    text = _OPENCV_LOG_PREFIX.sub("", lines[-1])
    for noise in _OPENCV_NOISE:
        text = noise.sub("", text)
    return text.strip()[:120]


@contextmanager
def _stderr_captured() -> Iterator[list[str]]:
    """What the image libraries print on stderr while decoding (libpng's and libjpeg's
    warnings), caught instead of shown: a file's problems are reported in one error line, or
    not at all when the image decodes. Yields a list that holds the text afterwards."""
    said: list[str] = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no file descriptor 2 to redirect (an embedding host)
        yield said
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            said.append(sink.read(4096).decode("utf-8", "replace"))


def _radiance_or_pfm_size(data: np.ndarray) -> tuple[int, int] | None:
    """``(width, height)`` from a Radiance HDR or PFM header (formats Pillow does not read)."""
    head = data[:4096].tobytes()
    if head.startswith((b"#?RADIANCE", b"#?RGBE")):
        m = re.search(rb"\n\s*[-+]Y\s+(\d+)\s+[-+]X\s+(\d+)", head)
        return (int(m.group(2)), int(m.group(1))) if m else None
    if head[:2] in (b"PF", b"Pf"):
        m = re.match(rb"P[Ff]\s+(\d+)\s+(\d+)", head)
        return (int(m.group(1)), int(m.group(2))) if m else None
    return None


def _peek_header(data: np.ndarray, path: Path) -> tuple[tuple[int, int] | None, int]:
    """``((width, height), EXIF orientation)`` from an image file's header, without decoding
    its pixels (Pillow opens lazily); ``(None, 1)`` where Pillow cannot tell, and then OpenCV's
    decoder alone judges the file.

    Raises:
        DeepMorphError: a header beyond Pillow's own bomb limit (far more than
            :data:`MAX_IMAGE_PIXELS`), before any pixel is decoded.
    """
    try:
        with warnings.catch_warnings():  # the size is judged by the caller, and a damaged
            warnings.simplefilter("ignore")  # header's metadata warnings are not the user's concern
            with Image.open(io.BytesIO(data.tobytes())) as img:
                return img.size, int(img.getexif().get(EXIF_ORIENTATION, 1) or 1)
    except Image.DecompressionBombError:
        raise DeepMorphError(f"{path}: its header claims far too many pixels to decode") from None
    except Exception:  # not a format Pillow knows, or a header it cannot parse: OpenCV decides
        return _radiance_or_pfm_size(data), 1


def upright(img: np.ndarray, orientation: int) -> np.ndarray:
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


def save_gray(image: np.ndarray, path: str | Path, dpi: int | None = None) -> None:
    """Save an ``(H, W)`` intensity image in ``[0, 1]`` as an 8-bit PNG (or any Pillow format).

    ``dpi`` is recorded in the file so that printing it gives the intended physical size.
    """
    arr = np.clip(np.rint(np.asarray(image) * 255), 0, 255).astype(np.uint8)
    _save(Image.fromarray(arr, "L"), path, dpi)


def save_rgb(image: np.ndarray, path: str | Path) -> None:
    """Save an ``(H, W, 3)`` image in ``[0, 1]``."""
    arr = np.clip(np.rint(np.asarray(image) * 255), 0, 255).astype(np.uint8)
    _save(Image.fromarray(arr, "RGB"), path)


def save_bgr(image: np.ndarray, path: str | Path) -> None:
    """Save an ``(H, W, 3)`` uint8 BGR (or ``(H, W)`` gray) image, the format by the path's
    extension (OpenCV's encoders), written atomically.

    Raises:
        DeepMorphError: an extension OpenCV cannot write.
    """
    path = Path(path)
    try:
        ok, buf = cv2.imencode(path.suffix or ".png", np.ascontiguousarray(image))
    except cv2.error:
        ok = False
    if not ok:
        raise DeepMorphError(f"{path}: cannot write this image format (use .png or .jpg)")
    atomic_write(path, buf.tobytes())


def image_format(path: str | Path) -> str:
    """The image format Pillow writes for ``path``'s extension (check it before any work).

    Raises:
        DeepMorphError: an extension no image format has.
    """
    path = Path(path)
    fmt = Image.registered_extensions().get(path.suffix.lower())
    if fmt is None:
        raise DeepMorphError(f"{path}: cannot write image: unknown file extension {path.suffix!r} (use .png)")
    return fmt


def _save(img: Image.Image, path: str | Path, dpi: int | None = None) -> None:
    """Encode in memory, then write atomically: a failed write never leaves half an image (or
    half of the file it replaces)."""
    path = Path(path)
    fmt = image_format(path)
    buf = io.BytesIO()
    try:
        img.save(buf, format=fmt, **({"dpi": (dpi, dpi)} if dpi else {}))
    except (OSError, ValueError) as exc:
        raise DeepMorphError(f"{path}: cannot write image: {exc}") from None
    atomic_write(path, buf.getvalue())
