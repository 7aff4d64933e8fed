"""The wrong payloads training measures, and the longer CRC a ``--payload-bits auto`` payload
gives bits to (:mod:`deepmorph.training.trust`): the rule, a lengthened model that still reads
its renders, a model that keeps the user's code, the photo chain's count, and a training that
stores and shows the record."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.trust import (
    TRUST_TARGET,
    check_trust,
    crc_for,
    lengthen_crc,
    trust_samples,
    trust_warning,
)
from deepmorph.training.validation import validate_renders
from deepmorph_core.bundle import AutoPayload, TrustRecord
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.codec import COLOUR_CRC, CodecSpec, with_crc
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.close_up_pool import read_close_ups
from deepmorph_detect.photo_validation import close_ups, count_wrong_payloads, payloads_reported
from tests.conftest import make_svg


def record(wrong: int, samples: int = 1000, crc_bits: int = 8, payload_bits: int = 10) -> TrustRecord:
    """A measurement's record: ``wrong`` payloads in ``samples`` close-ups, two CRC bits checked."""
    return TrustRecord(severity="hard", print_px=230, samples=samples, crc_checked=2, wrong=wrong,
                       crc_bits=(crc_bits, crc_bits), payload_bits=(payload_bits, payload_bits), seconds=1.0)  # fmt: skip


def test_the_rule_picks_the_shortest_crc_whose_estimate_meets_the_target() -> None:
    spec = CodecSpec(payload_bits=10, crc_bits=8, bch_t=1)
    assert crc_for(record(0), spec) == 8
    # 1 in 1000 with 2 bits checked: 1e-3 * 2**(2 - c) <= 1e-5 from c = 8.6, and there is no CRC-9
    assert crc_for(record(1), spec) == 10
    assert crc_for(record(5), spec) == 11  # 5e-3 * 2**-9 = 9.8e-6
    assert record(5).wrong_per_read(11) <= TRUST_TARGET < record(5).wrong_per_read(10)
    assert crc_for(record(5), CodecSpec(payload_bits=3, crc_bits=8, bch_t=1)) is None  # 3 bits cannot give 3
    assert crc_for(record(400), spec) is None  # nothing up to 16 bits is enough
    for width in (10, 13, 16):
        longer = with_crc(spec, width)
        assert (longer.payload_bits, longer.crc_bits, longer.code_bits) == (18 - width, width, spec.code_bits)


def test_colour_drawings_are_measured_by_default_and_a_setting_wins() -> None:
    assert trust_samples(None, colour=True) == 600 and trust_samples(None, colour=False) == 0
    assert trust_samples(25, colour=False) == 25 and trust_samples(0, colour=True) == 0


def test_a_lengthened_model_reads_its_renders_and_keeps_its_record(tmp_path: Path) -> None:
    """Payload bits given to the CRC leave the networks as they are: the lengthened model reads
    fresh renders as before, with no wrong payload, and its bundle keeps the code and the record."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    before = validate_renders(model, samples=60, seed=3)
    model.meta.record.payload_auto = AutoPayload()
    lengthened = lengthen_crc(model, record(5, crc_bits=8, payload_bits=24))
    spec = model.codec.spec
    assert (spec.payload_bits, spec.crc_bits, spec.bch_t) == (21, 11, 1) and spec.code_bits == 24 + 8 + spec.ecc_bits
    assert lengthened.crc_bits == (8, 11) and lengthened.payload_bits == (24, 21)
    assert lengthened.wrong_per_read() <= TRUST_TARGET < lengthened.wrong_per_read(8)
    after = validate_renders(model, samples=60, seed=3)
    assert after.wrong == 0 and after.read >= before.read - 1, (before, after)
    model.meta.trust = lengthened
    model.save(tmp_path / "longer.dmm")
    again = DeepMorphModel.load(tmp_path / "longer.dmm")
    assert again.codec.spec == spec and again.meta.trust == lengthened
    assert "lengthened from CRC-8: payload 24 -> 21 bits" in again.info()["trust"]["text"]
    assert DeepMorphModel.load(BUNDLED_MODEL).meta.trust is None  # a bundle from before: none


def test_a_users_payload_keeps_its_code_and_is_warned() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)  # its payload size was the user's
    spec = model.codec.spec
    measured = record(5, crc_bits=8, payload_bits=24)
    assert lengthen_crc(model, measured) == measured and model.codec.spec == spec
    warning = trust_warning(measured, "ghost.dmm")
    assert warning is not None and warning.startswith("ghost.dmm: an estimated 0.78 wrong payloads per 10,000")
    assert trust_warning(record(0), "ghost.dmm") is None
    model.meta.record.payload_auto = AutoPayload(crc_bits=8)  # auto, but the CRC was the user's
    assert lengthen_crc(model, measured) == measured and model.codec.spec == spec


def test_the_chain_counts_wrong_payloads_with_the_crc_checked_on_fewer_bits() -> None:
    """With the whole CRC checked a well-trained model reads its close-ups and gives no wrong
    payload; a count with fewer bits checked leaves the model's own codec as it was."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    whole = count_wrong_payloads(model, 6, seed=2, crc_checked=8, severity="medium")
    assert whole.samples == 6 and whole.wrong == 0 and whole.read >= 5, whole
    count_wrong_payloads(model, 2, seed=2, crc_checked=0, severity="medium")
    assert model.codec._crc_checked == 8 and model.codec._collided is None  # noqa: SLF001 - not changed


