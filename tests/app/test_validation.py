"""Validation after training: fresh payloads read from renders and close-up photos, stored in
the bundle, shown by ``info``, warned about when weak; ``deepmorph validate`` for any bundle."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.validation import TARGET_RATE, validate_renders, validation_warning
from deepmorph_core import hookimpl
from deepmorph_core.bundle import PayloadTally, ValidationRecord
from deepmorph_core.errors import PluginError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.plugins import load_registry
from tests.conftest import BUNDLED_MODEL, make_svg

app = application()
TINY = make_svg(
    '<g stroke="black" stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="2.5">'
    '<polyline points="4 6 12 4 20 6"/><line x1="4" y1="12" x2="20" y2="12"/>'
    '<polyline points="4 18 12 20 20 18"/><circle cx="12" cy="12" r="3" dm:move="1.5"/></g>'
)


def test_the_bundled_model_reads_fresh_renders() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    record = validate_renders(model, samples=150, seed=5)
    assert record.name == "renders" and record.samples == 150
    assert record.wrong == 0
    assert record.rate >= 0.96 and record.bit_accuracy > 0.99
    again = validate_renders(model, samples=150, seed=5)
    assert (again.read, again.bit_accuracy) == (record.read, record.bit_accuracy)  # seeded


def test_a_payload_counts_as_read_when_a_vouched_one_is_it_and_as_wrong_when_none_is() -> None:
    sent, other = np.array([1, 0, 1, 1], np.uint8), np.array([1, 0, 1, 0], np.uint8)
    tally = PayloadTally()
    tally.add([], sent)  # nothing vouched for: neither
    assert (tally.read, tally.wrong) == (0, 0)
    tally.add([sent.copy()], sent)
    tally.add([other], sent)
    tally.add([other, sent.copy()], sent)  # several prints in a photo, one of them the code sent
    tally.add(iter([other, other]), sent)
    assert (tally.read, tally.wrong) == (2, 2)


def test_training_ends_with_a_stored_validation(tmp_path: Path) -> None:
    svg = tmp_path / "tiny.svg"
    svg.write_bytes(TINY)
    out = tmp_path / "m.dmm"
    args = ["train", str(svg), "--out", str(out), "--steps", "40", "--payload-bits", "4", "--crc", "16"]
    args += ["--ecc-t", "0", "--image-width", "40", "--batch", "8", "--severity", "none", "--threads", "1"]
    result = CliRunner().invoke(app, [*args, "--validation", "40,3"])
    assert result.exit_code == 0, result.output
    assert "validation: renders (medium): " in result.output and "validation: close-ups (medium): " in result.output
    records = DeepMorphModel.load(out).meta.validation
    assert [(r.name, r.samples) for r in records] == [("renders", 40), ("close-ups", 3)]
    weak = any(r.rate < TARGET_RATE or r.wrong for r in records)
    assert ("warning: " in result.output and "validation read fewer than" in result.output) == weak
    shown = CliRunner().invoke(app, ["info", str(out)])
    assert "validated" in shown.output and "renders (medium)" in shown.output
    as_json = json.loads(CliRunner().invoke(app, ["info", str(out), "--json"]).output)
    assert [r["name"] for r in as_json["validation"]] == ["renders", "close-ups"]


def test_validate_command_prints_and_saves_on_request(tmp_path: Path) -> None:
    bundle = tmp_path / "ghost.dmm"
    shutil.copyfile(BUNDLED_MODEL, bundle)
    assert "none (run `deepmorph validate" in CliRunner().invoke(app, ["info", str(bundle)]).output
    result = CliRunner().invoke(app, ["validate", str(bundle), "--samples", "30", "--photos", "2", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert [r["name"] for r in data["validation"]] == ["renders", "close-ups"] and data["saved"] is False
    assert DeepMorphModel.load(bundle).meta.validation == [] and data["trust"] is None
    args = ["validate", str(bundle), "--samples", "30", "--photos", "0", "--trust", "2", "--save"]
    saved = CliRunner().invoke(app, args)
    assert saved.exit_code == 0, saved.output
    assert "wrong payloads: 2 hard close-ups" in saved.output
    kept = DeepMorphModel.load(bundle)
    assert [r.name for r in kept.meta.validation] == ["renders"]
    assert kept.meta.trust is not None and kept.meta.trust.samples == 2 and kept.meta.trust.crc_bits == (8, 8)
    assert kept.codec.spec == DeepMorphModel.load(BUNDLED_MODEL).codec.spec  # the code is never changed here


def test_bad_validation_counts_are_a_usage_error(tmp_path: Path) -> None:
    svg = tmp_path / "tiny.svg"
    svg.write_bytes(TINY)
    result = CliRunner().invoke(app, ["train", str(svg), "--out", str(tmp_path / "m.dmm"), "--validation", "lots"])
    assert result.exit_code == 2 and "--validation" in result.output
    assert not (tmp_path / "m.dmm").exists()


def test_warning_names_what_fell_short() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    record = validate_renders(model, samples=20, seed=1)
    weak = record.model_copy(update={"read": 10})
    assert validation_warning([record.model_copy(update={"read": 20, "wrong": 0})], "m.dmm") is None
    text = validation_warning([weak], "m.dmm")
    assert text is not None and "renders 10/20 read, 0 wrong" in text and "deepmorph capacity" in text


def test_prints_the_chain_did_not_find_call_for_a_detector_not_fewer_bits() -> None:
    """A close-up that nothing was found in says nothing about what the drawing carries."""
    base = {"name": "close-ups", "description": "", "severity": "medium", "samples": 100, "seconds": 1.0}
    unfound = ValidationRecord(**base, read=90, wrong=0, missed=8, bit_accuracy=0.999)
    text = validation_warning([unfound], "m.dmm")
    assert text is not None and "8 not found" in text and "train-detector" in text and "capacity" not in text
    tuned = validation_warning([unfound], "m.dmm", own_detector=True)  # one was trained: not advised again
    assert tuned is not None and "8 not found" in tuned and "train-detector" not in tuned
    assert "universal detector" in tuned and "deepmorph validate" in tuned
    misread = ValidationRecord(**base, read=90, wrong=0, missed=2, bit_accuracy=0.97)
    text = validation_warning([misread], "m.dmm")
    assert text is not None and "deepmorph capacity" in text and "train-detector" not in text


def test_photos_missed_where_the_renders_read_are_not_blamed_on_the_code() -> None:
    """Renders that read say the code carries: close-ups read a little less are their captures'
    (a smaller code reads as many), so the advice is not fewer bits; a wrong payload still is."""
    renders = ValidationRecord(name="renders", description="", severity="medium", samples=1000, read=999, wrong=0,
                               bit_accuracy=0.99, seconds=1.0)  # fmt: skip
    base = {"name": "close-ups", "description": "", "severity": "medium", "samples": 200, "seconds": 1.0}
    photos = ValidationRecord(**base, read=196, wrong=0, missed=0, bit_accuracy=0.98)
    text = validation_warning([renders, photos], "m.dmm")
    assert text is not None and "close-ups 196/200 read" in text and "not the code's" in text
    assert "--payload-bits" not in text and "renders 999" not in text
    wrong = photos.model_copy(update={"read": 195, "wrong": 1})
    assert "fewer --payload-bits" in validation_warning([renders, wrong], "m.dmm")
    weak_renders = renders.model_copy(update={"read": 970})
    assert "fewer --payload-bits" in validation_warning([weak_renders, photos], "m.dmm")


class _BadValidation:
    @hookimpl
    def deepmorph_validate_model(self, model, samples, seed):  # noqa: ANN001, ANN201 - a broken plugin
        return {"read": 1}


def test_a_plugin_validation_must_return_a_record() -> None:
    import deepmorph_primitives.plugin as builtin

    registry = load_registry([builtin, _BadValidation()], entry_points=False)
    with pytest.raises(PluginError, match="deepmorph_validate_model returned a dict"):
        registry.validate_model(DeepMorphModel.load(BUNDLED_MODEL), 1, 0)


def test_a_print_found_but_not_read_is_not_counted_as_not_found(monkeypatch: pytest.MonkeyPatch) -> None:
    """The universal detector reports only the prints it reads, so an empty result is not a
    print not found: one that aligns counts as not read, which calls for fewer bits, not a
    detector; one that does not align counts as not found."""
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import validate_close_ups

    model = DeepMorphModel.load(BUNDLED_MODEL)
    monkeypatch.setattr(Locator, "locate", lambda self, image, camera=None, soft=True: [])
    record = validate_close_ups(model, 3, 0, "easy", detector="universal")
    assert record.read == 0 and record.missed == 0 and record.bit_accuracy is None
    monkeypatch.setattr(Locator, "aligns", lambda self, image: False)
    assert validate_close_ups(model, 3, 0, "easy", detector="universal").missed == 3


def test_close_ups_narrower_than_a_model_reads_are_not_counted_unless_wrong(monkeypatch: pytest.MonkeyPatch) -> None:
    """A model trained for prints at least ``print_px`` wide refuses narrower ones as too small;
    the simulator makes a few narrower than asked (no pose of that size fitted the frame). Those
    are left out of the count and named in the description, unless they give a wrong payload,
    which counts whatever the print's width."""
    from dataclasses import replace

    import deepmorph_detect.photo_validation as validation
    from deepmorph_detect.locate import Locator

    model = DeepMorphModel.load(BUNDLED_MODEL)
    model.meta.train["print_px"] = 150
    real = validation.close_ups
    shots = list(real(model, 4, 0, "easy"))
    assert all(150 <= shot.width_px <= 210 for shot in shots)  # 200-267 px photos' 60-80 %, head-on
    shrunk = [replace(shot, width_px=120.0) if k < 2 else shot for k, shot in enumerate(shots)]
    monkeypatch.setattr(validation, "close_ups", lambda *args, **kwargs: iter(shrunk))
    record = validation.validate_close_ups(model, 4, 0, "easy")
    assert record.samples == 2 and record.read == 2 and record.wrong == 0
    assert record.description.endswith("; 2 narrower than 150 px not counted")
    locate = Locator.locate

    def misread(self: Locator, image: np.ndarray, camera: object = None, soft: bool = True) -> list:
        found = locate(self, image, camera, soft)
        return [replace(f, result=replace(f.result, payload=1 - f.result.payload, ok=True)) for f in found]

    monkeypatch.setattr(Locator, "locate", misread)
    assert validation.validate_close_ups(model, 4, 0, "easy").wrong == 4


