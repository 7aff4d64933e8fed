"""Payloads: the bits a user hides, and every form a user may hand them in or want them out.

A :class:`Payload` is a fixed number of bits, most significant first. It is made from an
``int``, text (hex ``"0xA1B2C3"``, a decimal number ``"0d10597059"``, or binary digits),
``bytes`` (big-endian, the value right-aligned in the payload), or a sequence of 0/1 (a list
or an array), and it gives each of those back. Anything that does not fit the payload's size, or is not one of those
types, is one clear :class:`~deepmorph_core.errors.DeepMorphError`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Union

import numpy as np

from deepmorph_core.errors import DeepMorphError

MAX_PAYLOAD_BITS = 256

#: What :meth:`Payload.of` accepts.
PayloadLike = Union["Payload", int, str, bytes, Sequence[int], np.ndarray]
#: How a payload is written as text (:func:`parse_payload_text`): hex digits, a decimal number,
#: or binary digits.
TextForm = Literal["hex", "number", "bits"]
TEXT_FORMS: tuple[TextForm, ...] = ("hex", "number", "bits")


def check_payload_bits(payload_bits: int) -> None:
    """Refuse a payload size outside 1..:data:`MAX_PAYLOAD_BITS`."""
    if not 1 <= payload_bits <= MAX_PAYLOAD_BITS:
        raise DeepMorphError(f"payload_bits must be between 1 and {MAX_PAYLOAD_BITS}, got {payload_bits}")


def hex_digits(payload_bits: int) -> int:
    """Hex digits that write a payload of ``payload_bits`` bits."""
    return math.ceil(payload_bits / 4)


def int_to_bits(value: int, n: int) -> np.ndarray:
    """``(n,)`` uint8 bits of ``value``, most significant first."""
    return np.array([(value >> (n - 1 - i)) & 1 for i in range(n)], dtype=np.uint8)


def as_bits(bits: Any, n: int | None, what: str) -> np.ndarray:
    """``bits`` as a ``(n,)`` uint8 array of 0/1 (any length when ``n`` is None).

    Raises:
        DeepMorphError: another shape, or values other than 0 and 1 (no silent casts).
    """
    arr = np.asarray(bits)
    if arr.ndim != 1 or (n is not None and arr.shape[0] != n):
        want = f"({n},)" if n is not None else "(n,)"
        raise DeepMorphError(f"{what} must have shape {want}, got {tuple(arr.shape)}")
    if arr.size and not np.isin(arr, (0, 1)).all():
        raise DeepMorphError(f"{what} must hold only 0 and 1")
    return arr.astype(np.uint8)


@dataclass(frozen=True, eq=False)
class Payload:
    """A payload of ``len(payload)`` bits, most significant first.

    Attributes:
        bits: ``(n,)`` read-only uint8 array of 0/1.
    """

    bits: np.ndarray

    def __post_init__(self) -> None:
        bits = as_bits(self.bits, None, "payload")
        bits.setflags(write=False)
        object.__setattr__(self, "bits", bits)

    @classmethod
    def of(cls, value: PayloadLike, payload_bits: int) -> Payload:
        """A payload of exactly ``payload_bits`` bits from any accepted form.

        * ``int``: the value, ``0 <= value < 2**payload_bits``;
        * ``str``: hex with the ``0x`` prefix and ``ceil(payload_bits / 4)`` digits, a decimal
          number with the ``0d`` prefix, or exactly ``payload_bits`` binary digits
          (:func:`parse_payload_text`);
        * ``bytes``: a big-endian value of exactly ``ceil(payload_bits / 8)`` bytes that fits
          (what :attr:`bytes` gives back);
        * a sequence or array of ``payload_bits`` zeros and ones.

        Raises:
            DeepMorphError: a value of another type, or one that does not fit, saying what was
                expected.
        """
        check_payload_bits(payload_bits)
        if isinstance(value, Payload):
            if len(value) != payload_bits:
                raise DeepMorphError(f"the payload has {len(value)} bits; this model carries {payload_bits}")
            return value
        if isinstance(value, (bool, np.bool_)):
            raise DeepMorphError(f"a payload is not a bool; {_expected(payload_bits)}")
        if isinstance(value, (int, np.integer)):
            return cls(_int_bits(int(value), payload_bits, repr(int(value))))
        if isinstance(value, str):
            return cls(parse_payload_text(value, payload_bits))
        if isinstance(value, (bytes, bytearray)):
            if len(value) != math.ceil(payload_bits / 8):
                raise DeepMorphError(f"payload of {len(value)} bytes; {_expected(payload_bits)}")
            return cls(_int_bits(int.from_bytes(bytes(value), "big"), payload_bits, f"bytes {bytes(value)!r}"))
        if isinstance(value, (np.ndarray, list, tuple)):
            try:
                return cls(as_bits(value, payload_bits, "payload bits"))
            except DeepMorphError as exc:
                raise DeepMorphError(f"{exc}; {_expected(payload_bits)}") from None
        what = "None" if value is None else f"a {type(value).__name__}"
        raise DeepMorphError(f"a payload cannot be {what}; {_expected(payload_bits)}")

    @classmethod
    def parse(cls, text: str, payload_bits: int, form: TextForm | None = None) -> Payload:
        """A payload from text, written as ``form`` says or, with none, as its prefix says
        (:func:`parse_payload_text`)."""
        return cls(parse_payload_text(text, payload_bits, form))

    def __len__(self) -> int:
        return int(self.bits.shape[0])

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Payload) and np.array_equal(self.bits, other.bits)

    def __hash__(self) -> int:
        return hash(self.bits.tobytes())

    @property
    def int(self) -> int:
        """The payload's value."""
        return int(self.binary, 2) if len(self) else 0

    @property
    def hex(self) -> str:
        """``0x`` and ``ceil(n / 4)`` upper-case hex digits."""
        return f"0x{self.int:0{hex_digits(len(self))}X}"

    @property
    def binary(self) -> str:
        """The bits as a string of ``0`` and ``1``."""
        return "".join("1" if b else "0" for b in self.bits)

    @property
    def bytes(self) -> bytes:
        """The value as ``ceil(n / 8)`` big-endian bytes."""
        return self.int.to_bytes(math.ceil(len(self) / 8), "big")

    def to_json(self) -> dict[str, str]:
        """``{"hex": "0x..", "bits": ".."}``."""
        return {"hex": self.hex, "bits": self.binary}

    def __repr__(self) -> str:
        return f"Payload({self.hex}, {len(self)} bits)"


