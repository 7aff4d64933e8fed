"""Payload codec: round trips, hard and soft error correction, false accepts of garbage, payload
text, JSON shape, and readable spec errors. Reference values come from bchlib and crc directly."""

from __future__ import annotations

import itertools
import json
import math
import re
from pathlib import Path

import bchlib
import crc
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError

from deepmorph_core.codec import (
    COLOUR_CRC,
    CRC_POLYNOMIALS,
    CRC_WIDTHS,
    CodecSpec,
    DecodeResult,
    PayloadCodec,
    choose_codec,
    crc_configuration,
    default_crc_bits,
    format_codec_error,
)
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.payload import Payload, TextForm, format_payload, parse_payload_text, random_payloads

DOCS = Path(__file__).parents[2] / "docs" / "codec.md"

SPECS = [
    CodecSpec(payload_bits=p, crc_bits=c, bch_t=t)
    for p in (8, 16, 24, 32, 48, 64)
    for c in (8, 16)
    for t in (0, 1, 2, 3)
]


def spec_id(spec: CodecSpec) -> str:
    return f"p{spec.payload_bits}-crc{spec.crc_bits}-t{spec.bch_t}"


def as_probs(word: np.ndarray, confident: float = 1.0) -> np.ndarray:
    """Probabilities a perfect decoder network would output for ``word``."""
    return np.where(word == 1, confident, 1.0 - confident)


def binomial_ceiling(n: int, p: float) -> float:
    """A count that ``Binomial(n, p)`` exceeds with negligible probability (mean + 4 sd + 1)."""
    return n * p + 4.0 * math.sqrt(n * p * (1.0 - p)) + 1.0


# ------------------------------------------------------------------ layout against the libraries


def test_bit_order_is_most_significant_first() -> None:
    bits = parse_payload_text("0xA1B2C3", 24)
    assert "".join(map(str, bits)) == "101000011011001011000011"
    assert format_payload(bits) == {"hex": "0xA1B2C3", "bits": "101000011011001011000011"}


def _reference_word(payload: np.ndarray, bch: bchlib.BCH) -> np.ndarray:
    """payload | CRC-16/XMODEM | bchlib parity, built by hand (payload a whole number of bytes)."""
    value = crc.Calculator(crc.Crc16.XMODEM).checksum(np.packbits(payload).tobytes())
    info = np.concatenate([payload, np.unpackbits(np.array([value >> 8, value & 0xFF], np.uint8))])
    ecc = np.unpackbits(np.frombuffer(bch.encode(np.packbits(info).tobytes()), np.uint8))[: bch.ecc_bits]
    return np.concatenate([info, ecc])


def test_code_word_is_payload_crc_and_bchlib_ecc_under_a_fixed_mask() -> None:
    """Naive reference: build the code word by hand from crc and bchlib and compare."""
    spec = CodecSpec(payload_bits=72, crc_bits=16, bch_t=3)
    codec = PayloadCodec(spec)
    bch = bchlib.BCH(3, m=spec.field_order)
    assert spec.ecc_bits == bch.ecc_bits and spec.code_bits == 72 + 16 + bch.ecc_bits
    check = np.unpackbits(np.frombuffer(b"123456789", np.uint8))  # the CRC catalogue's check string
    reference = _reference_word(check, bch)
    assert int("".join(map(str, reference[72:88])), 2) == 0x31C3  # CRC-16/XMODEM's check value
    mask = codec.encode(check) ^ reference
    assert 0.3 < mask.mean() < 0.7  # whitening, not a constant
    for payload in random_payloads(20, 72, np.random.default_rng(0)):
        assert np.array_equal(codec.encode(payload) ^ mask, _reference_word(payload, bch))  # the same mask


def test_crc8_is_over_the_left_padded_payload_value() -> None:
    spec = CodecSpec(payload_bits=12, crc_bits=8, bch_t=0)
    word = PayloadCodec(spec).encode(parse_payload_text("0xABC", 12))
    assert crc.Calculator(crc.Crc8.CCITT).checksum(b"123456789") == 0xF4  # the catalogue's check value
    zero = PayloadCodec(spec).encode(np.zeros(12, np.uint8))
    crc_bits = (word ^ zero)[12:20]  # the mask cancels; CRC-8/CCITT of 0 is 0
    assert int("".join(map(str, crc_bits)), 2) == crc.Calculator(crc.Crc8.CCITT).checksum(b"\x0a\xbc")


# ------------------------------------------------------------------------------ round trips


@pytest.mark.parametrize("spec", SPECS, ids=spec_id)
def test_round_trip_many_payloads(spec: CodecSpec) -> None:
    codec = PayloadCodec(spec)
    payloads = random_payloads(40, spec.payload_bits, np.random.default_rng(spec.payload_bits * 31 + spec.bch_t))
    words = codec.encode(payloads)
    assert words.shape == (40, spec.code_bits) and words.dtype == np.uint8
    assert spec.code_bits == spec.payload_bits + spec.crc_bits + spec.ecc_bits
    for payload, word in zip(payloads, words):
        assert np.array_equal(codec.encode(payload), word)
        for probs in (as_probs(word), as_probs(word, 0.7)):
            result = codec.decode(probs)
            assert result.ok and result.corrected_bits == 0
            assert np.array_equal(result.payload, payload)


