"""Payload codec: payload bits -> CRC -> shortened BCH code -> whitened code bits, and back.

The decoder network outputs one probability per *code bit*. This module turns a payload into
those ``N_b`` code bits and turns the network's probabilities back into a payload, correcting
up to ``t`` wrong bits with BCH (hard decisions) and more with a Chase-II search over the least
reliable bits (soft decisions), and saying whether the CRC vouches for the result.

Code word layout (most significant bit first everywhere)::

    info  = payload bits (P) | CRC of the payload (C)           K = P + C bits
    data  = info + zero bits up to a byte boundary              (padding is never sent)
    ecc   = bchlib.BCH(t, m).encode(data), first ecc_bits bits  (its byte padding is never sent)
    code  = (info | ecc) XOR whitening mask                     N_b = P + C + ecc_bits

The whitening mask is a fixed pseudo-random bit string (SHA-256 of a constant; per spec, the
first variant under which no constant output decodes as valid), so that a blank or unrelated
picture read as all zeros or all ones is not a code word and the bits the encoder network must
embed are balanced. See ``docs/codec.md``.

An unchecked payload is never presented as valid: ``DecodeResult.ok`` is True only when a CRC
was checked and matches, so with ``crc_bits=0`` it is always False.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import math
from dataclasses import dataclass
from functools import cache
from typing import Any, Literal

import bchlib
import crc
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.payload import MAX_PAYLOAD_BITS, as_bits, format_payload, int_to_bits

MAX_BCH_T = 16
BCH_M_RANGE = (5, 15)
#: The CRC of each width a code may have (normal form, the top bit implied): CRC-8/CCITT and
#: CRC-16/XMODEM, and between them the RevEng catalogue's CRC-10/ATM, -11/FLEXRAY, -12/DECT,
#: -13/BBC, -14/DARC and -15/CAN polynomials. All start at zero with no final XOR and no
#: reflection, so the differences between code words stay one linear code
#: (:meth:`PayloadCodec.rival_margin`). The widths between 8 and 16 let the trust check
#: (``deepmorph.training.trust``) lengthen a drawing's CRC by what its photos need, bit by bit.
CRC_POLYNOMIALS = {8: 0x07, 10: 0x233, 11: 0x385, 12: 0x80F, 13: 0x1CF5, 14: 0x805, 15: 0x4599, 16: 0x1021}
#: Every CRC width a :class:`CodecSpec` may have (0: none).
CRC_WIDTHS: tuple[int, ...] = (0, *CRC_POLYNOMIALS)
#: The shortest CRC a colour drawing's payload gets where the CRC is DeepMorph's to choose
#: (:func:`default_crc_bits`, :func:`deepmorph_core.capacity.plan_code`). Counted over the whole
#: photo chain (``bench/trust.py``), six colour drawings trained for prints 200 px wide gave
#: 0.16-10 wrong payloads per 10,000 hard close-ups with CRC-8, all above the aim of 0.1
#: (:data:`deepmorph.training.trust.TRUST_TARGET`); the CRCs that meet it were 10-15 bits on the
#: five whose payload had the bits to give (median 12). Training counts each colour model's own
#: and lengthens an ``auto`` payload's CRC further where that needs it.
COLOUR_CRC = 12
CrcWidth = Literal[0, 8, 10, 11, 12, 13, 14, 15, 16]
_WHITENING_SEED = b"deepmorph payload codec whitening/1"
_PROB_EPS = 1e-9
#: a payload of at most this many bits has every difference between two of its code words listed
#: (:meth:`PayloadCodec.rival_margin`: 2**16 rows); a longer one's are searched near the least
#: supported bits, :data:`RIVAL_SEARCH_BITS` of them (2**10 - 1 flips)
LISTED_RIVALS_UP_TO = 16
RIVAL_SEARCH_BITS = 10
#: ... by syndromes (0.2-0.4 ms) for BCH codes that correct up to this many bits (a table of every
#: correction: 1.8k rows for 60 code bits at t = 2), else by BCH decoding each flip (4-15 ms)
MAX_SYNDROME_T = 2


@cache
def _bch_ecc_bits(t: int, m: int) -> int | None:
    """ECC bits of the BCH code (t, m), or None where the Linux BCH library has no such code."""
    try:
        return int(bchlib.BCH(t, m=m).ecc_bits)
    except (RuntimeError, ValueError):
        return None


def _bch_data_capacity(t: int, m: int) -> int:
    """Most data bits a (byte-aligned) shortened BCH(t, m) code word can carry; 0 if none."""
    ecc = _bch_ecc_bits(t, m)
    if ecc is None:
        return 0
    return max(0, ((2**m - 1 - ecc) // 8) * 8)


def _data_bits(payload_bits: int, crc_bits: int) -> int:
    """Payload + CRC bits padded to whole bytes: what the BCH encoder sees."""
    return 8 * math.ceil((payload_bits + crc_bits) / 8)


class CodecSpec(BaseModel):
    """How payload bits become code bits (frozen; stored in model bundles).

    Attributes:
        payload_bits: bits the user hides, 1..256.
        crc_bits: CRC width (0, 8, 10-16: :data:`CRC_WIDTHS`). Without a CRC nothing can vouch for
            a decoded payload, so :attr:`DecodeResult.ok` is always False.
        bch_t: bit errors the BCH code corrects (0 = no error correction), at most 16.
        bch_m: Galois field order 5..15 of the BCH code; None picks the smallest that fits.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    payload_bits: int = Field(ge=1, le=MAX_PAYLOAD_BITS)
    crc_bits: CrcWidth = 8
    bch_t: int = Field(default=2, ge=0, le=MAX_BCH_T)
    bch_m: int | None = Field(default=None, ge=BCH_M_RANGE[0], le=BCH_M_RANGE[1])

    @model_validator(mode="after")
    def _fits(self) -> CodecSpec:
        if self.bch_t == 0:
            if self.bch_m is not None:
                raise ValueError(f"bch_m={self.bch_m} has no effect without error correction (bch_t=0); leave it unset")
            return self
        need = _data_bits(self.payload_bits, self.crc_bits)
        smallest = _smallest_m(self.bch_t, need)
        if smallest is None:
            raise ValueError(
                f"no BCH code corrects bch_t={self.bch_t} errors in {need} payload+CRC bits "
                f"(Galois field order up to {BCH_M_RANGE[1]}); lower bch_t or payload_bits"
            )
        if self.bch_m is not None and self.bch_m < smallest:
            have = _bch_data_capacity(self.bch_t, self.bch_m)
            raise ValueError(
                f"bch_m={self.bch_m} is too small: with bch_t={self.bch_t} its code words carry {have} data bits, "
                f"but payload+CRC need {need} (byte-padded); use bch_m >= {smallest} or leave bch_m unset"
            )
        if self.bch_m is not None and _bch_ecc_bits(self.bch_t, self.bch_m) is None:  # pragma: no cover
            raise ValueError(f"the BCH library has no code with bch_t={self.bch_t}, bch_m={self.bch_m}")
        return self

    @property
    def field_order(self) -> int | None:
        """The Galois field order ``m`` in use (``bch_m`` or the smallest that fits); None if ``bch_t=0``."""
        if self.bch_t == 0:
            return None
        if self.bch_m is not None:
            return self.bch_m
        return _smallest_m(self.bch_t, _data_bits(self.payload_bits, self.crc_bits))

    @property
    def ecc_bits(self) -> int:
        """Transmitted BCH parity bits (``bchlib``'s ``ecc_bits``; about ``m * t``)."""
        m = self.field_order
        return 0 if m is None else int(_bch_ecc_bits(self.bch_t, m))

    @property
    def code_bits(self) -> int:
        """``N_b``: the bits the network embeds, ``payload_bits + crc_bits + ecc_bits``."""
        return self.payload_bits + self.crc_bits + self.ecc_bits