def _expected(payload_bits: int) -> str:
    digits = hex_digits(payload_bits)
    example = "0x" + "A1B2C3D4E5F6"[:digits].ljust(digits, "0")
    return (
        f"expected a {payload_bits}-bit payload: an int below 2**{payload_bits}, hex with {digits} digits like "
        f"{example}, a number like 0d{_example_value(payload_bits)}, {payload_bits} binary digits, "
        f"{math.ceil(payload_bits / 8)} bytes, or {payload_bits} bits"
    )


def _example_value(payload_bits: int) -> int:
    """A decimal example that fits ``payload_bits`` bits: the hex example's value."""
    digits = hex_digits(payload_bits)
    return int("A1B2C3D4E5F6"[:digits].ljust(digits, "0"), 16) & ((1 << payload_bits) - 1)


def _int_bits(value: int, payload_bits: int, shown: str) -> np.ndarray:
    if value < 0 or value >> payload_bits:
        digits = hex_digits(payload_bits)
        raise DeepMorphError(
            f"payload {shown} does not fit in {payload_bits} bits (0 to 0x{(1 << payload_bits) - 1:0{digits}X}); "
            f"{_expected(payload_bits)}"
        )
    return int_to_bits(value, payload_bits)


def parse_payload_text(text: str, payload_bits: int, form: TextForm | None = None) -> np.ndarray:
    """Read a payload written as text: hex, a decimal number, or binary digits.

    With no ``form`` the text says which, as ``deepmorph encode --payload`` takes it: ``0x`` and
    exactly ``ceil(payload_bits / 4)`` hex digits (``0xA1B2C3``), ``0d`` and a decimal number
    (``0d10597059``), or exactly ``payload_bits`` binary digits. A ``form`` says what the text is
    instead, for a field whose kind the user chose: ``"hex"`` (the ``0x`` may be left out),
    ``"number"`` (the ``0d`` may be left out) or ``"bits"``. The value must fit in
    ``payload_bits`` bits. Bits are most significant first: with 24 bits ``0xA1B2C3`` is
    ``0d10597059`` and ``101000011011001011000011``.

    Returns:
        ``(payload_bits,)`` uint8 array of 0/1.

    Raises:
        DeepMorphError: anything else, saying what was expected (a number too large for the
            payload says the largest there is).
    """
    check_payload_bits(payload_bits)
    if form is not None and form not in TEXT_FORMS:
        raise DeepMorphError(f"a payload is written as {', '.join(TEXT_FORMS)}, not {form!r}")
    digits = hex_digits(payload_bits)
    example = "0x" + "A1B2C3D4E5F6"[:digits].ljust(digits, "0")
    largest = (1 << payload_bits) - 1
    expected = {
        None: f"expected a {payload_bits}-bit payload: hex with {digits} digits like {example}, a number like "
        f"0d{_example_value(payload_bits)}, or {payload_bits} binary digits",
        "hex": f"expected {digits} hex digits like {example} (a {payload_bits}-bit payload)",
        "number": f"expected a whole number from 0 to {largest} (a {payload_bits}-bit payload)",
        "bits": f"expected {payload_bits} binary digits (a {payload_bits}-bit payload)",
    }[form]
    if not isinstance(text, str):
        raise DeepMorphError(f"payload must be text, got {type(text).__name__}; {expected}")
    s = text.strip()
    if not s:
        raise DeepMorphError(f"empty payload; {expected}")
    prefix = s[:2].lower()
    if form == "hex" or (form is None and prefix == "0x"):
        return _hex_bits(s, s[2:] if prefix == "0x" else s, payload_bits, expected)
    if form == "number" or (form is None and prefix == "0d"):
        return _number_bits(s, s[2:] if prefix == "0d" else s, payload_bits, expected)
    if form == "bits" or set(s) <= {"0", "1"}:
        if not set(s) <= {"0", "1"}:
            raise DeepMorphError(f"payload {s[:40]!r} holds digits other than 0 and 1; {expected}")
        if len(s) != payload_bits:
            raise DeepMorphError(f"payload has {len(s)} binary digits; {expected}")
        return np.frombuffer(s.encode(), dtype=np.uint8) - ord("0")
    raise DeepMorphError(
        f"payload {s[:40]!r} is neither 0x-prefixed hex, a 0d-prefixed number nor binary digits; {expected}"
    )


