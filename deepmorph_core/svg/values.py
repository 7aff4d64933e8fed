"""Parsing SVG attribute values: numbers, lengths, point lists and transform lists.

Every parser raises ``ValueError`` with a short message; :class:`ElementReader` turns that into
an :class:`~deepmorph_core.errors.SvgError` carrying the file and line.
"""

from __future__ import annotations

import math
import re

import numpy as np

#: Coordinates beyond this magnitude are refused: they are never a real drawing and they
#: overflow float32 geometry.
MAX_ABS = 1e6

_NUMBER = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"  # ASCII digits: renderers read no others
_NUMBER_RE = re.compile(_NUMBER)
_LENGTH_RE = re.compile(rf"^\s*({_NUMBER})\s*(px)?\s*$")
_SEPARATOR_RE = re.compile(r"^[\s,]*$")
_TRANSFORM_RE = re.compile(r"\s*(matrix|translate|scale|rotate|skewX|skewY)\s*\(([^)]*)\)\s*,?")


def check_finite(value: float, what: str = "number") -> float:
    """Refuse NaN, infinities and absurd magnitudes."""
    if not math.isfinite(value):
        raise ValueError(f"{what} is not finite ({value})")
    if abs(value) > MAX_ABS:
        raise ValueError(f"{what} {value:g} is beyond +-{MAX_ABS:g}")
    return value


def parse_number(text: str) -> float:
    """One SVG number (``NaN``/``inf`` spellings are refused, not parsed)."""
    s = text.strip()
    if not re.fullmatch(_NUMBER, s):
        raise ValueError(f"not a number: {text!r}")
    return check_finite(float(s))


def parse_length(text: str) -> float:
    """A user-unit length, with an optional ``px`` unit; other units are unsupported."""
    m = _LENGTH_RE.match(text)
    if not m:
        raise ValueError(f"unsupported length {text!r} (use plain numbers or px)")
    return check_finite(float(m.group(1)))


def parse_numbers(text: str) -> list[float]:
    """A comma/whitespace separated list of numbers, refusing anything else in between."""
    out: list[float] = []
    pos = 0
    for m in _NUMBER_RE.finditer(text):
        if not _SEPARATOR_RE.match(text[pos : m.start()]):
            raise ValueError(f"unexpected {text[pos : m.start()].strip()!r} in number list")
        out.append(check_finite(float(m.group(0))))
        pos = m.end()
    if not _SEPARATOR_RE.match(text[pos:]):
        raise ValueError(f"unexpected {text[pos:].strip()!r} in number list")
    return out


def parse_points(text: str) -> np.ndarray:
    """A ``points`` attribute as an ``(n, 2)`` array."""
    nums = parse_numbers(text)
    if len(nums) % 2:
        raise ValueError(f"points has an odd number of coordinates ({len(nums)})")
    if len(nums) < 4:
        raise ValueError("points needs at least two points")
    return np.asarray(nums, dtype=np.float64).reshape(-1, 2)


def parse_transform(text: str) -> np.ndarray:
    """A transform list as a 3x3 matrix (applied right to left, as SVG specifies)."""
    out = np.eye(3)
    pos = 0
    text = text.strip()
    while pos < len(text):
        m = _TRANSFORM_RE.match(text, pos)
        if not m:
            raise ValueError(f"cannot read transform at {text[pos : pos + 20]!r}")
        name, args = m.group(1), parse_numbers(m.group(2))
        out = out @ _transform_matrix(name, args)
        pos = m.end()
    return out


def _transform_matrix(name: str, a: list[float]) -> np.ndarray:
    def need(*counts: int) -> None:
        if len(a) not in counts:
            raise ValueError(f"{name}() takes {' or '.join(map(str, counts))} numbers, got {len(a)}")

    m = np.eye(3)
    if name == "matrix":
        need(6)
        m[:2] = [[a[0], a[2], a[4]], [a[1], a[3], a[5]]]
    elif name == "translate":
        need(1, 2)
        m[0, 2], m[1, 2] = a[0], (a[1] if len(a) > 1 else 0.0)
    elif name == "scale":
        need(1, 2)
        m[0, 0], m[1, 1] = a[0], (a[1] if len(a) > 1 else a[0])
    elif name == "rotate":
        need(1, 3)
        t = math.radians(a[0])
        r = np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])
        if len(a) == 3:
            pre, post = np.eye(3), np.eye(3)
            pre[:2, 2], post[:2, 2] = (a[1], a[2]), (-a[1], -a[2])
            r = pre @ r @ post
        m = r
    elif name == "skewX":
        need(1)
        m[0, 1] = math.tan(math.radians(a[0]))
    elif name == "skewY":
        need(1)
        m[1, 0] = math.tan(math.radians(a[0]))
    if abs(np.linalg.det(m[:2, :2])) < 1e-12:
        raise ValueError(f"{name}() is degenerate (it collapses the drawing)")
    return m


def format_number(x: float) -> str:
    """Compact, round-trippable enough number text for writing SVG (4 decimals)."""
    s = f"{x:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def format_matrix(m: np.ndarray) -> str:
    """A 3x3 affine as ``matrix(a b c d e f)``."""
    vals = [m[0, 0], m[1, 0], m[0, 1], m[1, 1], m[0, 2], m[1, 2]]
    return "matrix(" + " ".join(format_number(v) for v in vals) + ")"