@given(
    payload_bits=st.integers(1, 256),
    crc_bits=st.sampled_from([8, 16]),
    bch_t=st.integers(0, 4),
    data=st.data(),
)
def test_hard_decoding_corrects_up_to_t_flips(payload_bits: int, crc_bits: int, bch_t: int, data) -> None:
    spec = CodecSpec(payload_bits=payload_bits, crc_bits=crc_bits, bch_t=bch_t)
    codec = PayloadCodec(spec)
    payload = np.array(data.draw(st.lists(st.integers(0, 1), min_size=payload_bits, max_size=payload_bits)), np.uint8)
    flips = data.draw(st.lists(st.integers(0, spec.code_bits - 1), max_size=bch_t, unique=True))
    word = codec.encode(payload)
    word[flips] ^= 1
    result = codec.decode(as_probs(word), soft=False)
    assert result.ok and np.array_equal(result.payload, payload)
    assert result.corrected_bits == len(flips)


def test_every_error_pattern_up_to_t_is_corrected_around_the_paddings() -> None:
    """20 payload + 8 CRC bits leave 4 data padding bits, and 12 ECC bits 4 more: every single and
    double error, in payload, CRC and ECC alike, is corrected (checks bchlib's error locations)."""
    spec = CodecSpec(payload_bits=20, crc_bits=8, bch_t=2)
    assert (spec.field_order, spec.ecc_bits, spec.code_bits) == (6, 12, 40)
    codec = PayloadCodec(spec)
    payload = parse_payload_text("0x5A0F3", 20)
    word = codec.encode(payload)
    for flips in itertools.chain(itertools.combinations(range(40), 1), itertools.combinations(range(40), 2)):
        received = word.copy()
        received[list(flips)] ^= 1
        result = codec.decode(as_probs(received), soft=False)
        assert result.ok and result.corrected_bits == len(flips) and np.array_equal(result.payload, payload), flips


def test_a_correction_in_the_untransmitted_padding_is_a_failure() -> None:
    """A word one bit from a code word whose (never sent) padding bit is 1 is not decodable: the
    padding is known to be 0, so BCH's "correction" there means more than t errors. No CRC here,
    so only the padding check can tell."""
    spec = CodecSpec(payload_bits=28, crc_bits=0, bch_t=2)
    codec = PayloadCodec(spec)
    bch = bchlib.BCH(2, m=spec.field_order)
    mask = codec.encode(np.zeros(28, np.uint8))  # the all-zero payload's code word is all zeros
    info = np.random.default_rng(4).integers(0, 2, 28).astype(np.uint8)
    data = np.packbits(info)
    data[-1] |= 0x01  # a padding bit set: a code word of the unshortened code
    ecc = np.unpackbits(np.frombuffer(bch.encode(data.tobytes()), np.uint8))[: spec.ecc_bits]
    result = codec.decode(as_probs(np.concatenate([info, ecc]) ^ mask), soft=False)
    assert result.corrected_bits == -1 and not result.ok


def test_unchecked_payload_is_never_ok() -> None:
    spec = CodecSpec(payload_bits=24, crc_bits=0, bch_t=2)
    codec = PayloadCodec(spec)
    payload = parse_payload_text("0x123456", 24)
    word = codec.encode(payload)
    assert spec.code_bits == 24 + spec.ecc_bits
    clean = codec.decode(as_probs(word))
    assert not clean.ok and clean.corrected_bits == 0 and np.array_equal(clean.payload, payload)
    word[[1, 30]] ^= 1
    fixed = codec.decode(as_probs(word))
    assert not fixed.ok and fixed.corrected_bits == 2 and np.array_equal(fixed.payload, payload)
    raw = PayloadCodec(CodecSpec(payload_bits=5, crc_bits=0, bch_t=0))
    assert not raw.decode(as_probs(raw.encode(np.ones(5, np.uint8)))).ok


# ------------------------------------------------------------------------------ soft decisions


@pytest.mark.parametrize(
    "spec",
    [
        CodecSpec(payload_bits=8, crc_bits=8, bch_t=1),
        CodecSpec(payload_bits=24, crc_bits=8, bch_t=2),
        CodecSpec(payload_bits=32, crc_bits=8, bch_t=3),
        CodecSpec(payload_bits=48, crc_bits=16, bch_t=2),
        CodecSpec(payload_bits=64, crc_bits=16, bch_t=3),
        CodecSpec(payload_bits=16, crc_bits=16, bch_t=0),
    ],
    ids=spec_id,
)
@pytest.mark.parametrize("extra", [1, 2])
def test_soft_decoding_fixes_errors_beyond_t_on_uncertain_bits(spec: CodecSpec, extra: int) -> None:
    """t+1 and t+2 wrong bits, each with p a little on the wrong side of 0.5, the rest confident:
    hard decoding never recovers the payload, Chase-II almost always does, and never wrongly."""
    codec = PayloadCodec(spec)
    rng = np.random.default_rng(100 * spec.bch_t + extra)
    trials, hard_ok, soft_ok = 60, 0, 0
    for payload in random_payloads(trials, spec.payload_bits, rng):
        word = codec.encode(payload)
        sure = rng.uniform(0.97, 1.0, word.shape)
        probs = np.where(word == 1, sure, 1.0 - sure)
        wrong = rng.choice(spec.code_bits, spec.bch_t + extra, replace=False)
        probs[wrong] = np.where(
            word[wrong] == 1, rng.uniform(0.35, 0.5, wrong.shape), rng.uniform(0.5, 0.65, wrong.shape)
        )
        hard = codec.decode(probs, soft=False)
        soft = codec.decode(probs)
        hard_ok += hard.ok and np.array_equal(hard.payload, payload)
        if soft.ok:
            assert np.array_equal(soft.payload, payload)
            assert soft.corrected_bits == spec.bch_t + extra
            soft_ok += 1
    assert hard_ok == 0
    assert soft_ok >= (trials if extra == 1 else 0.9 * trials)