def _hex_bits(shown: str, body: str, payload_bits: int, expected: str) -> np.ndarray:
    digits = hex_digits(payload_bits)
    bad = [c for c in body if c not in "0123456789abcdefABCDEF"]
    if bad:
        raise DeepMorphError(f"payload {shown!r}: {bad[0]!r} is not a hex digit; {expected}")
    if len(body) != digits:
        raise DeepMorphError(f"payload {shown!r} has {len(body)} hex digits; {expected}")
    value = int(body, 16)
    if value >> payload_bits:
        raise DeepMorphError(
            f"payload {shown!r} needs {value.bit_length()} bits, more than {payload_bits}; {expected} "
            f"(at most 0x{(1 << payload_bits) - 1:0{digits}X})"
        )
    return int_to_bits(value, payload_bits)


def _number_bits(shown: str, body: str, payload_bits: int, expected: str) -> np.ndarray:
    largest = (1 << payload_bits) - 1
    bad = [c for c in body if c not in "0123456789"]
    if bad or not body:
        what = f"{bad[0]!r} is not a decimal digit" if bad else "no digits"
        raise DeepMorphError(f"payload {shown[:40]!r}: {what}; {expected}")
    # compared as text first: no huge int is ever made from a long string
    if len(body.lstrip("0")) > len(str(largest)) or int(body) > largest:
        raise DeepMorphError(
            f"payload {shown[:40]!r} is too large for {payload_bits} bits: the largest is {largest} "
            f"(0x{largest:0{hex_digits(payload_bits)}X})"
        )
    return int_to_bits(int(body), payload_bits)


def format_payload(bits: np.ndarray) -> dict[str, str]:
    """``{"hex": "0x..", "bits": ".."}`` for payload bits (most significant bit first)."""
    return Payload(bits).to_json()


def random_payloads(n: int, payload_bits: int, generator: np.random.Generator) -> np.ndarray:
    """``(n, payload_bits)`` uniformly random uint8 payloads, drawn from ``generator``."""
    check_payload_bits(payload_bits)
    return generator.integers(0, 2, size=(n, payload_bits), dtype=np.uint8)


__all__ = [
    "MAX_PAYLOAD_BITS",
    "TEXT_FORMS",
    "Payload",
    "PayloadLike",
    "TextForm",
    "format_payload",
    "parse_payload_text",
    "random_payloads",
]
