"""Capacity before training: what a drawing carries, what limits it, and ``--payload-bits auto``."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.code_shrink import SHRINK_BELOW, SHRINK_BELOW_AT_PIXELS, shrink_below
from deepmorph.training.codec import train_model
from deepmorph_core.capacity import (
    CHANNEL_SHARE,
    CODE_BITS_PER_GROUP,
    COLOUR_CRC,
    COLOUR_KEPT,
    ECC_CHOICES,
    FOUND_ENOUGH,
    LARGEST_CODE_MEASURED,
    PIXELS_MEASURED,
    CapacityReport,
    code_bits_for,
    default_crc_code,
    for_print,
    largest_payload,
    payload_for_width,
    plan_code,
    predict,
    size_warning,
    with_channel,
)
from deepmorph_core.codec import choose_codec
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.morphable import MorphableDrawing
from tests.conftest import FEATHER, make_svg

app = application()

#: Strokes with generous bounds; the middle point of the straight polyline moving along it
#: changes nothing a renderer shows.
DRAWING = make_svg(
    '<g stroke="black" stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="2.5">'
    '<polyline points="4 6 12 4 20 6"/><polyline points="4 12 12 12 20 12"/>'
    '<polyline points="4 18 12 20 20 18"/><circle cx="12" cy="12" r="3" dm:move="1.5"/>'
    '<polyline points="2 9 2 15" dm:move="1.5"/><polyline points="22 9 22 15" dm:move="1.5"/></g>',
    style='stroke-linejoin="round"',
)


@pytest.fixture(scope="module")
def drawing_svg(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cap") / "drawing.svg"
    path.write_bytes(DRAWING)
    return path


def test_prediction_counts_readable_variables_and_names_what_limits_them() -> None:
    md = MorphableDrawing.load(DRAWING)
    report = predict(md)
    assert report.n_variables == 28 and report.visible == 27  # the straight middle point's x
    assert report.readable_groups <= report.visible
    assert report.code_bits == int(CODE_BITS_PER_GROUP * report.readable_groups)
    assert report.codec is not None and report.codec.code_bits <= report.code_bits
    assert report.payload_bits == report.codec.payload_bits > 0
    bigger = largest_payload(report.code_bits + 12)
    assert bigger is not None and bigger.payload_bits > report.payload_bits  # more bits, more payload
    limits = " ".join(report.limits())
    assert "1 of 28 variables change nothing a renderer shows" in limits and "shape 1 (<polyline>" in limits


def test_the_prediction_grows_with_readable_groups_up_to_the_largest_code_measured() -> None:
    bits = [code_bits_for(groups) for groups in range(0, 200)]
    assert bits == sorted(bits) and bits[0] == 0
    assert bits[40] == int(CODE_BITS_PER_GROUP * 40) and max(bits) == LARGEST_CODE_MEASURED


def test_a_model_trained_for_wide_prints_is_planned_from_its_channel_there() -> None:
    """``--pixels`` of at least :data:`PIXELS_MEASURED`: a share of what photos of a print that
    wide let a linear reading carry, in codes correcting two errors (those measured); narrower,
    the 96-px figure stands."""
    md = MorphableDrawing.load(DRAWING)
    plain = predict(md)
    wide = predict(md, print_px=250)
    assert plain.channel_payload is None and wide.channel_payload is not None
    assert wide.readable_groups == plain.readable_groups and wide.print_px == 250 and plain.print_px is None
    share = math.floor(CHANNEL_SHARE * wide.channel_payload)
    assert wide.codec is not None and wide.codec.bch_t == 2 and wide.code_bits == wide.codec.code_bits
    assert wide.payload_bits == share > plain.payload_bits
    assert any(f"carry {wide.channel_payload} payload bits" in line for line in wide.limits())
    assert predict(md, print_px=PIXELS_MEASURED - 1) == plain  # not measured below, and no channel read
    # the same plan from the readable groups and the channel, with no new renders
    with pytest.raises(ValueError, match="needs the drawing's channel"):
        for_print(plain, 250)
    measured = with_channel(plain, md)
    assert for_print(measured, 250) == wide and for_print(wide, None) == measured
    assert with_channel(measured, md) is measured  # measured once
    assert for_print(measured, 250, ecc=(1,)).codec.bch_t == 1  # a user's own BCH strength is kept
    # per print width: too small, the default training, or a model trained for 200 px
    assert payload_for_width(measured, 80, 96) == (None, None)
    assert payload_for_width(measured, 150, 96) == (plain.payload_bits, None)
    assert payload_for_width(measured, 300, 96) == (wide.payload_bits, 200)
    assert payload_for_width(plain, 300, 96) == (None, 200)  # a model for 200 px, its channel not measured yet
    assert with_channel(plain, md, measure=False) == measured  # the measurement this process kept
    assert ECC_CHOICES == (2, 1)


def test_a_code_is_shrunk_by_the_share_its_own_kind_of_training_reads() -> None:
    """A ``--pixels`` model's batches are the camera at its narrowest print, with hard captures:
    far harsher than its close-ups, so its code is judged by a lower share."""
    assert shrink_below(None) == SHRINK_BELOW == 0.9
    assert shrink_below(200) == SHRINK_BELOW_AT_PIXELS < SHRINK_BELOW


def test_a_drawing_with_more_readable_variables_than_measured_is_told_where_the_prediction_stops() -> None:
    strokes = "".join(f'<polyline points="{2 + x} 2 {3 + x} 12 {2 + x} 22"/>' for x in range(20))
    crowded = make_svg(f'<g stroke="black" stroke-width="0.5" fill="none" dm:move="0.8">{strokes}</g>')
    report = predict(MorphableDrawing.load(crowded))
    assert report.readable_groups * CODE_BITS_PER_GROUP > LARGEST_CODE_MEASURED
    assert report.code_bits == LARGEST_CODE_MEASURED
    assert any(f"stops at {LARGEST_CODE_MEASURED} code bits" in line for line in report.limits())


def test_every_payload_size_that_fits_is_the_largest() -> None:
    for code_bits in range(10, 70, 3):
        spec = largest_payload(code_bits)
        if spec is None:
            assert all(choose_codec(p, None, 1).code_bits > code_bits for p in (1, 2))
            continue
        assert spec.code_bits <= code_bits
        for t in (1, 2):
            try:
                assert choose_codec(spec.payload_bits + 1, None, t).code_bits > code_bits
            except DeepMorphError:
                pass


def test_a_feather_icon_with_few_readable_variables_is_told_so() -> None:
    md = MorphableDrawing.load(FEATHER / "camera.svg", move=0.48)
    report = predict(md)
    assert report.visible < report.n_variables and report.payload_bits == 0 and report.codec is None
    warning = size_warning(choose_codec(24), report, "camera.svg")
    assert warning is not None and "no payload is predicted to read reliably" in warning


def test_capacity_command_table_and_json(drawing_svg: Path) -> None:
    shown = CliRunner().invoke(app, ["capacity", str(drawing_svg)])
    assert shown.exit_code == 0, shown.output
    text = " ".join(shown.output.split())
    assert "28 (27 visible, 1 change nothing a renderer shows)" in text and "--payload-bits auto" in text
    data = json.loads(CliRunner().invoke(app, ["capacity", str(drawing_svg), "--json"]).output)
    assert data["n_variables"] == 28 and data["payload_bits"] == data["codec"]["payload_bits"]
    assert data["limits"] and data["elements"][1]["kind"] == "polyline"


def test_auto_trains_the_predicted_size_and_a_short_training_reads_it(drawing_svg: Path, tmp_path: Path) -> None:
    """The prediction is a real number: a short training at that size reads fresh payloads."""
    predicted = predict(MorphableDrawing.load(DRAWING)).codec
    out = tmp_path / "auto.dmm"
    summary = train_model(
        drawing_svg,
        out,
        payload_bits="auto",
        train={"steps": 500, "width": 40, "batch": 16, "threads": 1, "log_every": 50, "renders_tune": 0},
        validation_samples=(300, 0),
    )
    model = DeepMorphModel.load(out)
    assert model.codec.spec == predicted
    (renders,) = summary.validation
    assert renders.wrong == 0 and renders.rate >= 0.97, renders


def test_a_size_above_the_prediction_is_warned_about_before_training(drawing_svg: Path, tmp_path: Path) -> None:
    args = ["train", str(drawing_svg), "--steps", "1", "--image-width", "32", "--batch", "2", "--threads", "1"]
    args += ["--validation", "0"]
    big = CliRunner().invoke(app, [*args, "--payload-bits", "40", "--out", str(tmp_path / "big.dmm")])
    text = " ".join(big.output.split())
    assert big.exit_code == 0 and "warning:" in text and "a 40-bit payload needs" in text
    assert "the largest predicted to read is" in text
    small = CliRunner().invoke(app, [*args, "--payload-bits", "4", "--out", str(tmp_path / "small.dmm")])
    assert small.exit_code == 0 and "warning" not in small.output


def test_auto_refuses_a_drawing_that_carries_nothing(tmp_path: Path) -> None:
    camera = tmp_path / "camera.svg"
    camera.write_bytes((FEATHER / "camera.svg").read_bytes())
    result = CliRunner().invoke(
        app, ["train", str(camera), "--move", "0.48", "--payload-bits", "auto", "--out", str(tmp_path / "c.dmm")]
    )
    assert result.exit_code == 1 and "no payload is predicted to read" in result.output
    assert not (tmp_path / "c.dmm").exists()
    bad = CliRunner().invoke(app, ["train", str(camera), "--payload-bits", "lots", "--out", str(tmp_path / "c.dmm")])
    assert bad.exit_code == 2


def test_a_plan_for_wide_prints_stops_at_the_largest_code_measured() -> None:
    """A channel far above anything measured (a crowded colour emoji's) plans no more code bits
    than the 96-px plan may, and says so."""
    md = MorphableDrawing.load(DRAWING)
    huge = replace(with_channel(predict(md), md), channel_payload=400)
    wide = for_print(huge, 250)
    assert wide.codec is not None and wide.codec.bch_t == 2
    assert wide.code_bits <= LARGEST_CODE_MEASURED  # the largest t = 2 code within it
    assert choose_codec(wide.payload_bits + 1, None, 2).code_bits > LARGEST_CODE_MEASURED
    assert wide.payload_bits < math.floor(CHANNEL_SHARE * 400)
    assert any(f"stops at {LARGEST_CODE_MEASURED} code bits" in line for line in wide.limits())
    plain = for_print(replace(huge, channel_payload=40), 250)  # within it: the share, and no such line
    assert plain.payload_bits == math.floor(CHANNEL_SHARE * 40)
    assert not any("stops at" in line for line in plain.limits())


def test_a_colour_drawings_plan_says_how_much_training_kept_of_such_plans() -> None:
    """The count of shapes that show overshoots colour drawings (faint edges in a photo): the
    report says by how much, where a black-and-white one does not."""
    coloured = DRAWING.replace(b'stroke="black"', b'stroke="#1f4e9c"')  # a dark blue
    report = predict(MorphableDrawing.load(coloured))
    assert report.colour and report.payload_bits > 0
    least, median, most = COLOUR_KEPT
    assert 0 < least <= median <= most <= 1
    assert any(f"training kept {least:.2f}-{most:.2f} of it" in line for line in report.limits())
    assert report.to_json()["colour"] is True
    plain = predict(MorphableDrawing.load(DRAWING))
    assert not plain.colour and not any("colour drawing's plan" in line for line in plain.limits())


def test_a_colour_plan_gives_payload_bits_to_a_longer_crc_in_the_same_code() -> None:
    """A colour drawing's plan has the black drawing's code bits and BCH, with payload bits given
    to CRC-12 (where the CRC is DeepMorph's): at 96 px, for wide prints and in the width table;
    its limits say why. A CRC the user chose, and black ink, keep the codec's."""
    coloured = MorphableDrawing.load(DRAWING.replace(b'stroke="black"', b'stroke="#1f4e9c"'))
    black = MorphableDrawing.load(DRAWING)
    for_colour, for_black = predict(coloured), predict(black)
    assert for_colour.codec is not None and for_black.codec is not None
    assert for_black.codec.crc_bits == 8 and for_colour.codec.crc_bits == COLOUR_CRC
    assert for_colour.code_bits == for_black.code_bits and for_colour.codec.code_bits == for_black.codec.code_bits
    assert for_colour.payload_bits == for_black.payload_bits - (COLOUR_CRC - 8)
    assert for_colour.codec.bch_t == for_black.codec.bch_t
    assert any(f"CRC of {COLOUR_CRC} (black ink: 8)" in line for line in for_colour.limits())
    assert not any("black ink: 8" in line for line in for_black.limits())
    wide = for_print(replace(for_colour, channel_payload=40), 250)
    assert wide.codec is not None and wide.codec.crc_bits == COLOUR_CRC
    assert wide.payload_bits == math.floor(CHANNEL_SHARE * 40) - (COLOUR_CRC - 8)  # the same information
    assert not any("stops at" in line for line in wide.limits())
    assert payload_for_width(replace(for_colour, channel_payload=40), 250, 96)[0] == wide.payload_bits
    chosen = predict(coloured, crc_bits=8)  # the user's CRC stands
    assert chosen.codec is not None and chosen.codec.crc_bits == 8
    own_12 = predict(coloured, crc_bits=COLOUR_CRC)  # the user's CRC-12: nothing was given to it
    assert own_12.codec is not None and own_12.codec.crc_bits == COLOUR_CRC and own_12.crc_bits == COLOUR_CRC
    assert not any("black ink: 8" in line for line in own_12.limits())
    assert not any("black ink: 8" in line for line in for_print(replace(own_12, channel_payload=40), 250, 12).limits())
    large = replace(for_colour, codec=choose_codec(40, None, 2))  # CRC-16: black ink's too above 32 bits
    assert not any("black ink: 8" in line for line in large.limits())


@pytest.mark.parametrize(
    ("payload", "crc", "planned"),
    [(16, 8, (12, 12)), (3, 8, (1, 10)), (4, 8, (1, 11)), (1, 8, (1, 8)), (40, 16, (40, 16))],
)
def test_a_colour_code_takes_the_longest_crc_up_to_colour_crc_that_leaves_a_payload_bit(
    payload: int, crc: int, planned: tuple[int, int]
) -> None:
    """The plan's CRC for colour: up to COLOUR_CRC bits, never the last payload bit, never
    shorter than the codec's; the code's size stays and the code it came from is recovered."""
    spec = choose_codec(payload, crc, 2)
    colour = plan_code(spec, colour=True)
    assert (colour.payload_bits, colour.crc_bits) == planned
    assert colour.code_bits == spec.code_bits and colour.bch_t == spec.bch_t
    assert default_crc_code(colour) == spec
    assert plan_code(spec, colour=False) == spec and plan_code(spec, colour=True, crc_bits=crc) == spec


def test_a_drawing_the_chain_found_too_seldom_is_called_out() -> None:
    """`limits` names a drawing found in fewer than FOUND_ENOUGH of its simulated hard photos,
    and says nothing where it was found often enough or not simulated."""
    just_enough = math.ceil(FOUND_ENOUGH * 40)

    def said(found: tuple[int, int] | None) -> bool:
        report = CapacityReport(10, 10, 10, 7, 4, None, colour=True, found=found)
        return any("simulated hard photos" in line for line in report.limits())

    assert said((just_enough - 1, 40)) and not said((just_enough, 40)) and not said(None)