def test_soft_search_leaves_saturated_bits_alone() -> None:
    """Probabilities of exactly 0/1 say nothing about which bits are wrong: no Chase search."""
    spec = CodecSpec(payload_bits=24, crc_bits=8, bch_t=2)
    codec = PayloadCodec(spec)
    payload = parse_payload_text("0xC0FFEE", 24)
    word = codec.encode(payload)
    word[[0, 5, 9]] ^= 1
    assert codec.decode(as_probs(word)).corrected_bits == -1
    probs = as_probs(word)
    probs[[0, 5, 9]] = np.where(word[[0, 5, 9]] == 1, 0.55, 0.45)
    assert codec.decode(probs).ok
    assert PayloadCodec(spec, soft_bits=0).decode(probs).corrected_bits == -1


# ------------------------------------------------------------------------------ false accepts


def _false_accepts(codec: CodecSpec | PayloadCodec, inputs: np.ndarray, truth: np.ndarray | None = None) -> int:
    count = 0
    for i, probs in enumerate(inputs):
        result = codec.decode(probs)
        if result.ok and (truth is None or not np.array_equal(result.payload, truth[i])):
            count += 1
    return count


def _corrupted(codec: PayloadCodec, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Code words with 20-50% of their bits flipped, read with confident (hard) probabilities."""
    spec = codec.spec
    payloads = random_payloads(n, spec.payload_bits, rng)
    words = codec.encode(payloads)
    flips = rng.random(words.shape) < rng.uniform(0.2, 0.5, (n, 1))
    return as_probs(words ^ flips, 0.98), payloads


@pytest.mark.parametrize(
    "spec",
    [CodecSpec(payload_bits=48, crc_bits=16, bch_t=2), CodecSpec(payload_bits=64, crc_bits=16, bch_t=0)],
    ids=spec_id,
)
def test_crc16_never_accepts_heavily_corrupted_words(spec: CodecSpec) -> None:
    codec = PayloadCodec(spec)
    probs, payloads = _corrupted(codec, 3000, np.random.default_rng(7))
    assert _false_accepts(codec, probs, payloads) == 0


@pytest.mark.parametrize(
    "spec",
    [CodecSpec(payload_bits=24, crc_bits=8, bch_t=2), CodecSpec(payload_bits=8, crc_bits=8, bch_t=1)],
    ids=spec_id,
)
def test_crc8_rarely_accepts_heavily_corrupted_words(spec: CodecSpec) -> None:
    codec = PayloadCodec(spec)
    n = 3000
    probs, payloads = _corrupted(codec, n, np.random.default_rng(8))
    rate = _false_accepts(codec, probs, payloads) / n
    print(f"crc8 {spec_id(spec)}: heavily corrupted words falsely accepted {rate:.3%}")
    assert rate < 0.01


@pytest.mark.parametrize(
    "spec, n",
    [
        (CodecSpec(payload_bits=24, crc_bits=8, bch_t=2), 3000),
        (CodecSpec(payload_bits=32, crc_bits=8, bch_t=0), 3000),
        (CodecSpec(payload_bits=64, crc_bits=16, bch_t=2), 2000),
    ],
    ids=lambda x: spec_id(x) if isinstance(x, CodecSpec) else str(x),
)
def test_random_probabilities_false_accept_rate_is_bounded_by_the_crc(spec: CodecSpec, n: int) -> None:
    """Unrelated pictures: uniform probabilities. Each code word put to the CRC passes with
    chance 2**-crc_bits: the hard decoder's plus at most ``soft_candidates`` from Chase-II."""
    codec = PayloadCodec(spec)
    bound = (1 + codec.soft_candidates) * 2.0**-spec.crc_bits
    inputs = np.random.default_rng(9).random((n, spec.code_bits))
    count = _false_accepts(codec, inputs)
    print(f"{spec_id(spec)}: random inputs accepted {count / n:.3%} (bound {bound:.3%})")
    assert count <= binomial_ceiling(n, bound)
    assert _false_accepts(PayloadCodec(spec, soft_bits=0), inputs[:1000]) <= binomial_ceiling(1000, 2.0**-spec.crc_bits)


@pytest.mark.parametrize("spec", SPECS, ids=spec_id)
def test_constant_outputs_are_never_accepted(spec: CodecSpec) -> None:
    """A blank picture (every probability equal) is not a code word, whatever the constant."""
    codec = PayloadCodec(spec)
    for value in (0.0, 0.02, 0.3, 0.5, 0.51, 0.8, 0.99, 1.0):
        assert not codec.decode(np.full(spec.code_bits, value)).ok


# ------------------------------------------------------------------------------ payload text


@pytest.mark.parametrize(
    "text, bits, expect",
    [
        ("0xA1B2C3", 24, "101000011011001011000011"),
        ("0xa1b2c3", 24, "101000011011001011000011"),
        ("  0XA1B2C3\n", 24, "101000011011001011000011"),
        ("0x3FF", 10, "1111111111"),
        ("0x1", 1, "1"),
        ("0101", 4, "0101"),
        ("000", 3, "000"),
        ("0d10597059", 24, "101000011011001011000011"),
        ("0D0005", 4, "0101"),
        ("0d1023", 10, "1111111111"),
        ("0d0", 3, "000"),
    ],
)
def test_parse_payload_accepts(text: str, bits: int, expect: str) -> None:
    arr = parse_payload_text(text, bits)
    assert arr.dtype == np.uint8 and arr.shape == (bits,)
    assert "".join(map(str, arr)) == expect


@pytest.mark.parametrize(
    "text, bits, message",
    [
        ("0xA1B2C", 24, "has 5 hex digits; expected a 24-bit payload: hex with 6 digits"),
        ("0xA1B2C3D4", 24, "has 8 hex digits"),
        ("0xG1B2C3", 24, "'G' is not a hex digit"),
        ("0x7FF", 10, "needs 11 bits, more than 10"),
        ("0x", 8, "has 0 hex digits"),
        ("0101", 24, "payload has 4 binary digits; expected a 24-bit payload"),
        ("A1B2C3", 24, "neither 0x-prefixed hex, a 0d-prefixed number nor binary digits"),
        ("0d16777216", 24, "payload '0d16777216' is too large for 24 bits: the largest is 16777215 (0xFFFFFF)"),
        ("0d" + "9" * 5000, 24, "is too large for 24 bits"),
        ("0d-1", 24, "'-' is not a decimal digit"),
        ("0d1e3", 24, "'e' is not a decimal digit"),
        ("0d", 24, "no digits"),
        ("0b0101", 4, "neither"),
        ("", 8, "empty payload"),
        ("0101", 0, "payload_bits must be between 1 and 256"),
    ],
)
def test_parse_payload_rejects(text: str, bits: int, message: str) -> None:
    with pytest.raises(DeepMorphError) as info:
        parse_payload_text(text, bits)
    assert message in str(info.value)


@pytest.mark.parametrize(
    "text, form, expect",
    [
        ("10597059", "number", 0xA1B2C3),
        ("0d10597059", "number", 0xA1B2C3),
        ("000101", "number", 101),  # digits a user chose to give as a number are never bits
        ("A1B2C3", "hex", 0xA1B2C3),
        ("0xa1b2c3", "hex", 0xA1B2C3),
        ("000101", "hex", 0x101),
        ("000000000000000100000001", "bits", 0x101),
    ],
)
def test_a_chosen_form_says_what_the_text_is(text: str, form: TextForm, expect: int) -> None:
    assert Payload.parse(text, 24, form).int == expect


@pytest.mark.parametrize(
    "text, form, message",
    [
        ("16777216", "number", "payload '16777216' is too large for 24 bits: the largest is 16777215 (0xFFFFFF)"),
        ("0xA1", "number", "'x' is not a decimal digit; expected a whole number from 0 to 16777215"),
        ("-3", "number", "'-' is not a decimal digit"),
        ("A1B2", "hex", "has 4 hex digits; expected 6 hex digits like 0xA1B2C3"),
        ("A1.B2C", "hex", "'.' is not a hex digit"),
        ("0102", "bits", "holds digits other than 0 and 1"),
        ("12", "octal", "a payload is written as hex, number, bits, not 'octal'"),
    ],
)
def test_a_chosen_form_refuses_other_text(text: str, form: str, message: str) -> None:
    with pytest.raises(DeepMorphError) as info:
        parse_payload_text(text, 24, form)  # type: ignore[arg-type]
    assert message in str(info.value), str(info.value)


@given(st.integers(1, 256).flatmap(lambda n: st.tuples(st.just(n), st.integers(0, 2**n - 1))))
def test_a_number_reads_back_as_its_value(case: tuple[int, int]) -> None:
    bits, value = case
    assert Payload.parse(f"0d{value}", bits).int == value == Payload.parse(str(value), bits, "number").int
    assert Payload.parse(f"0d{value}", bits) == Payload.of(value, bits)


@given(st.lists(st.integers(0, 1), min_size=1, max_size=256))
def test_format_and_parse_are_inverse(bits: list[int]) -> None:
    arr = np.array(bits, np.uint8)
    shown = format_payload(arr)
    assert re.fullmatch(r"0x[0-9A-F]+", shown["hex"]) and len(shown["hex"]) == 2 + math.ceil(len(bits) / 4)
    assert np.array_equal(parse_payload_text(shown["hex"], len(bits)), arr)
    assert np.array_equal(parse_payload_text(shown["bits"], len(bits)), arr)


def test_random_payloads_are_replayable() -> None:
    a = random_payloads(5, 24, np.random.default_rng(1))
    assert a.shape == (5, 24) and a.dtype == np.uint8 and set(np.unique(a)) <= {0, 1}
    assert np.array_equal(a, random_payloads(5, 24, np.random.default_rng(1)))


# ------------------------------------------------------------------------------ results and inputs


def test_decode_result_json_shape() -> None:
    spec = choose_codec(24)
    codec = PayloadCodec(spec)
    word = codec.encode(parse_payload_text("0xA1B2C3", 24))
    word[[2, 40]] ^= 1
    result = codec.decode(as_probs(word, 0.9))
    assert isinstance(result, DecodeResult)
    doc = result.to_json()
    assert doc == {
        "payload": {"hex": "0xA1B2C3", "bits": "101000011011001011000011"},
        "ok": True,
        "corrected_bits": 2,
        "confidence": pytest.approx(0.9),
    }
    assert json.loads(json.dumps(doc)) == doc
    assert type(doc["ok"]) is bool and type(doc["corrected_bits"]) is int and type(doc["confidence"]) is float
    failed = codec.decode(np.full(spec.code_bits, 0.5)).to_json()
    assert failed["ok"] is False and failed["corrected_bits"] == -1 and failed["confidence"] == pytest.approx(0.5)
    assert len(failed["payload"]["bits"]) == 24
    with pytest.raises(ValueError):
        result.payload[0] = 1  # results are read-only


def test_bad_inputs_are_readable_errors() -> None:
    codec = PayloadCodec(choose_codec(16))
    n = codec.spec.code_bits
    cases = [
        (lambda: codec.encode(np.zeros(15)), "payload must have shape (16,), got (15,)"),
        (lambda: codec.encode(np.full(16, 2)), "only 0 and 1"),
        (lambda: codec.encode(np.zeros((3, 8))), "payloads must have shape (B, 16)"),
        (lambda: codec.decode(np.zeros(n + 1)), f"probabilities must have shape ({n},)"),
        (lambda: codec.decode(np.full(n, 1.5)), "lie in [0, 1]"),
        (lambda: codec.decode(np.full(n, np.nan)), "finite"),
    ]
    for call, message in cases:
        with pytest.raises(DeepMorphError) as info:
            call()
        assert message in str(info.value)


def test_decode_batch_matches_decode() -> None:
    codec = PayloadCodec(choose_codec(32))
    payloads = random_payloads(4, 32, np.random.default_rng(3))
    results = codec.decode_batch(as_probs(codec.encode(payloads), 0.8))
    assert [r.to_json() for r in results] == [codec.decode(as_probs(codec.encode(p), 0.8)).to_json() for p in payloads]
    assert all(r.ok for r in results)


# ------------------------------------------------------------------------------ specs


def test_default_codecs_match_the_docs_table() -> None:
    rows = re.findall(
        r"^\|\s*(\d+)\s*\|\s*(\d+)\s*\|\s*(\d+)\s*\|\s*(\d+)\s*\|\s*(\d+)\s*\|\s*(\d+)\s*\|$", DOCS.read_text(), re.M
    )
    assert len(rows) >= 8
    for payload_bits, crc_bits, t, m, ecc, code in (tuple(map(int, r)) for r in rows):
        spec = choose_codec(payload_bits)
        assert (spec.crc_bits, spec.bch_t, spec.field_order, spec.ecc_bits, spec.code_bits) == (
            crc_bits,
            t,
            m,
            ecc,
            code,
        )


def test_choose_codec_defaults() -> None:
    assert (choose_codec(8).crc_bits, choose_codec(8).bch_t) == (8, 1)
    assert (choose_codec(32).crc_bits, choose_codec(32).bch_t) == (8, 2)
    assert (choose_codec(33).crc_bits, choose_codec(33).bch_t) == (16, 2)
    assert choose_codec(40, crc_bits=8, bch_t=0).code_bits == 48


def test_spec_is_frozen_and_round_trips_through_json() -> None:
    spec = CodecSpec(payload_bits=40, crc_bits=16, bch_t=3, bch_m=8)
    assert CodecSpec.model_validate_json(spec.model_dump_json()) == spec
    assert spec.field_order == 8 and spec.ecc_bits == 24
    assert CodecSpec(payload_bits=40, crc_bits=16, bch_t=3).field_order == 7
    assert CodecSpec(payload_bits=40, bch_t=0).ecc_bits == 0 and CodecSpec(payload_bits=40, bch_t=0).field_order is None
    with pytest.raises(ValidationError):
        spec.bch_t = 1  # type: ignore[misc]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"payload_bits": 0}, "payload_bits: Input should be greater than or equal to 1"),
        ({"payload_bits": 257}, "payload_bits: Input should be less than or equal to 256"),
        ({"payload_bits": 24, "crc_bits": 9}, "crc_bits: Input should be 0, 8, 10, 11, 12, 13, 14, 15 or 16"),
        ({"payload_bits": 24, "bch_t": -1}, "bch_t: Input should be greater than or equal to 0"),
        ({"payload_bits": 24, "bch_m": 4}, "bch_m: Input should be greater than or equal to 5"),
        (
            {"payload_bits": 24, "bch_t": 2, "bch_m": 5},
            "bch_m=5 is too small: with bch_t=2 its code words carry 16 data bits, but payload+CRC need 32 "
            "(byte-padded); use bch_m >= 6 or leave bch_m unset",
        ),
        ({"payload_bits": 24, "bch_t": 0, "bch_m": 6}, "bch_m=6 has no effect without error correction"),
        ({"payload_bits": 24, "ecc": 2}, "unknown codec setting 'ecc' (known: payload_bits, crc_bits, bch_t, bch_m)"),
    ],
)
def test_spec_errors_are_readable(kwargs: dict, message: str) -> None:
    with pytest.raises(ValidationError) as info:
        CodecSpec(**kwargs)
    text = format_codec_error(info.value)
    assert message in text and "\n" not in text


