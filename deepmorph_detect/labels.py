"""``labels.csv``: what each photo of a folder shows, for ``deepmorph bench-photos``.

One row per printed code in a photo: the file name (relative to the folder), the expected
payload in hex (``0x`` optional), and optionally the 8 pixel coordinates ``x0,y0,...,x3,y3`` of
the corners of the drawing's frame (its viewBox) in the photo: top-left, top-right,
bottom-right, bottom-left, as ``deepmorph decode --json`` reports ``corners``. A photo holding
two codes has two rows; a photo holding none has one row with an empty payload. A first row
starting with ``file`` is a header. ``deepmorph synth`` writes this file beside its scenes.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.payload import format_payload, hex_digits, parse_payload_text

LABELS_NAME = "labels.csv"
HEADER = ("file", "payload", "x0", "y0", "x1", "y1", "x2", "y2", "x3", "y3")


@dataclass(frozen=True)
class Label:
    """One row of ``labels.csv``.

    Attributes:
        line: the row's line in the file (for messages).
        file: the photo's name, relative to the folder.
        payload: ``(payload_bits,)`` uint8 bits, or ``None`` for a photo without a code.
        corners: ``(4, 2)`` pixel corners of the drawing's frame (TL, TR, BR, BL), when labelled.
    """

    line: int
    file: str
    payload: np.ndarray | None
    corners: np.ndarray | None = None


def _payload(text: str, payload_bits: int) -> np.ndarray:
    s = text.strip()
    if s[:2] not in ("0x", "0X") and len(s) == hex_digits(payload_bits):
        s = "0x" + s
    return parse_payload_text(s, payload_bits)


def _file_name(text: str) -> str:
    name = text.strip()
    parts = PurePosixPath(name.replace("\\", "/")).parts
    if not name or name.startswith(("/", "\\")) or ".." in parts or (parts and ":" in parts[0]):
        raise ValueError(f"file {name!r} must be a name inside the photos' folder")
    return name


def read_labels(path: Path, payload_bits: int) -> list[Label]:
    """Every row of a labels file, checked.

    Raises:
        DeepMorphError: ``file:line: what`` for the first bad row (an unreadable payload, a
            corner count other than 0 or 8, a number that is not finite, a photo marked both
            with and without a code), or a file that is not readable text.
    """
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise DeepMorphError(f"{path}: cannot read the labels ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise DeepMorphError(f"{path}: not a text file (expected CSV: file, payload, corners)") from None
    labels: list[Label] = []
    reader = csv.reader(io.StringIO(text))
    header_seen = False
    while True:
        try:
            row = next(reader)
        except StopIteration:
            break
        except csv.Error as exc:
            raise DeepMorphError(f"{path}:{reader.line_num}: not CSV ({exc})") from None
        line = reader.line_num
        cells = [c.strip() for c in row]
        while cells and not cells[-1]:
            cells.pop()
        if not cells or cells[0].startswith("#"):
            continue
        if not labels and not header_seen and cells[0].lower() == "file":
            header_seen = True
            continue
        try:
            labels.append(_row(cells, line, payload_bits))
        except (ValueError, DeepMorphError) as exc:
            raise DeepMorphError(f"{path}:{line}: {exc}") from None
    _check_codeless(path, labels)
    if not labels:
        raise DeepMorphError(f"{path}: no labels (rows: file, payload in hex[, x0,y0,...,x3,y3])")
    return labels


def _row(cells: list[str], line: int, payload_bits: int) -> Label:
    name = _file_name(cells[0])
    payload = _payload(cells[1], payload_bits) if len(cells) > 1 and cells[1] else None
    numbers = cells[2:]
    if numbers and len(numbers) != 8:
        raise ValueError(f"{len(numbers)} corner coordinates; expected none or 8 (x0,y0,...,x3,y3 in pixels)")
    corners = None
    if numbers:
        try:
            values = [float(v) for v in numbers]
        except ValueError:
            raise ValueError("corner coordinates must be numbers (pixels)") from None
        if not all(math.isfinite(v) for v in values):
            raise ValueError("corner coordinates must be finite")
        if payload is None:
            raise ValueError("corners without a payload: a photo without a code has no corners")
        corners = np.asarray(values, dtype=np.float64).reshape(4, 2)
    return Label(line, name, payload, corners)


def _check_codeless(path: Path, labels: list[Label]) -> None:
    """A photo is either without a code (one row, empty payload) or holds codes, not both."""
    first: dict[str, Label] = {}
    for label in labels:
        other = first.setdefault(label.file, label)
        if other is not label and (other.payload is None or label.payload is None):
            raise DeepMorphError(
                f"{path}:{label.line}: {label.file} is also on line {other.line}; a photo without a code"
                " has one row with an empty payload, a photo with codes one row per code"
            )


def label_rows(file: str, codes: list[tuple[np.ndarray, np.ndarray]]) -> list[list[str]]:
    """The rows of one photo: one per ``(payload bits, (4, 2) corners)``, or one empty row."""
    if not codes:
        return [[file, ""]]
    return [[file, format_payload(bits)["hex"], *(f"{v:.2f}" for v in np.asarray(c).ravel())] for bits, c in codes]


def labels_text(rows: list[list[str]]) -> str:
    """``labels.csv`` with its header."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(HEADER)
    writer.writerows(rows)
    return buf.getvalue()


__all__ = ["HEADER", "LABELS_NAME", "Label", "label_rows", "labels_text", "read_labels"]