def test_close_ups_counted_by_two_processes_count_as_by_one() -> None:
    """The count's close-ups read by two worker processes give each close-up's verdict as one
    process does, in order: the same close-ups read and the same wrong payloads."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    shots = list(close_ups(model, 8, seed=5, severity="hard"))
    narrow = replace(model, codec=model.codec.narrowed(0))  # CRC-blind: wrong words pass too
    one = list(read_close_ups(narrow, shots, payloads_reported, workers=1))
    two = list(read_close_ups(narrow, shots, payloads_reported, workers=2))
    assert one == two and len(one) == 8 and any(right for right, _ in one)
    counted = [count_wrong_payloads(model, 8, seed=5, crc_checked=0, workers=w) for w in (1, 2)]
    assert (counted[0].read, counted[0].wrong) == (counted[1].read, counted[1].wrong)


def test_check_trust_measures_nothing_without_samples_or_crc() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    assert check_trust(model, 0, 0, "ghost", lambda text: None) is None and model.meta.trust is None


#: A small colour drawing (orange strokes on white), quick to train for a few steps.
ORANGE = make_svg(
    """<g stroke="#e67e22" stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="2.5">
  <polyline points="4 6 12 4 20 6"/>
  <line x1="4" y1="12" x2="20" y2="12"/>
  <polyline points="4 18 12 20 20 18"/>
  <circle cx="12" cy="12" r="3" dm:move="1.5"/>
</g>""",
    style='stroke-linejoin="round"',
)


def test_training_stores_and_shows_the_measurement(tmp_path: Path) -> None:
    """``train`` on a colour drawing counts its wrong payloads after its validation where asked
    (``--trust-samples``, whatever the model reads), stores the record, prints it, and ``info``
    shows it. The payload the user sized gets a colour drawing's CRC (12 bits: six checked)."""
    svg = tmp_path / "orange.svg"
    svg.write_bytes(ORANGE)
    out = tmp_path / "orange.dmm"
    app = application()
    args = ["train", str(svg), "--out", str(out), "--steps", "20", "--image-width", "32", "--batch", "4",
            "--threads", "1", "--payload-bits", "2", "--ecc-t", "0", "--validation", "10,2", "--trust-samples", "3",
            "--json"]  # fmt: skip
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    trust = data["trust"]
    assert trust["samples"] == 3 and trust["severity"] == "hard" and trust["crc_checked"] == COLOUR_CRC - 6
    assert DeepMorphModel.load(out).codec.spec.crc_bits == COLOUR_CRC and trust["crc_bits"] == [12, 12]
    assert trust["payload_bits"][1] == data["payload_bits"] == DeepMorphModel.load(out).codec.spec.payload_bits
    stored = DeepMorphModel.load(out).meta.trust
    assert stored is not None and stored.model_dump(mode="json") == trust
    res = CliRunner().invoke(app, ["info", str(out)])
    assert res.exit_code == 0 and "wrong payloads" in res.stdout and "3 hard close-ups" in res.stdout
    info = json.loads(CliRunner().invoke(app, ["info", str(out), "--json"]).stdout)
    assert info["trust"]["samples"] == 3 and info["trust"]["text"] == stored.describe()