def test_choose_codec_errors_are_one_line() -> None:
    with pytest.raises(DeepMorphError) as info:
        choose_codec(0)
    assert str(info.value) == "invalid codec: payload_bits: Input should be greater than or equal to 1"
    with pytest.raises(
        DeepMorphError, match="^invalid codec: crc_bits: Input should be 0, 8, 10, 11, 12, 13, 14, 15 or 16$"
    ):
        choose_codec(24, crc_bits=32)


def _every_code_word(codec: PayloadCodec) -> np.ndarray:
    """``(2**P, N_b)`` the code word of every payload, encoded one by one."""
    p = codec.spec.payload_bits
    payloads = (np.arange(2**p)[:, None] >> np.arange(p - 1, -1, -1)) & 1
    return codec.encode(payloads.astype(np.uint8))


@pytest.mark.parametrize(
    "spec",
    [
        choose_codec(11, crc_bits=8, bch_t=1),
        choose_codec(8, crc_bits=8, bch_t=2),
        choose_codec(12, crc_bits=16, bch_t=1),
    ],
)
def test_the_rival_margin_is_the_least_support_of_any_other_code_word(spec: CodecSpec) -> None:
    """Listed, the margin is exact: the minimum over every other code word (encoded one by one)
    of the support on the bits where it differs."""
    codec = PayloadCodec(spec)
    words = _every_code_word(codec)
    rng = np.random.default_rng(5)
    for _ in range(20):
        word = words[rng.integers(len(words))]
        support = rng.normal(1.0, 1.0, spec.code_bits)
        others = words[(words != word).any(1)]
        exact = float(((others != word) * support).sum(1).min())
        assert codec.rival_margin(word, support) == pytest.approx(exact, abs=1e-4)


