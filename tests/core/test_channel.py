"""The channel a drawing's moves form in photos of its print: the physics a ``--pixels`` plan
starts from (how far each variable moves in pixels, the contrast of its edge, crowding)."""

from __future__ import annotations

import numpy as np
import pytest

from deepmorph_core.channel import (
    amplitude_limited,
    binary_input,
    channel_table,
    information_at,
    payload_within,
    read_channel,
)
from deepmorph_core.codec import choose_codec
from deepmorph_core.morphable import MorphableDrawing
from tests.conftest import make_svg

#: Fewer renders than a plan fits its reading on, of a smaller print: enough to rank drawings.
SAMPLES, PRINT_PX = 800, 120


def strokes(colour: str, move: float) -> bytes:
    """Six strokes and a circle in ``colour``, each point free to move ``move`` units."""
    return make_svg(
        f'<g stroke="{colour}" stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="{move}">'
        '<polyline points="4 6 12 4 20 6"/><polyline points="4 12 12 12 20 12"/>'
        '<polyline points="4 18 12 20 20 18"/><circle cx="12" cy="12" r="3"/>'
        '<polyline points="2 9 2 15"/><polyline points="22 9 22 15"/></g>',
        style='stroke-linejoin="round"',
    )


def test_a_group_read_more_precisely_carries_more_and_never_more_than_its_levels_allow() -> None:
    table = channel_table()
    sigma = np.array([0.03, 0.1, 0.3])
    capacity, dispersion, binary = table(sigma)
    assert list(capacity) == sorted(capacity, reverse=True) and list(binary) == sorted(binary, reverse=True)
    assert np.all(binary <= 1.0 + 1e-9) and np.all(binary <= capacity + 1e-5)  # at 0.3 two levels are best
    assert capacity[0] > 2.0  # a precise reading tells more than two places apart
    assert amplitude_limited(0.1)[0] == pytest.approx(capacity[1], rel=0.02)
    assert binary_input(0.03) == pytest.approx(1.0, abs=1e-3) and np.all(dispersion >= 0)


def test_the_information_of_a_code_grows_with_its_channels_and_a_payload_leaves_room_for_its_crc() -> None:
    assert information_at(0.0, 0.0, 0) == 0.0
    low, high = information_at(30.0, 10.0, 20), information_at(40.0, 10.0, 20)
    assert high == pytest.approx(low + 10.0)  # the dispersion's toll and the word count's are the same
    assert information_at(30.0, 40.0, 20) < low  # a noisier channel keeps a wider margin for 99 %
    payload = payload_within(40.0)
    assert payload + choose_codec(payload, bch_t=0).crc_bits <= 40.0
    assert (payload + 1) + choose_codec(payload + 1, bch_t=0).crc_bits > 40.0
    assert payload_within(3.0) == 0


def test_wider_bounds_and_darker_ink_carry_more_in_photos_of_the_same_print() -> None:
    """The plan depends on each variable's travel in the photo's pixels and on the contrast of
    the edge it moves; a count of readable variables sees neither. (Moves of about a stroke's
    width: the linear reading undervalues far wider ones, see the module's docstring.)"""
    read = {
        key: read_channel(MorphableDrawing.load(strokes(colour, move)), PRINT_PX, samples=SAMPLES)
        for key, (colour, move) in {"black": ("black", 0.6), "narrow": ("black", 0.2), "grey": ("#c8c8c8", 0.6)}.items()
    }
    assert np.median(read["black"].sigma) < np.median(read["narrow"].sigma)
    assert np.median(read["black"].sigma) < np.median(read["grey"].sigma)
    assert read["black"].payload_bits > read["narrow"].payload_bits
    assert read["black"].payload_bits > read["grey"].payload_bits
    assert read["black"].information_bits <= read["black"].capacity_bits + 0.5 * np.log2(len(read["black"].sigma))
    assert all(r.print_px == PRINT_PX and r.visible > 0 for r in read.values())