@cache
def crc_configuration(width: int) -> crc.Configuration:
    """The CRC of ``width`` bits (:data:`CRC_POLYNOMIALS`)."""
    return crc.Configuration(
        width=width,
        polynomial=CRC_POLYNOMIALS[width],
        init_value=0,
        final_xor_value=0,
        reverse_input=False,
        reverse_output=False,
    )


@cache
def _smallest_m(t: int, data_bits: int) -> int | None:
    for m in range(BCH_M_RANGE[0], BCH_M_RANGE[1] + 1):
        if _bch_data_capacity(t, m) >= data_bits:
            return m
    return None


def format_codec_error(exc: ValidationError) -> str:
    """One readable ``field: problem`` line per problem of a :class:`CodecSpec`."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(x) for x in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            known = ", ".join(CodecSpec.model_fields)
            lines.append(f"unknown codec setting {loc!r} (known: {known})")
        else:
            lines.append(f"{loc}: {msg}" if loc else msg)
    return "; ".join(lines)


def default_crc_bits(payload_bits: int, colour: bool = False) -> int:
    """The CRC a payload gets where nobody chose one: 8 bits up to 32 payload bits, 16 above; for a
    ``colour`` drawing at least :data:`COLOUR_CRC` (its photos' wrong words pass the photo chain's
    checks far more often)."""
    width = 8 if payload_bits <= 32 else 16
    return max(width, COLOUR_CRC) if colour else width


def choose_codec(payload_bits: int, crc_bits: int | None = None, bch_t: int | None = None) -> CodecSpec:
    """A codec with sensible defaults for a payload size.

    Defaults: an 8-bit CRC for payloads up to 32 bits, 16 bits above; ``t = 1`` for payloads up to
    8 bits, ``t = 2`` above; the smallest Galois field that fits.

    Raises:
        DeepMorphError: an impossible combination, with one readable line per problem.
    """
    if crc_bits is None:
        crc_bits = default_crc_bits(payload_bits)
    if bch_t is None:
        bch_t = 1 if payload_bits <= 8 else 2
    try:
        return CodecSpec(payload_bits=payload_bits, crc_bits=crc_bits, bch_t=bch_t)
    except ValidationError as exc:
        raise DeepMorphError(f"invalid codec: {format_codec_error(exc)}") from None


def widths_within(spec: CodecSpec) -> list[int]:
    """The CRC widths ``spec``'s code can have, shortest first: its own and the longer ones that
    leave at least one payload bit."""
    return [w for w in CRC_WIDTHS if spec.crc_bits <= w < spec.crc_bits + spec.payload_bits]


def with_crc(spec: CodecSpec, width: int) -> CodecSpec:
    """``spec`` with payload bits given over to a CRC of ``width`` bits: the same code bits, BCH
    data and parity (payload and CRC fill the same bytes)."""
    longer = CodecSpec(
        payload_bits=spec.payload_bits - (width - spec.crc_bits),
        crc_bits=width,
        bch_t=spec.bch_t,
        bch_m=spec.bch_m,
    )
    if longer.code_bits != spec.code_bits:  # pragma: no cover - the layout's invariant
        raise AssertionError(f"a CRC of {width} bits changed the code's size: {spec} -> {longer}")
    return longer


def _mask_bits(n: int, variant: int) -> np.ndarray:
    """``n`` pseudo-random bits: SHA-256(seed || variant || counter) blocks, fixed forever."""
    blocks = math.ceil(n / 256)
    raw = b"".join(
        hashlib.sha256(_WHITENING_SEED + variant.to_bytes(2, "big") + i.to_bytes(4, "big")).digest()
        for i in range(blocks)
    )
    mask = np.unpackbits(np.frombuffer(raw, dtype=np.uint8))[:n].copy()
    mask.setflags(write=False)
    return mask


@cache
def _whitening_mask(spec: CodecSpec) -> np.ndarray:
    """The first mask variant under which no constant output decodes as a valid payload.

    With every probability equal, hard decisions are all 0 or all 1 and every bit is equally
    (un)reliable, so the decoder sees the same thing for every constant below 0.5 (and for every
    one above): probing 0.25 and 0.75 with the widest default soft search covers them all.
    """
    for variant in range(1 << 16):
        mask = _mask_bits(spec.code_bits, variant)
        probe = PayloadCodec._with_mask(spec, mask)
        if not any(probe.decode(np.full(spec.code_bits, v)).ok for v in (0.25, 0.75)):
            return mask
    raise AssertionError("no whitening mask found")  # pragma: no cover - a try fails with p < 1%


@cache
def _flip_patterns(n: int) -> np.ndarray:
    """Every non-empty subset of ``n`` positions as a ``(2**n - 1, n)`` 0/1 matrix, fewest flips first."""
    subsets = [c for r in range(1, n + 1) for c in itertools.combinations(range(n), r)]
    out = np.zeros((len(subsets), n), dtype=np.uint8)
    for row, subset in enumerate(subsets):
        out[row, list(subset)] = 1
    out.setflags(write=False)
    return out


def _beyond_search(searched: np.ndarray, others: np.ndarray, t: int) -> float:
    """The least support a code word can have that differs from another in at least ``t + 1`` of
    the ``others`` bits and in at least ``2 t + 1`` bits in all (BCH's designed distance): over
    how many of the ``searched`` bits it shares, the weakest of them and of the others (and every
    other one of those with negative support, which can only lower the sum). Both arrays are sorted
    ascending. ``inf`` when no such word fits in the bits."""
    best = math.inf
    for shared in range(len(searched) + 1):
        need = max(t + 1, 2 * t + 1 - shared)
        if need > len(others):
            continue
        total = searched[:shared].sum() + others[:need].sum() + np.minimum(others[need:], 0.0).sum()
        best = min(best, float(total))
    return best


# --------------------------------------------------------------------------- decode result


@dataclass(frozen=True, eq=False)
class DecodeResult:
    """What decoding one code word found.

    Attributes:
        payload: ``(payload_bits,)`` uint8 best guess, always present (even when ``ok`` is False).
        ok: True only when the CRC matches after correction; never without a CRC.
        corrected_bits: code bits the decoder changed relative to the hard decisions (BCH
            corrections plus soft flips); -1 when decoding failed.
        confidence: geometric mean of ``max(p, 1 - p)`` over the code bits, in [0.5, 1].
        rival_log_odds: for a word that passed the CRC with corrections, how much the
            probabilities still prefer it to every other code word (:meth:`PayloadCodec.rival_margin`
            with each bit's log-odds as its support): a misread that lands on another word has
            the decoder's doubt on the bits where the two differ. 0 where not computed (a word
            read without corrections, or not read).
    """

    payload: np.ndarray
    ok: bool
    corrected_bits: int
    confidence: float
    rival_log_odds: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return {
            "payload": format_payload(self.payload),
            "ok": bool(self.ok),
            "corrected_bits": int(self.corrected_bits),
            "confidence": float(self.confidence),
        }


# --------------------------------------------------------------------------- the codec


class PayloadCodec:
    """Encode payloads to code bits and decode code-bit probabilities to payloads.

    Args:
        spec: the code.
        soft_bits: ``L``, how many least reliable bits the Chase-II search flips (up to
            ``2**L - 1`` test patterns); 0 disables soft decoding.
        soft_candidates: most distinct code words the soft search may put to the CRC. Each one is
            a ``2**-crc_bits`` chance of accepting garbage, so the false-accept rate of a random
            input is at most ``(1 + soft_candidates) * 2**-crc_bits``. Default: 64 with a 16-bit
            CRC (<= 0.1%), 2 with a shorter one (<= 1.2% with 8 bits).
        reliable_above: bits whose ``max(p, 1 - p)`` reaches this are never flipped by the soft
            search (saturated outputs say nothing about which bits are wrong).

    A codec is not thread-safe (bchlib keeps the last error locations in the object): use one
    per thread.
    """

    def __init__(
        self,
        spec: CodecSpec,
        *,
        soft_bits: int = 6,
        soft_candidates: int | None = None,
        reliable_above: float = 0.95,
    ) -> None:
        self._setup(spec, soft_bits, soft_candidates, reliable_above)
        self._mask = _whitening_mask(spec)

    @classmethod
    def _with_mask(cls, spec: CodecSpec, mask: np.ndarray) -> PayloadCodec:
        """A codec with the widest default soft search and a given whitening mask (to pick masks)."""
        codec = cls.__new__(cls)
        codec._setup(spec, soft_bits=6, soft_candidates=64, reliable_above=0.95)
        codec._mask = mask
        return codec

    def _setup(self, spec: CodecSpec, soft_bits: int, soft_candidates: int | None, reliable_above: float) -> None:
        if not 0 <= soft_bits <= 12:
            raise DeepMorphError(f"soft_bits must be between 0 and 12, got {soft_bits}")
        if soft_candidates is not None and soft_candidates < 0:
            raise DeepMorphError(f"soft_candidates must be 0 or more, got {soft_candidates}")
        if not 0.5 < reliable_above <= 1.0:
            raise DeepMorphError(f"reliable_above must lie in (0.5, 1], got {reliable_above}")
        self.spec = spec
        self.soft_bits = soft_bits
        if soft_candidates is None:
            soft_candidates = {0: 2**soft_bits, 16: 64}.get(spec.crc_bits, 2)
        self.soft_candidates = soft_candidates
        self.reliable_above = reliable_above
        self._k = spec.payload_bits + spec.crc_bits
        self._bch = bchlib.BCH(spec.bch_t, m=spec.field_order) if spec.bch_t else None
        self._crc = crc.Calculator(crc_configuration(spec.crc_bits), optimized=True) if spec.crc_bits else None
        self._crc_checked = spec.crc_bits  # the CRC bits a word must match (:meth:`narrowed`)
        self._collided: dict[bytes, np.ndarray] | None = None  # a narrowed copy's collisions
        self._differences: np.ndarray | None = None
        self._columns: np.ndarray | None = None
        self._zero_word: np.ndarray | None = None
        self._correction_table: tuple[np.ndarray, np.ndarray] | None = None

    def __repr__(self) -> str:
        return f"PayloadCodec({self.spec!r})"

    # -- pieces

    def _crc_bits_of(self, payload: np.ndarray) -> np.ndarray:
        """CRC of the payload's value as big-endian bytes (left-padded with zeros); in a
        :meth:`narrowed` copy, the CRC bits a collision gave it, where one did."""
        if self._collided:
            collided = self._collided.get(np.asarray(payload, np.uint8).tobytes())
            if collided is not None:
                return collided.copy()
        pad = (-payload.shape[0]) % 8
        data = np.packbits(np.concatenate([np.zeros(pad, np.uint8), payload])).tobytes()
        return int_to_bits(self._crc.checksum(data), self.spec.crc_bits)

    def _crc_ok(self, word: np.ndarray) -> bool:
        p = self.spec.payload_bits
        return bool(np.array_equal(self._crc_bits_of(word[:p]), word[p : self._k]))

    def _accepts(self, word: np.ndarray) -> bool:
        """Whether decoding accepts ``word``: its CRC matches. A :meth:`narrowed` copy also accepts
        a word whose CRC bits match on the bits it checks, and takes them as its payload's CRC."""
        p, checked = self.spec.payload_bits, self._crc_checked
        own, read = self._crc_bits_of(word[:p]), word[p : self._k]
        if np.array_equal(own, read):
            return True
        if self._collided is None:
            return False
        key = np.asarray(word[:p], np.uint8).tobytes()
        if key in self._collided or not np.array_equal(own[:checked], read[:checked]):
            return False
        self._collided[key] = np.array(read, dtype=np.uint8)
        return True

    def narrowed(self, checked: int) -> PayloadCodec:
        """A copy of this codec whose decoding checks only the first ``checked`` of the CRC's bits,
        to measure how often wrong code words get through the rest of a reading
        (``deepmorph.training.trust``), never to read. A wrong word, whose CRC bits are as good as
        random, then passes ``2**(crc_bits - checked)`` times as often; a right one still passes.

        A word accepted on fewer than all its CRC bits has *collided*: until :meth:`forget`, the
        CRC bits it was read with are its payload's CRC, so the rest of the reading (the payload
        check encodes the payload again) judges the very code word the correction reached, as
        it would a real collision, not the payload's own code word, which differs from what was
        read in about half its CRC and parity bits.

        Raises:
            DeepMorphError: ``checked`` outside ``0..crc_bits``.
        """
        if not 0 <= checked <= self.spec.crc_bits:
            raise DeepMorphError(f"a CRC of {self.spec.crc_bits} bits cannot be checked on {checked} of them")
        narrow = copy.copy(self)
        narrow._crc_checked = checked
        narrow._collided = {}
        return narrow

    def forget(self) -> None:
        """Forget the collisions a :meth:`narrowed` copy took (before another photo)."""
        if self._collided is not None:
            self._collided.clear()

    def _ecc(self, info: np.ndarray) -> np.ndarray:
        ecc = self._bch.encode(np.packbits(info).tobytes())
        return np.unpackbits(np.frombuffer(ecc, dtype=np.uint8))[: self.spec.ecc_bits]

    def _bch_correct(self, words: np.ndarray) -> list[np.ndarray | None]:
        """Hard BCH decoding of (unwhitened) words: for each, the code word within ``t`` bit flips,
        or None where there is none.

        Shape:
            ``words``: ``(T, code_bits)``; one ``(code_bits,)`` array or None per row.
        """
        if self._bch is None:
            return list(words)
        k = self._k
        data_rows = np.packbits(words[:, :k], axis=1)  # zero padding to whole bytes, as sent to encode
        ecc_rows = np.packbits(words[:, k:], axis=1)
        data_len = 8 * data_rows.shape[1]
        out: list[np.ndarray | None] = []
        for word, data_row, ecc_row in zip(words, data_rows, ecc_rows):
            nerr = self._bch.decode(data_row.tobytes(), ecc_row.tobytes())
            if nerr <= 0:
                out.append(word if nerr == 0 else None)
                continue
            where = [self._errloc_to_index(loc, data_len) for loc in self._bch.errloc]
            if None in where:
                out.append(None)  # a "correction" of padding known to be zero: more than t errors
                continue
            fixed = word.copy()
            fixed[where] ^= 1
            out.append(fixed)
        return out

    def _errloc_to_index(self, loc: int, data_len: int) -> int | None:
        """Index in our word of a bchlib error location, or None if it falls in the padding.

        bchlib counts bits through the data bytes and then the ecc bytes, least significant bit of
        each byte first; our words are most significant bit first and skip both paddings.
        """
        k, ecc_bits = self._k, self.spec.ecc_bits
        if loc < data_len:
            index = (loc & ~7) + 7 - (loc & 7)
            return index if index < k else None
        loc -= data_len
        index = (loc & ~7) + 7 - (loc & 7)
        return k + index if index < ecc_bits else None

    # -- public

    def encode(self, payload: np.ndarray) -> np.ndarray:
        """Code bits for a payload.

        Shape:
            ``(payload_bits,)`` -> ``(code_bits,)``, or ``(B, payload_bits)`` -> ``(B, code_bits)``.
            Values 0/1; the result is uint8.
        """
        arr = np.asarray(payload)
        if arr.ndim == 2:
            if arr.shape[1] != self.spec.payload_bits:
                raise DeepMorphError(f"payloads must have shape (B, {self.spec.payload_bits}), got {tuple(arr.shape)}")
            words = np.zeros((len(arr), self.spec.code_bits), np.uint8)
            for row, payload_row in enumerate(arr):
                words[row] = self.encode(payload_row)
            return words
        bits = as_bits(arr, self.spec.payload_bits, "payload")
        info = np.concatenate([bits, self._crc_bits_of(bits)]) if self._crc else bits
        word = np.concatenate([info, self._ecc(info)]) if self._bch else info
        return word ^ self._mask

    def decode(self, probs: np.ndarray, soft: bool = True) -> DecodeResult:
        """Payload from the decoder network's probabilities.

        Args:
            probs: ``(code_bits,)`` values in [0, 1], each P(code bit = 1).
            soft: when hard decoding fails, search flips of the least reliable bits (Chase-II).
        """
        q = self._probabilities(probs)
        conf = float(np.exp(np.mean(np.log(np.maximum(q, 1.0 - q)))))
        # Hard decisions on the sent bits, then undo the whitening (so p = 0.5 everywhere is not
        # read as the all-zero code word).
        hard = (q > 0.5).astype(np.uint8) ^ self._mask
        cost = np.abs(np.log(q + _PROB_EPS) - np.log(1.0 - q + _PROB_EPS))  # |LLR| of each bit
        p, checked = self.spec.payload_bits, self._crc is not None

        word = self._bch_correct(hard[None])[0]
        if word is None or (checked and not self._accepts(word)):
            word = self._chase(hard, cost, first=word) if soft else None
        if word is None:
            return self._result(hard[:p], ok=False, flips=-1, conf=conf)
        flips = int(np.count_nonzero(word != hard))
        margin = self.rival_log_odds((word ^ self._mask).astype(np.uint8), q) if checked and flips else 0.0
        return self._result(word[:p], ok=checked, flips=flips, conf=conf, margin=margin)

    def decode_batch(self, probs: np.ndarray, soft: bool = True) -> list[DecodeResult]:
        """:meth:`decode` for each row of a ``(B, code_bits)`` array."""
        arr = np.asarray(probs, dtype=np.float64)
        if arr.ndim != 2:
            raise DeepMorphError(f"probabilities must have shape (B, {self.spec.code_bits}), got {tuple(arr.shape)}")
        return [self.decode(row, soft=soft) for row in arr]

    def rival_log_odds(self, code_bits: np.ndarray, probs: np.ndarray) -> float:
        """How much the decoder's probabilities ``probs`` (``(code_bits,)``, each P(bit = 1))
        prefer the code word ``code_bits`` to every other code word: :meth:`rival_margin` with
        each bit's log-odds, signed towards the word, as its support
        (:attr:`DecodeResult.rival_log_odds` of a word read with corrections)."""
        code = np.asarray(code_bits, dtype=np.uint8)
        return self.rival_margin(code, self._decoder_support(code, probs))

    def runner_up(self, code_bits: np.ndarray, probs: np.ndarray) -> np.ndarray | None:
        """The code word the decoder's probabilities ``probs`` prefer next to the code word
        ``code_bits``: :meth:`nearest_rival` with each bit's log-odds, signed towards the word, as
        its support (the rival :meth:`rival_log_odds` measures); ``None`` where it finds none."""
        code = np.asarray(code_bits, dtype=np.uint8)
        return self.nearest_rival(code, self._decoder_support(code, probs))

    def _decoder_support(self, code: np.ndarray, probs: np.ndarray) -> np.ndarray:
        """Each bit's log-odds under the decoder's ``probs``, signed towards the code word ``code``."""
        q = self._probabilities(probs)
        log_odds = np.log(q + _PROB_EPS) - np.log(1.0 - q + _PROB_EPS)
        return np.where(code == 1, log_odds, -log_odds)

    def rival_margin(self, code_bits: np.ndarray, support: np.ndarray) -> float:
        """How much per-bit ``support`` prefers the code word ``code_bits`` to every other code
        word: the least total support over the bits where another code word differs from it.

        ``support`` is ``(code_bits,)``, about +1 where a photo shows the word's bit and -1 where it
        shows the flipped one (:class:`~deepmorph_detect.synthesis.BitEvidence`). A photo of
        another word shows the whole set of bits where the two differ flipped, never just a few:
        a word with some bits shown flipped is still the likeliest one when every set a rival
        needs adds up to more support than doubt.

        The differences between code words are the words of one linear code (the CRCs start at
        zero, BCH is linear, whitening cancels), the same for every word. A payload of at most
        :data:`LISTED_RIVALS_UP_TO` bits has them listed, and the margin is exact. Above that it is
        a lower bound: the rivals that differ in at most ``t`` bits beyond the
        :data:`RIVAL_SEARCH_BITS` least supported ones are found by taking every flip of those
        bits to the code word within ``t`` bits of it (Chase-II; by syndromes up to
        :data:`MAX_SYNDROME_T`); any other one differs in at least ``t + 1`` better supported bits.
        ``inf`` for a code with one word.
        """
        return self._rivals(code_bits, support)[0]

    def nearest_rival(self, code_bits: np.ndarray, support: np.ndarray) -> np.ndarray | None:
        """The code word other than ``code_bits`` that per-bit ``support`` prefers least to it
        (:meth:`rival_margin`'s nearest rival), ``(code_bits,)`` uint8; ``None`` for a code with
        one word, or, above :data:`LISTED_RIVALS_UP_TO` payload bits, when the search near the
        least supported bits finds none (every rival then differs in better supported bits)."""
        return self._rivals(code_bits, support)[1]

    def _rivals(self, code_bits: np.ndarray, support: np.ndarray) -> tuple[float, np.ndarray | None]:
        """:meth:`rival_margin` and :meth:`nearest_rival` together."""
        code = np.asarray(code_bits, dtype=np.uint8)
        shown = np.asarray(support, dtype=np.float64)
        if shown.shape != (self.spec.code_bits,) or code.shape != shown.shape:
            raise DeepMorphError(f"a code word and its support must have shape ({self.spec.code_bits},)")
        if self.spec.payload_bits <= LISTED_RIVALS_UP_TO:
            differences = self._code_differences()
            if not len(differences):
                return math.inf, None
            sums = differences @ shown
            nearest = int(np.argmin(sums))
            return float(sums[nearest]), code ^ differences[nearest].astype(np.uint8)
        order = np.argsort(shown, kind="stable")
        searched, others = order[:RIVAL_SEARCH_BITS], np.sort(shown[order[RIVAL_SEARCH_BITS:]])
        margin = _beyond_search(np.sort(shown[searched]), others, self.spec.bch_t)
        if self.spec.bch_t <= MAX_SYNDROME_T and self._is_code_word(code):
            found = self._nearest_by_syndrome(code, shown, searched)
        else:
            found = self._nearest_by_bch(code, shown, searched)
        if found is None:
            return margin, None
        return min(margin, found[0]), found[1]

    def _nearest_by_bch(
        self, code: np.ndarray, shown: np.ndarray, searched: np.ndarray
    ) -> tuple[float, np.ndarray] | None:
        """The least supported code word that BCH decoding finds within ``t`` bits of a flip of the
        ``searched`` bits of ``code``, and its support; ``None`` where there is none."""
        plain = code ^ self._mask
        found: tuple[float, np.ndarray] | None = None
        trials = np.repeat(plain[None], 2 ** len(searched) - 1, axis=0)
        trials[:, searched] ^= _flip_patterns(len(searched))
        for word in self._bch_correct(trials):
            if word is None or np.array_equal(word, plain) or (self._crc is not None and not self._crc_ok(word)):
                continue
            total = float(shown[word != plain].sum())
            if found is None or total < found[0]:
                found = (total, word)
        return None if found is None else (found[0], (found[1] ^ self._mask).astype(np.uint8))

    def _nearest_by_syndrome(
        self, code: np.ndarray, shown: np.ndarray, searched: np.ndarray
    ) -> tuple[float, np.ndarray] | None:
        """:meth:`_nearest_by_bch` for a code word by syndromes, in one pass over every flip.

        A flip ``s`` of the searched bits reaches a code word within ``t`` more bits ``x`` exactly
        where ``H (s + x) = 0``, ``H`` checking the differences between code words (their
        linear code, :meth:`_check_columns`): ``x`` is the correction whose syndrome is ``s``'s.
        Two corrections of at most ``t`` bits never share a syndrome (their sum would be a code
        difference lighter than BCH's ``2t + 1``), so this finds the words BCH decoding and the
        CRC find, 17-62x as fast (``bench/rival_search.py``)."""
        n = self.spec.code_bits
        columns = self._check_columns()
        patterns = _flip_patterns(len(searched)).astype(bool)
        syndromes = np.bitwise_xor.reduce(np.where(patterns, columns[searched], np.uint64(0)), axis=1)
        differences = np.zeros((len(patterns), n), dtype=np.uint8)
        differences[:, searched] = patterns
        reached = syndromes == 0
        corrections, correction_syndromes = self._corrections()
        if len(correction_syndromes):
            at = np.minimum(np.searchsorted(correction_syndromes, syndromes), len(correction_syndromes) - 1)
            hit = ~reached & (correction_syndromes[at] == syndromes)
            for column in corrections[at[hit]].T:
                used = column >= 0
                rows = np.flatnonzero(hit)[used]
                differences[rows, column[used]] ^= 1
            reached |= hit
        reached &= differences.any(axis=1)
        if not reached.any():
            return None
        totals = np.where(reached, differences @ shown, np.inf)
        nearest = int(np.argmin(totals))
        return float(totals[nearest]), code ^ differences[nearest]

    def _check_columns(self) -> np.ndarray:
        """``(N_b,)`` uint64: each code bit's column of the parity checks of the code words'
        differences, as bits of an integer. The code is systematic (``[payload | CRC | BCH]``
        under the whitening), so the differences' generator is ``[I | A]`` and the checks
        ``[A^T | I]``: a payload bit's column is its row of ``A``, every other bit's a unit."""
        if self._columns is None:
            p = self.spec.payload_bits
            self._zero_word, generator = self._difference_generator()
            generator = generator.astype(np.uint64)
            weights = np.left_shift(np.uint64(1), np.arange(self.spec.code_bits - p, dtype=np.uint64))
            self._columns = np.concatenate([(generator[:, p:] * weights).sum(axis=1), weights])
        return self._columns

    def _difference_generator(self) -> tuple[np.ndarray, np.ndarray]:
        """The zero payload's code word ``(N_b,)``, and ``(P, N_b)`` each payload bit's code word
        minus it: the generator of the differences between code words."""
        p = self.spec.payload_bits
        words = self.encode(np.vstack([np.zeros(p, np.uint8), np.eye(p, dtype=np.uint8)]))
        return words[0], words[1:] ^ words[0]

    def _corrections(self) -> tuple[np.ndarray, np.ndarray]:
        """Every set of 1 to ``t`` code bits (``(K, t)`` indices, -1 past a smaller set's end) and
        their syndromes ``(K,)``, sorted by syndrome (:meth:`_nearest_by_syndrome`)."""
        if self._correction_table is None:
            t, n = self.spec.bch_t, self.spec.code_bits
            columns = self._check_columns()
            sets = [c for r in range(1, t + 1) for c in itertools.combinations(range(n), r)]
            indices = np.full((len(sets), max(t, 1)), -1, dtype=np.int64)
            for row, subset in enumerate(sets):
                indices[row, : len(subset)] = subset
            syndromes = np.bitwise_xor.reduce(np.where(indices >= 0, columns[indices], np.uint64(0)), axis=1)
            order = np.argsort(syndromes, kind="stable")
            self._correction_table = (indices[order], syndromes[order])
        return self._correction_table

    def _is_code_word(self, code: np.ndarray) -> bool:
        """Whether ``code`` (``(N_b,)`` 0/1) is one of the code's words."""
        columns = self._check_columns()  # sets the zero payload's word too
        return not np.bitwise_xor.reduce(np.where((code ^ self._zero_word).astype(bool), columns, np.uint64(0)))

    def _code_differences(self) -> np.ndarray:
        """``(2**P - 1, N_b)`` every non-zero difference between two code words, as floats (kept)."""
        if self._differences is None:
            p = self.spec.payload_bits
            generator = self._difference_generator()[1].astype(np.int64)
            payloads = (np.arange(1, 2**p)[:, None] >> np.arange(p - 1, -1, -1)) & 1
            self._differences = ((payloads @ generator) % 2).astype(np.float32)
        return self._differences

    def describe(self) -> dict[str, Any]:
        """What a program needs to decode code bits without DeepMorph, JSON-ready: the layout
        (this module's docstring), the CRC's and the BCH code's parameters, and the whitening
        mask as a string of ``0`` and ``1``, most significant bit first (``docs/export.md``)."""
        spec = self.spec
        crc_config = crc_configuration(spec.crc_bits) if spec.crc_bits else None
        return {
            "payload_bits": spec.payload_bits,
            "crc_bits": spec.crc_bits,
            "ecc_bits": spec.ecc_bits,
            "code_bits": spec.code_bits,
            "layout": "code = (payload | CRC of the payload | BCH parity) XOR whitening, most significant bit first",
            "crc": None
            if crc_config is None
            else {
                "width": crc_config.width,
                "polynomial": crc_config.polynomial,
                "init": crc_config.init_value,
                "final_xor": crc_config.final_xor_value,
                "reflect_input": crc_config.reverse_input,
                "reflect_output": crc_config.reverse_output,
                "input": "the payload's value as big-endian bytes, zero bits added in front to whole bytes",
            },
            "bch": None
            if self._bch is None
            else {
                "t": spec.bch_t,
                "m": spec.field_order,
                "primitive_polynomial": int(self._bch.prim_poly),
                "data": "payload and CRC bits with zero bits added at the end to whole bytes (not sent)",
                "parity": "the first ecc_bits bits of the Linux kernel BCH encoder's parity bytes (bchlib)",
            },
            "whitening": "".join(str(int(b)) for b in self._mask),
        }

    # -- decoding internals

    def _probabilities(self, probs: Any) -> np.ndarray:
        q = np.asarray(probs, dtype=np.float64)
        if q.shape != (self.spec.code_bits,):
            raise DeepMorphError(f"probabilities must have shape ({self.spec.code_bits},), got {tuple(q.shape)}")
        if not np.isfinite(q).all() or (q < 0).any() or (q > 1).any():
            raise DeepMorphError("probabilities must be finite and lie in [0, 1]")
        return q

    def _chase(self, hard: np.ndarray, cost: np.ndarray, first: np.ndarray | None) -> np.ndarray | None:
        """Chase-II: BCH-decode the hard word with each combination of the ``L`` least reliable
        bits flipped, rank the distinct code words found by likelihood, and return the most likely
        of the ``soft_candidates`` best that passes the CRC (without a CRC: the most likely)."""
        sure = self.reliable_above
        reliable_cost = math.log(sure / (1.0 - sure)) if sure < 1 else math.inf
        order = np.argsort(cost, kind="stable")
        weak = [int(i) for i in order[: self.soft_bits] if cost[i] < reliable_cost]
        if not weak:
            return None
        trials = np.repeat(hard[None], 2 ** len(weak) - 1, axis=0)
        trials[:, weak] ^= _flip_patterns(len(weak))
        found = {w.tobytes(): w for w in self._bch_correct(trials) if w is not None}
        if first is not None:
            found.pop(first.tobytes(), None)  # the hard decoder's word already failed the CRC
        if not found:
            return None
        words = np.stack(list(found.values()))
        # -log-likelihood relative to the hard decision: the sum of |LLR| over the changed bits
        ranked = np.argsort((words != hard) @ cost, kind="stable")[: self.soft_candidates]
        for i in ranked:
            if self._crc is None or self._accepts(words[i]):
                return words[i]
        return None

    def _result(self, payload: np.ndarray, ok: bool, flips: int, conf: float, margin: float = 0.0) -> DecodeResult:
        out = np.array(payload, dtype=np.uint8)
        out.setflags(write=False)
        return DecodeResult(payload=out, ok=ok, corrected_bits=flips, confidence=conf, rival_log_odds=margin)