def test_close_ups_validated_by_two_processes_give_the_record_of_one() -> None:
    """Validation's close-ups read by two worker processes give the record one process gives
    (read, wrong, bits, missed), but for its time."""
    from deepmorph_detect.photo_validation import validate_close_ups

    model = DeepMorphModel.load(BUNDLED_MODEL)
    one, two = (validate_close_ups(model, 6, 3, "hard", workers=w) for w in (1, 2))
    assert one.model_dump(exclude={"seconds"}) == two.model_dump(exclude={"seconds"}) and one.read >= 3


def test_a_close_up_carries_the_pose_it_was_photographed_at() -> None:
    """``CloseUp.homography`` is the simulator's pose of the print. There the photo correlates
    with the unmorphed drawing (0.67-0.81 on easy ghost close-ups: the print is morphed), a
    twentieth of the print's width to the side it does not (0.15-0.25), and the chain, aligning
    the photo on its own, ends within 8 % of the print's width of it (2-7 %: it takes part of the
    morph for the pose)."""
    from deepmorph_detect.camera import project, viewbox_corners
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import close_ups
    from deepmorph_detect.refine import LEVELS, aligned_at

    model = DeepMorphModel.load(BUNDLED_MODEL)
    locator = Locator(model)
    template, width = locator.template, LEVELS[-1]
    frame = viewbox_corners(template.viewbox)
    for shot in close_ups(model, 3, 0, "easy"):
        _, _, pyramid = locator.frame(shot.photo, None)
        truth = project(shot.homography, frame)
        across = float(np.linalg.norm(truth[1] - truth[0]))
        aside = np.array([[1.0, 0.0, 0.05 * across], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ shot.homography
        at_truth, beside = (aligned_at(pyramid, H, template, width).correlation for H in (shot.homography, aside))
        assert at_truth > 0.6 and beside < at_truth / 2
        (aligned,) = locator.alignments(shot.photo)
        assert np.linalg.norm(project(aligned.alignment.homography, frame) - truth, axis=1).mean() < 0.08 * across
