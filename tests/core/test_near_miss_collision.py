"""``bench/near_misses.py`` stands near misses in for CRC collisions: a word the correction
reached with its CRC bits as read must be checked as that very code word, not re-encoded with
its payload's true CRC (which changes its CRC and parity bits, bits the photo then contradicts
and that no real collision has)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from deepmorph_core.codec import PayloadCodec, choose_codec

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
from near_misses import colliding, crc_blind, labels  # noqa: E402


def _a_word_with_a_foreign_crc(codec: PayloadCodec, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The sent bits of a code word whose CRC bits are not its payload's, and its payload."""
    spec = codec.spec
    while True:
        payload = rng.integers(0, 2, spec.payload_bits).astype(np.uint8)
        crc = rng.integers(0, 2, spec.crc_bits).astype(np.uint8)
        if not np.array_equal(crc, codec._crc_bits_of(payload)):  # noqa: SLF001
            break
    info = np.concatenate([payload, crc])
    return np.concatenate([info, codec._ecc(info)]) ^ codec._mask, payload  # noqa: SLF001


def test_a_near_miss_is_checked_as_the_code_word_the_correction_reached() -> None:
    codec = PayloadCodec(choose_codec(20, 8, 2))
    rng = np.random.default_rng(3)
    sent, payload = _a_word_with_a_foreign_crc(codec, rng)
    probs = np.where(sent == 1, 0.9, 0.1)
    probs[[2, 17]] = 1.0 - probs[[2, 17]]  # two misread bits, within the code's t
    assert not codec.decode(probs).ok  # its CRC fails: no payload
    blind = crc_blind(codec)
    word = blind.decode(probs)
    assert word.corrected_bits == 2 and np.array_equal(word.payload, payload)
    own = codec.encode(payload)
    assert np.count_nonzero(own != sent) > 2  # re-encoded, it differs from what was read
    with colliding(codec, blind.reached):
        np.testing.assert_array_equal(codec.encode(payload), sent)
        assert codec.decode(probs).ok  # the collision: its CRC now passes
        other = rng.integers(0, 2, 20).astype(np.uint8)
        np.testing.assert_array_equal(codec.encode(other), PayloadCodec(codec.spec).encode(other))
    np.testing.assert_array_equal(codec.encode(payload), own)  # the codec's own CRC again
    assert not codec.decode(probs).ok


def test_a_word_with_the_printed_payload_and_other_crc_bits_is_not_the_right_word() -> None:
    """The printed word carries its payload's own CRC: a correction that reaches the same
    payload with other CRC bits is a near miss (checked as that code word, the photo shows it
    differs), whose payload is nonetheless right."""
    codec = PayloadCodec(choose_codec(20, 8, 2))
    sent, payload = _a_word_with_a_foreign_crc(codec, np.random.default_rng(5))
    printed = codec.encode(payload)
    blind = crc_blind(codec)
    word = blind.decode(np.where(sent == 1, 0.9, 0.1))
    with colliding(codec, blind.reached):
        code = codec.encode(word.payload)
    assert labels(code, word.payload, printed, payload) == {"right": False, "right_payload": True}
    assert labels(printed, payload, printed, payload) == {"right": True, "right_payload": True}
    other = payload ^ 1
    assert labels(codec.encode(other), other, printed, payload) == {"right": False, "right_payload": False}