def test_a_clear_word_beats_its_rivals_by_the_code_distance_and_a_near_miss_loses() -> None:
    codec = PayloadCodec(choose_codec(11, crc_bits=8, bch_t=1))
    words = _every_code_word(codec)
    distance = int(min((w != words[0]).sum() for w in words[1:]))
    assert distance >= 3  # a CRC and BCH with t = 1
    clear = np.ones(codec.spec.code_bits)
    assert codec.rival_margin(words[0], clear) == pytest.approx(distance)
    # three bits shown flipped: no rival needs only those, so the word still wins
    shown = clear.copy()
    shown[[0, 7, 19]] = -0.6
    assert codec.rival_margin(words[0], shown) >= 1.0
    # the photo of another word, asked about this one: that word is a rival the photo prefers
    other = words[1234]
    seen = np.where(other == words[0], 1.0, -1.0)
    assert codec.rival_margin(words[0], seen) == pytest.approx(-(other != words[0]).sum())


def test_the_nearest_rival_is_the_code_word_whose_differing_bits_have_the_least_support(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Listed or searched, the nearest rival is a code word other than the word, and the support
    over the bits where it differs is the rival margin (exact when the rival lies in the search)."""
    import deepmorph_core.codec as codec_module

    codec = PayloadCodec(choose_codec(11, crc_bits=8, bch_t=1))
    words = _every_code_word(codec)
    rng = np.random.default_rng(13)
    for _ in range(20):
        word = words[rng.integers(len(words))]
        support = rng.normal(1.0, 1.0, codec.spec.code_bits)
        rival = codec.nearest_rival(word, support)
        assert rival is not None and rival.dtype == np.uint8 and (rival != word).any()
        assert (words == rival).all(1).any()  # a code word
        assert float(support[rival != word].sum()) == pytest.approx(codec.rival_margin(word, support), abs=1e-4)
    # the photo of another word asked about this one: that word, listed and searched
    other = words[321]
    seen = np.where(other == words[0], 1.0, -1.0)
    assert np.array_equal(codec.nearest_rival(words[0], seen), other)
    monkeypatch.setattr(codec_module, "LISTED_RIVALS_UP_TO", 0)
    assert np.array_equal(codec.nearest_rival(words[0], seen), other)


@pytest.mark.parametrize(
    ("payload_bits", "crc_bits", "bch_t"), [(14, 8, 0), (11, 16, 2), (12, 8, 2), (24, 8, 1), (29, 8, 1)]
)
def test_the_rival_search_by_syndromes_finds_what_bch_decoding_finds(
    payload_bits: int, crc_bits: int, bch_t: int
) -> None:
    """Above the listed size, every flip of the least supported bits is taken to the code word
    within ``t`` bits of it by syndromes; BCH decoding and the CRC, flip by flip, find the same
    nearest word with the same support, and none where they find none."""
    from deepmorph_core.codec import RIVAL_SEARCH_BITS

    codec = PayloadCodec(choose_codec(payload_bits, crc_bits=crc_bits, bch_t=bch_t))
    n = codec.spec.code_bits
    rng = np.random.default_rng(payload_bits + bch_t)
    differences = codec._code_differences() if payload_bits <= 16 else None
    found = 0
    for trial in range(40):
        word = codec.encode(rng.integers(0, 2, payload_bits).astype(np.uint8))
        if trial % 2:  # a photo of another word: their differing bits shown flipped, weakly
            near = codec.encode(rng.integers(0, 2, payload_bits).astype(np.uint8))
            if payload_bits <= 16:  # one that differs in few enough bits for the search
                light = differences[differences.sum(axis=1) <= RIVAL_SEARCH_BITS + bch_t]
                near = word ^ light[rng.integers(len(light))].astype(np.uint8)
            shown = np.where(near == word, 1.0, -0.2) + rng.normal(0.0, 0.3, n)
        else:
            shown = rng.normal(1.0, (0.3, 1.5)[trial % 4 // 2], n)
        searched = np.argsort(shown, kind="stable")[:RIVAL_SEARCH_BITS]
        by_bch = codec._nearest_by_bch(word, shown, searched)
        by_syndrome = codec._nearest_by_syndrome(word, shown, searched)
        assert (by_bch is None) == (by_syndrome is None)
        if by_bch is not None:
            found += 1
            assert np.array_equal(by_bch[1], by_syndrome[1])
            assert by_syndrome[0] == pytest.approx(by_bch[0], abs=1e-9)
            assert codec.decode(by_syndrome[1].astype(np.float64)).ok
    assert found >= 10
    assert not codec._is_code_word(word ^ np.eye(n, dtype=np.uint8)[0])


def test_a_long_payload_bounds_its_rival_margin_from_below(monkeypatch: pytest.MonkeyPatch) -> None:
    """Above the listed size the rivals are searched around the least supported bits: never above
    the exact margin, and exact when the nearest rival lies in the search."""
    import deepmorph_core.codec as codec_module

    codec = PayloadCodec(choose_codec(11, crc_bits=8, bch_t=1))
    words = _every_code_word(codec)
    rng = np.random.default_rng(9)
    for scale in (0.3, 0.8, 1.5):
        for _ in range(10):
            word = words[rng.integers(len(words))]
            support = rng.normal(1.0, scale, codec.spec.code_bits)
            exact = codec.rival_margin(word, support)
            monkeypatch.setattr(codec_module, "LISTED_RIVALS_UP_TO", 0)
            bound = codec.rival_margin(word, support)
            monkeypatch.setattr(codec_module, "LISTED_RIVALS_UP_TO", 16)
            assert bound <= exact + 1e-9
    # a clear word's rivals beyond the search differ in BCH's designed distance at least
    monkeypatch.setattr(codec_module, "LISTED_RIVALS_UP_TO", 0)
    assert codec.rival_margin(words[0], np.ones(codec.spec.code_bits)) >= 2 * codec.spec.bch_t + 1
    # a near miss found in the search is found exactly
    other = words[77]
    seen = np.where(other == words[0], 1.0, -1.0)
    assert codec.rival_margin(words[0], seen) == pytest.approx(-(other != words[0]).sum())
    with pytest.raises(DeepMorphError, match="shape"):
        codec.rival_margin(words[0], np.ones(3))


def test_a_corrected_reading_reports_how_much_its_probabilities_prefer_it_to_any_rival() -> None:
    """A word read with corrections carries its rival margin in the decoder's own log-odds: the
    least total over the bits where another code word differs, the corrected bit counting
    against it. A reading without corrections, and one that failed, report 0."""
    codec = PayloadCodec(choose_codec(11, crc_bits=8, bch_t=1))
    words = _every_code_word(codec)
    word = words[777]
    sure = np.where(word == 1, 0.99, 0.01)
    log_odds = math.log(0.99 / 0.01)
    assert codec.decode(sure).corrected_bits == 0 and codec.decode(sure).rival_log_odds == 0.0
    misread = sure.copy()
    misread[4] = 1.0 - misread[4]  # one bit read wrong, as confidently
    repaired = codec.decode(misread)
    assert repaired.ok and repaired.corrected_bits == 1 and np.array_equal(codec.encode(repaired.payload), word)
    distance = int(min((w != word).sum() for w in words if (w != word).any()))
    others = words[(words != word).any(1)]
    support = np.where((misread > 0.5) == word, log_odds, -log_odds)
    exact = float(((others != word) * support).sum(1).min())
    assert repaired.rival_log_odds == pytest.approx(exact, rel=1e-6)
    # the misread bit counts against it: less than a clear reading's margin, the code distance
    clear = codec.rival_margin(word, np.full(codec.spec.code_bits, log_odds))
    assert clear == pytest.approx(distance * log_odds) and repaired.rival_log_odds < clear
    # the same misread with the other bits read less surely: a smaller margin
    doubtful = np.where(misread > 0.5, 0.8, 0.2)
    doubtful[4] = misread[4]
    assert 0 < codec.decode(doubtful).rival_log_odds < repaired.rival_log_odds
    assert codec.decode(np.full(codec.spec.code_bits, 0.5)).rival_log_odds == 0.0


def _crc_by_division(data: bytes, width: int, polynomial: int) -> int:
    """The CRC of ``data`` by long division, bit by bit (zero init, no reflection, no final XOR)."""
    register, top = 0, 1 << width
    for bit in np.unpackbits(np.frombuffer(data, dtype=np.uint8)).tolist() + [0] * width:
        register = (register << 1) | bit
        if register & top:
            register ^= top | polynomial
    return register


@pytest.mark.parametrize("width", [w for w in CRC_WIDTHS if w])
def test_every_crc_width_is_its_polynomial_and_the_catalogue_check_value(width: int) -> None:
    """Each width's CRC is long division by its polynomial; where the RevEng catalogue lists the
    same CRC with zero init, its check value over b"123456789" matches."""
    catalogue = {8: 0xF4, 10: 0x199, 12: 0xF5B, 13: 0x04FA, 15: 0x059E, 16: 0x31C3}
    calculator = crc.Calculator(crc_configuration(width))
    for data in (b"123456789", b"\x00\x01", b"\xff" * 5, bytes(range(7))):
        assert calculator.checksum(data) == _crc_by_division(data, width, CRC_POLYNOMIALS[width])
    if width in catalogue:
        assert calculator.checksum(b"123456789") == catalogue[width]


@pytest.mark.parametrize("width", [w for w in CRC_WIDTHS if w])
def test_every_crc_width_round_trips_and_corrects_t_flips(width: int) -> None:
    codec = PayloadCodec(CodecSpec(payload_bits=12, crc_bits=width, bch_t=2))
    rng = np.random.default_rng(width)
    payloads = random_payloads(20, 12, rng)
    for payload, word in zip(payloads, codec.encode(payloads)):
        probs = np.where(word == 1, 0.9, 0.1)
        flips = rng.choice(codec.spec.code_bits, 2, replace=False)
        probs[flips] = 1.0 - probs[flips]
        result = codec.decode(probs, soft=False)
        assert result.ok and np.array_equal(result.payload, payload) and result.corrected_bits == 2


def test_a_longer_crc_in_place_of_payload_bits_keeps_the_code_bits() -> None:
    """Payload bits given over to the CRC leave the BCH data, its parity and the code's size as
    they were: what lets a trained model's code carry a longer CRC."""
    for payload_bits, t in ((10, 1), (6, 2), (20, 2), (3, 1)):
        base = CodecSpec(payload_bits=payload_bits, crc_bits=8, bch_t=t)
        for width in CRC_WIDTHS:
            if 8 < width < 8 + payload_bits:
                longer = CodecSpec(payload_bits=payload_bits - (width - 8), crc_bits=width, bch_t=t)
                assert (longer.code_bits, longer.ecc_bits) == (base.code_bits, base.ecc_bits)


def test_a_narrowed_codec_checks_only_the_first_crc_bits() -> None:
    codec = PayloadCodec(CodecSpec(payload_bits=16, crc_bits=8, bch_t=1))
    narrow = codec.narrowed(3)
    payload = random_payloads(1, 16, np.random.default_rng(0))[0]
    right = codec.encode(payload)
    passes = {True: 0, False: 0}
    for flip in range(1, 256):  # every wrong CRC for the same payload, BCH parity made to match
        crc_bits = codec._crc_bits_of(payload) ^ np.array([(flip >> (7 - i)) & 1 for i in range(8)], np.uint8)  # noqa: SLF001
        info = np.concatenate([payload, crc_bits])
        word = (np.concatenate([info, codec._ecc(info)]) ^ codec._mask).astype(np.uint8)  # noqa: SLF001
        assert not codec.decode(np.where(word == 1, 0.9, 0.1), soft=False).ok
        narrow.forget()
        read = narrow.decode(np.where(word == 1, 0.9, 0.1), soft=False)
        passes[flip >> 5 == 0] += read.ok and read.corrected_bits == 0
        if read.ok:  # collided: the payload's code word is now the word read, as in a real collision
            assert np.array_equal(narrow.encode(payload), word) and not np.array_equal(codec.encode(payload), word)
    assert passes == {True: 31, False: 0}  # the flips within the last 5 bits, and only they
    narrow.forget()
    assert np.array_equal(narrow.encode(payload), right)
    assert narrow.decode(np.where(right == 1, 0.9, 0.1)).ok and codec._crc_checked == 8  # noqa: SLF001
    with pytest.raises(DeepMorphError, match="cannot be checked on 9"):
        codec.narrowed(9)


def test_a_colour_payloads_default_crc_is_at_least_colour_crc() -> None:
    """Where nobody chose a CRC: 8 bits up to 32 payload bits and 16 above; a colour drawing's at
    least COLOUR_CRC; ``choose_codec`` takes the black-ink default."""
    assert [default_crc_bits(p) for p in (1, 32, 33)] == [8, 8, 16]
    assert [default_crc_bits(p, colour=True) for p in (1, 32, 33)] == [COLOUR_CRC, COLOUR_CRC, 16]
    assert choose_codec(16).crc_bits == 8 and choose_codec(40).crc_bits == 16
