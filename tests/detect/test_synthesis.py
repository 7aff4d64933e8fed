"""Code bits read and checked by synthesis (deepmorph_detect.synthesis), on the bundled model,
real resvg renders and simulated photos."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.codec import DecodeResult, PayloadCodec
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import random_payloads
from deepmorph_core.photo import to_gray
from deepmorph_core.render import render_svg
from deepmorph_detect.check import MorphFit, PayloadCheck
from deepmorph_detect.fusion import FrameFuser
from deepmorph_detect.locate import Locator
from deepmorph_detect.read import Reader, Reading
from deepmorph_detect.refine import ImagePyramid
from deepmorph_detect.scenes import SceneMaker
from deepmorph_detect.synthesis import (
    BIT_RULES,
    MAX_CONTRADICTED,
    MAX_DEVIATION,
    MIN_WEAKEST_SUM,
    WEAKEST_BITS,
    BitEvidence,
    GridLight,
    MorphSynthesis,
    _blurred,
    broken_rules,
    disagreement,
    disagreement_in,
)

app = application()  # the command line's own commands and every installed plugin's

runner = CliRunner()
PHOTOS = Path(__file__).parent.parent / "data" / "photos"


def _small_print(model: DeepMorphModel, payload: np.ndarray, width: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A blurred, noisy photo of a print ``width`` px wide, and its homography (SVG -> px)."""
    page = np.ones((width * 2, width * 2), np.float32)
    page[width // 2 : width // 2 + width, width // 2 : width // 2 + width] = render_svg(model.encode(payload), width)
    page = cv2.GaussianBlur(page, (0, 0), 0.8) * 0.7 + 0.15
    page += np.random.default_rng(seed).normal(0, 0.02, page.shape).astype(np.float32)
    x, y, vw, _ = model.drawing.drawing.viewbox
    s = width / vw
    H = np.array([[s, 0, width / 2 - x * s], [0, s, width / 2 - y * s], [0, 0, 1]])
    return np.clip(page, 0, 1), H


def _near_payloads(payload: np.ndarray) -> list[np.ndarray]:
    """Every payload one bit away: each has a valid CRC and a code word several bits away."""
    out = []
    for j in range(len(payload)):
        near = payload.copy()
        near[j] ^= 1
        out.append(near)
    return out


def test_the_photo_confirms_every_bit_of_its_code_word_and_contradicts_a_near_one(
    model: DeepMorphModel, locator: Locator
) -> None:
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(3))[0]
    photo, H = _small_print(model, payload, 80, seed=1)
    pyramid = ImagePyramid(photo)
    true_code = model.codec.encode(payload)
    said = locator.checker.synthesis.evidence(pyramid, H, true_code)
    assert said.contradicted == 0 and said.agrees and said.fit > 0.9
    assert np.median(said.evidence) == pytest.approx(1.0, abs=0.3)  # +1: the photo shows the word's bit
    assert model.codec.rival_margin(true_code, said.evidence) >= 1.0  # no other word near
    for near in _near_payloads(payload)[:4]:
        code = model.codec.encode(near)
        differs = code != true_code
        assert differs.sum() >= 4
        fit = locator.checker.fit_morph(pyramid, H, near)  # aligned to its own morph, as the check does
        said = locator.checker.synthesis.evidence(pyramid, fit.homography, code)
        assert not said.agrees and said.contradicted > MAX_CONTRADICTED
        assert model.codec.rival_margin(code, said.evidence) < 0  # the printed word is likelier
        # the bits seen flipped are mostly the ones that differ from the printed word
        flipped = said.evidence < 0
        assert flipped[differs].mean() >= 0.5 > flipped[~differs].mean() + 0.25


def test_reading_by_synthesis_corrects_confident_misreadings(model: DeepMorphModel, locator: Locator) -> None:
    """70 px prints whose CNN readings have 6 confidently wrong bits each (BCH corrects 1)."""
    rng = np.random.default_rng(8)
    read_whole, errors = 0, []
    for payload in random_payloads(4, model.codec.spec.payload_bits, rng):
        photo, H = _small_print(model, payload, 70, seed=int(payload.sum()))
        code = model.codec.encode(payload)
        probs = np.where(code == 1, 0.9, 0.1).astype(np.float32)
        wrong = rng.choice(len(code), 6, replace=False)
        probs[wrong] = np.where(code[wrong] == 1, 0.03, 0.97)
        assert not model.codec.decode(probs, soft=False).ok
        read = locator.synthesis.read(ImagePyramid(photo), H, probs)
        errors.append(int(((read > 0.5) != (code == 1)).sum()))
        result = model.codec.decode(read, soft=False)
        assert not result.ok or np.array_equal(result.payload, payload)  # never another payload
        read_whole += result.ok
    assert read_whole >= 3 and np.mean(errors) <= 1.5, errors


@pytest.mark.parametrize("icon", ["anchor", "camera", "umbrella"])
def test_reading_by_synthesis_stops_after_one_round_on_another_drawing(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch, icon: str
) -> None:
    """A print of another drawing where the ghost would be leaves the photo unexplained by any
    word of the ghost's: one round asks it (``HOPELESS_DEVIATION``), not ``READ_ROUNDS``."""
    from deepmorph_detect.synthesis import HOPELESS_DEVIATION

    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(4))[0]
    photo, H = _small_print(model, payload, 70, seed=4)
    other = render_svg((Path(__file__).parent.parent / "data" / "feather" / f"{icon}.svg").read_text(), 70)
    photo[35:105, 35:105] = np.clip(cv2.GaussianBlur(other, (0, 0), 0.8) * 0.7 + 0.15, 0, 1)
    asked: list[float] = []
    evidence = locator.synthesis.evidence
    monkeypatch.setattr(
        locator.synthesis, "evidence", lambda *a: (lambda found: asked.append(found.deviation) or found)(evidence(*a))
    )
    probs = np.where(model.codec.encode(payload) == 1, 0.9, 0.1).astype(np.float32)
    locator.synthesis.read(ImagePyramid(photo), H, probs)
    assert len(asked) == 1 and asked[0] > HOPELESS_DEVIATION, asked


def test_the_locator_reads_by_synthesis_when_no_view_passes_the_crc(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene = SceneMaker(model, severity="easy", seed=21).make(drawings=1)
    truth = scene.placements[0]
    code = model.codec.encode(truth.payload)
    wrong = np.random.default_rng(0).choice(len(code), 5, replace=False)
    misread = np.where(code == 1, 0.95, 0.05).astype(np.float32)
    misread[wrong] = np.where(code[wrong] == 1, 0.02, 0.98)
    # every CNN reading, first and second looks, has the same five confident errors
    monkeypatch.setattr(
        Reader, "read", lambda self, view, soft, moments=None: Reading(model.codec.decode(misread, soft=False), misread)
    )
    (det,) = locator.locate(scene.image, camera=scene.camera)
    assert det.result.ok and np.array_equal(det.result.payload, truth.payload)
    assert det.morph_check == "passed" and det.bits is not None and det.bits.agrees  # always checked bit by bit
    data = det.to_json()
    assert data["bits_contradicted"] == det.bits.contradicted
    assert data["weakest_bits_support"] == pytest.approx(det.bits.weakest_sum, abs=1e-3)
    assert data["weakest_bits_support"] >= MIN_WEAKEST_SUM


def test_a_near_miss_that_passes_the_crc_and_the_morph_check_is_contradicted(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A CRC collision one payload bit from the truth, after corrections: one correlation over
    the whole drawing often cannot tell its morph from the true one; the bits can."""
    scene = SceneMaker(model, severity="medium", seed=4).make(drawings=1)
    truth = scene.placements[0]
    (det,) = locator.locate(scene.image, camera=scene.camera)
    assert det.result.ok and np.array_equal(det.result.payload, truth.payload) and det.morph_check == "passed"
    pyramid = ImagePyramid(to_gray(scene.image))
    passing = [
        p
        for p in _near_payloads(truth.payload)
        if (f := locator.checker.fit_morph(pyramid, det.homography, p)) and f.confirms
    ]
    assert passing, "no near miss passes the whole-drawing morph check on this print"
    near = passing[0]
    real_decode = model.codec.decode

    def collide(self_or_probs, *args, **kw):  # works as a bound or an unbound codec method
        probs = args[0] if isinstance(self_or_probs, PayloadCodec) else self_or_probs
        return replace(real_decode(probs, soft=False), payload=near, ok=True, corrected_bits=2)

    monkeypatch.setattr(model.codec, "decode", collide)
    (det,) = locator.locate(scene.image, camera=scene.camera)
    data = det.to_json()
    assert not det.result.ok and data["ok"] is False and data["morph_check"] == "contradicted"
    assert data["bits_contradicted"] > MAX_CONTRADICTED and data["pose_aligned_to"] == "unmorphed drawing"
    # the true payload, read with corrections, passes the same check
    monkeypatch.setattr(
        model.codec, "decode", lambda probs, soft=True: replace(real_decode(probs, soft=soft), corrected_bits=1)
    )
    (det,) = locator.locate(scene.image, camera=scene.camera)
    assert det.result.ok and det.morph_check == "passed" and det.bits is not None and det.bits.agrees
    # and the command line says why a payload is not verified
    cv2.imwrite(str(tmp_path / "photo.png"), scene.image)
    monkeypatch.setattr(PayloadCodec, "decode", collide)
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(tmp_path / "photo.png")])
    assert res.exit_code == 4 and "code bits flipped" in " ".join(res.output.split()), res.output


def test_a_collision_read_without_corrections_but_unsure_is_checked_bit_by_bit(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A misread that lands on a valid code word needs no corrections, but its wrong bits pull
    its confidence down: below ``CHECK_BELOW_CONFIDENCE`` it is checked bit by bit and caught,
    while a confident reading without corrections is not checked (about 50 ms saved)."""
    from deepmorph_detect.check import CHECK_BELOW_CONFIDENCE

    scene = SceneMaker(model, severity="medium", seed=4).make(drawings=1)
    truth = scene.placements[0]
    pyramid = ImagePyramid(to_gray(scene.image))
    (det,) = locator.locate(scene.image, camera=scene.camera)
    near = next(
        p
        for p in _near_payloads(truth.payload)
        if (f := locator.checker.fit_morph(pyramid, det.homography, p)) and f.confirms
    )
    real_decode = model.codec.decode
    reading = replace(real_decode(det.probabilities, soft=False), payload=near, ok=True, corrected_bits=0)

    unsure = locator.check_payload(pyramid, det.homography, replace(reading, confidence=CHECK_BELOW_CONFIDENCE - 0.05))
    assert unsure.status == "contradicted" and not unsure.result.ok and unsure.bits.contradicted > MAX_CONTRADICTED
    sure = locator.check_payload(pyramid, det.homography, replace(reading, confidence=0.995))
    assert sure.status == "passed" and sure.bits is None  # the morph check alone, as before
    # the true payload read as unsurely passes the same check
    right = replace(reading, payload=truth.payload, confidence=CHECK_BELOW_CONFIDENCE - 0.05)
    checked = locator.check_payload(pyramid, det.homography, right)
    assert checked.status == "passed" and checked.bits is not None and checked.bits.agrees


def test_a_repair_the_decoder_is_sure_of_skips_the_per_bit_check(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A word the code corrected within its ``t`` is checked bit by bit unless it is read
    confidently, the decoder's own probabilities prefer it to every other code word by
    ``TRUSTED_REPAIR_LOG_ODDS`` and its morph fits the photo as only prints of the drawing do
    (``TRUSTED_MORPH_FIT``); and only for a black-and-white drawing trained for the print's
    pixels, and for one that looks the same turned only where no other turn's first look read a
    word that passes the CRC (other decoders, and a symmetric drawing read at the wrong turn, read
    wrong words as surely)."""
    from deepmorph_detect.check import (
        CHECK_BELOW_CONFIDENCE,
        TRUSTED_MORPH_FIT,
        TRUSTED_REPAIR_LOG_ODDS,
        is_trusted_repair,
    )

    scene = SceneMaker(model, severity="medium", seed=4).make(drawings=1)
    truth = scene.placements[0]
    pyramid = ImagePyramid(to_gray(scene.image))
    (det,) = locator.locate(scene.image, camera=scene.camera)
    repaired = DecodeResult(truth.payload, True, 1, 0.99, rival_log_odds=TRUSTED_REPAIR_LOG_ODDS + 5)
    assert model.print_px is None  # the ghost reads from a 96-px frame: its repairs go bit by bit
    as_trained = locator.check_payload(pyramid, det.homography, repaired)
    assert as_trained.status == "passed" and as_trained.bits is not None
    assert not as_trained.vouched and not as_trained.settled  # the other turns may still beat it
    monkeypatch.setattr(type(model), "print_px", property(lambda self: 200))  # as if trained with --pixels 200
    sure = locator.check_payload(pyramid, det.homography, repaired)
    assert sure.fit.correlation >= TRUSTED_MORPH_FIT
    assert sure.status == "passed" and sure.bits is None  # the morph check alone
    assert sure.vouched and sure.settled  # and no other turn of the print is read
    t = model.codec.spec.bch_t
    doubts = [
        replace(repaired, rival_log_odds=TRUSTED_REPAIR_LOG_ODDS - 5),
        replace(repaired, confidence=CHECK_BELOW_CONFIDENCE - 0.01),
        replace(repaired, corrected_bits=t + 1),
    ]
    for doubt in doubts:
        checked = locator.check_payload(pyramid, det.homography, doubt)
        assert checked.bits is not None and not checked.vouched and not checked.settled
    # nor where the morph fits as other drawings can align, nor without corrections
    assert not is_trusted_repair(repaired, TRUSTED_MORPH_FIT - 0.01, t)
    assert not is_trusted_repair(replace(repaired, corrected_bits=0), 0.99, t)
    # nor for a drawing that looks the same turned: at the wrong turn its true morph turned reads
    # as another word as surely; unless no other turn's first look read a word
    with monkeypatch.context() as m:
        m.setattr(locator.checker.template, "symmetric_turns", (np.eye(3),))
        assert locator.check_payload(pyramid, det.homography, repaired).bits is not None
        unrivalled = locator.checker.check(pyramid, det.homography, repaired, unrivalled_turn=True)
        assert unrivalled.vouched and unrivalled.bits is None
    assert locator.check_payload(pyramid, det.homography, repaired).bits is None
    monkeypatch.setattr(type(model.drawing), "colour", property(lambda self: True))
    in_colour = locator.check_payload(pyramid, det.homography, repaired)
    assert in_colour.bits is not None


def test_a_weak_word_passes_on_its_corrected_and_least_sure_bits_and_a_near_miss_takes_the_whole_check(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A weak word of a black-and-white `--pixels` model is first asked about the bits the code
    corrected and the ``SCREEN_LEAST_SURE`` its decoder was least sure of: the true word passes
    there without the whole per-bit check; a near miss, which differs where the code corrected,
    does not, and the whole check contradicts it. Not asked without the decoder's probabilities,
    nor of a model trained for a 96-px frame or in colour."""
    from deepmorph_detect.check import SCREEN_LEAST_SURE

    scene = SceneMaker(model, severity="medium", seed=4).make(drawings=1)
    truth = scene.placements[0]
    pyramid = ImagePyramid(to_gray(scene.image))
    (det,) = locator.locate(scene.image, camera=scene.camera)
    code = model.codec.encode(truth.payload)
    # the decoder's probabilities: the true word's bits, more or less sure, the least sure misread
    sure = np.random.default_rng(2).uniform(0.6, 0.99, len(code))
    probabilities = np.where(code > 0, sure, 1 - sure).astype(np.float32)
    probabilities[5] = 0.55 if code[5] == 0 else 0.45
    weak = DecodeResult(truth.payload, True, 1, 0.9, rival_log_odds=3.0)

    def checked(result: DecodeResult, probs: np.ndarray | None = probabilities) -> PayloadCheck:
        return locator.checker.check(pyramid, det.homography, result, probabilities=probs)

    assert checked(weak).bits is not None  # the ghost reads from a 96-px frame: the whole check
    monkeypatch.setattr(type(model), "print_px", property(lambda self: 200))  # as if trained with --pixels 200
    right = checked(weak)
    assert right.status == "passed" and right.screened and right.bits is None and not right.settled
    assert checked(weak, None).bits is not None  # without the decoder's probabilities: the whole check
    asked: list[np.ndarray] = []
    drawn_on = locator.checker.synthesis.drawn_on
    monkeypatch.setattr(
        locator.checker.synthesis, "drawn_on", lambda *a, **k: asked.append(np.asarray(a[3])) or drawn_on(*a, **k)
    )
    near = next(
        p
        for p in _near_payloads(truth.payload)
        if (f := locator.checker.fit_morph(pyramid, det.homography, p)) and f.confirms
    )
    differ = np.flatnonzero(model.codec.encode(near) != code)
    missed = checked(replace(weak, payload=near, corrected_bits=1))
    # the near miss was asked where it differs from what the decoder read, and failed there
    assert set(differ) <= set(asked[0].tolist()) and len(asked[0]) <= len(differ) + SCREEN_LEAST_SURE
    assert missed.status == "contradicted" and not missed.screened and missed.bits is not None
    monkeypatch.setattr(type(model.drawing), "colour", property(lambda self: True))
    assert not checked(weak).screened


def test_a_word_the_photo_barely_supports_does_not_pass_the_bits() -> None:
    """Two bits contradicted is allowed; not when several more are barely supported (the
    evidence on a blurred, steeply tilted print is noise of about +-0.6)."""
    clear = np.ones(38, np.float32)
    clear[[3, 17]] = -0.9  # two bits misread on a sharp print: the rest is clearly shown
    assert BitEvidence(np.zeros(38, np.uint8), clear, 0.9, 1.0).agrees
    vague = clear.copy()
    vague[[3, 17, 5, 8, 21, 30]] = [-0.74, -0.08, 0.14, 0.24, 0.34, 0.34]  # the regression photo's
    said = BitEvidence(np.zeros(38, np.uint8), vague, 0.82, 1.0)
    assert said.contradicted <= MAX_CONTRADICTED  # the count alone would pass it
    assert said.weakest_sum == pytest.approx(-0.74 - 0.08 + 0.14 + 0.24 + 0.34, abs=1e-5)
    assert not said.agrees and WEAKEST_BITS == 5 and said.weakest_sum < MIN_WEAKEST_SUM
    # and the reason given is the half of the rule that failed, not a count of flipped bits
    assert said.reason == "the photo barely shows its 5 weakest code bits (support -0.10, at least 0.5 needed)"
    assert BitEvidence(np.zeros(38, np.uint8), clear, 0.9, 1.0).reason == ""
    assert said.broken == ("weakest bits",) and BitEvidence(np.zeros(38, np.uint8), clear, 0.9, 1.0).broken == ()
    assert replace(said, runner_up_passes=True).broken == ("weakest bits", "runner-up")
    assert disagreement(3, 2.0, 0.2) == "the photo shows 3 of its code bits flipped"
    # every rule a word breaks, by name and in the order asked (the first is the reason given)
    assert broken_rules(3, -1.0, 1.5, 0.4, 1.0, True, True) == BIT_RULES
    assert BIT_RULES == ("bits flipped", "weakest bits", "unexplained", "rival", "runner-up", "realigned")
    assert broken_rules(0, -1.0, 1.5) == ("weakest bits", "unexplained") and broken_rules(2, 5.0, 1.0, 1.0) == ()
    assert disagreement(0, 5.0, 0.5, 0.3).startswith("the nearest other code word explains the photo better")


def test_a_word_with_a_few_bits_shown_flipped_is_withdrawn_however_far_its_rivals(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Three bits shown weakly flipped fail the bit rules, even where every other code word needs
    more evidence than that doubt: such rescues passed wrong words of small prints in hard scenes
    (the true word explained the photo better but was not among the near rivals)."""
    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(21))[0]
    code = model.codec.encode(payload)
    shown = np.ones(len(code), np.float32)
    shown[[2, 9, 14]] = -0.3
    assert model.codec.rival_margin(code, shown) >= 1.0  # every other word needs more
    monkeypatch.setattr(checker, "fit_morph", lambda *args, **kwargs: MorphFit(np.eye(3), 0.9, 0.85))
    monkeypatch.setattr(checker.synthesis, "evidence", lambda *args, **kwargs: BitEvidence(code, shown, 0.9, 1.0))
    image = np.full((64, 64), 0.8, np.float32)
    checked = checker.check(image, np.eye(3), DecodeResult(payload, True, 1, 0.95))
    assert checked.status == "contradicted" and not checked.result.ok
    assert checked.bits.reason == "the photo shows 3 of its code bits flipped"
    assert disagreement_in(checked.bits.to_json()) == checked.bits.reason


def test_a_repaired_word_on_an_outline_no_flat_print_makes_is_withdrawn(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A cast shadow's edge bent the alignment (one corner pulled a quarter of the print's width
    out): a word the code corrected, its morph fitted there, is withdrawn before its bits are
    asked, since a bent homography takes up part of a wrong word's morph. The same outline
    seen as a flat print (a tilted square, every corner where a pose puts it) does not withdraw
    it, nor does the bent one a word read without corrections."""
    from deepmorph_detect.camera import project, viewbox_corners
    from deepmorph_detect.check import repaired_on_a_bent_outline

    checker = locator.checker
    frame = viewbox_corners(locator.template.viewbox).astype(np.float32)
    tilted = np.array([[220, 150], [420, 140], [440, 330], [210, 340]], np.float32)
    bent = tilted.copy()
    bent[2] += (50, 50)
    flat_H, bent_H = (cv2.getPerspectiveTransform(frame, q).astype(np.float64) for q in (tilted, bent))
    image = np.full((480, 640), 0.8, np.float32)
    pyramid = ImagePyramid(image)
    assert np.allclose(project(bent_H, frame), bent, atol=1e-3)
    assert repaired_on_a_bent_outline(bent_H, locator.template, pyramid)
    assert not repaired_on_a_bent_outline(flat_H, locator.template, pyramid)
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(23))[0]
    code = model.codec.encode(payload)
    asked: list[np.ndarray] = []

    def evidence(*args, **kwargs) -> BitEvidence:
        asked.append(code)
        return BitEvidence(code, np.ones(len(code), np.float32), 0.9, 1.0)

    fitted_at: list[np.ndarray] = []
    monkeypatch.setattr(checker, "fit_morph", lambda *args, **kwargs: MorphFit(fitted_at[-1], 0.9, 0.85))
    monkeypatch.setattr(checker.synthesis, "evidence", evidence)
    monkeypatch.setattr(checker, "rival_deviation", lambda *args, **kwargs: None)
    repaired = DecodeResult(payload, True, 1, 0.95)
    fitted_at.append(bent_H)
    withdrawn = checker.check(pyramid, bent_H, repaired)
    assert withdrawn.status == "failed" and not withdrawn.result.ok and asked == []
    assert checker.check(pyramid, bent_H, replace(repaired, corrected_bits=0)).status == "passed" and asked
    fitted_at.append(flat_H)
    assert checker.check(pyramid, flat_H, repaired).status == "passed"


def test_a_word_whose_nearest_rival_explains_the_photo_better_is_withdrawn(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A print too small for its code: a wrong word passes the bit rules. It passes the check only
    when its nearest rival, asked at its own morph's alignment, explains the photo worse, or
    the photo shows the word's bits rather than the rival's where the two differ; the verdict
    and its reason survive the JSON."""
    import deepmorph_detect.check as check_module
    from deepmorph_detect.refine import Alignment

    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(29))[0]
    code = model.codec.encode(payload)
    wobble = np.where(np.arange(len(code)) % 2 == 0, 1.0, -1.0).astype(np.float32)
    # the bits where the nearest payload's word differs barely shown: the rival search finds it
    near = min((model.codec.encode(p) for p in _near_payloads(payload)), key=lambda c: int((c != code).sum()))
    read_as = BitEvidence(code, np.where(near == code, 1.0 + 0.6 * wobble, 0.2), 0.9, 1.0)
    assert read_as.agrees and read_as.deviation == pytest.approx(0.6)
    rival = model.codec.nearest_rival(code, read_as.evidence)
    assert rival is not None and (rival != code).any()
    differ = rival != code
    asked: list[np.ndarray] = []

    def photo_shows(rival_evidence: np.ndarray) -> None:
        """The photo as the synthesis asks it: ``read_as`` of the word, ``rival_evidence`` of the rival."""

        def evidence(pyramid, homography, asked_code, *args, **kwargs) -> BitEvidence:
            asked.append(np.asarray(asked_code))
            return read_as if np.array_equal(asked_code, code) else BitEvidence(rival, rival_evidence, 0.9, 1.0)

        def shown_on(pyramid, homography, asked_code, bits, *args) -> np.ndarray:
            assert np.array_equal(asked_code, rival) and np.array_equal(bits, np.flatnonzero(differ))
            return rival_evidence[bits]

        monkeypatch.setattr(checker.synthesis, "evidence", evidence)
        monkeypatch.setattr(checker.synthesis, "shown_on", shown_on)

    monkeypatch.setattr(checker, "fit_morph", lambda *args, **kwargs: MorphFit(np.eye(3), 0.9, 0.85))
    monkeypatch.setattr(check_module, "refine_at", lambda *args, **kwargs: Alignment(np.eye(3), 0.9, 128))
    image = np.full((64, 64), 0.8, np.float32)
    read = DecodeResult(payload, True, 1, 0.92)
    photo_shows(1.0 + 0.3 * wobble)
    better = checker.check(image, np.eye(3), read)
    assert np.array_equal(asked[-1], rival)  # the rival was asked about its own word
    assert better.status == "contradicted" and not better.result.ok
    assert better.bits.rival_deviation == pytest.approx(0.3)
    reason = (
        "the nearest other code word explains the photo better, its bits shown where the two differ "
        "(deviation 0.30 against 0.60)"
    )
    assert better.bits.reason == reason
    assert disagreement_in(better.bits.to_json()) == reason
    # a rival that fails the bit rules itself (three shared bits shown flipped) is asked all the same
    flipped = np.ones(len(code), np.float32)
    flipped[np.flatnonzero(~differ)[:3]] = -1.0
    photo_shows(flipped)
    assert checker.check(image, np.eye(3), read).status == "contradicted"
    photo_shows(1.0 + 0.8 * wobble)
    worse = checker.check(image, np.eye(3), read)
    assert worse.status == "passed" and worse.bits.rival_deviation == pytest.approx(0.8)
    assert disagreement_in(worse.bits.to_json()) == ""
    # in a photo relit from the drawing's own template, a word read with corrections must leave
    # its rival RELIT_RIVAL_MARGIN times as much unexplained: 1.08 times is enough elsewhere only
    photo_shows(1.0 + 0.65 * wobble)
    assert checker.check(image, np.eye(3), read).status == "passed"
    relit = checker.check(image, np.eye(3), read, relit_from=0.76)
    assert relit.status == "contradicted" and relit.bits.rival_margin == check_module.RELIT_RIVAL_MARGIN == 1.15
    reason = (
        "the nearest other code word explains the photo nearly as well, its bits shown where the two differ "
        "(deviation 0.65 against 0.60; 1.15 times needed)"
    )
    assert relit.bits.reason == reason and disagreement_in(relit.bits.to_json()) == reason
    uncorrected = checker.check(image, np.eye(3), replace(read, corrected_bits=0), relit_from=0.76)
    assert uncorrected.status == "passed" and "rival_margin" not in uncorrected.bits.to_json()
    # explaining the rest better, but the photo shows the word's bits where the two differ
    shows_word = np.where(differ, -1.0, 1.0).astype(np.float32)
    photo_shows(shows_word)
    shown = checker.check(image, np.eye(3), read)
    assert shown.status == "passed" and shown.bits.rival_deviation is None
    assert np.array_equal(asked[-1], code)  # the rival's other bits never asked
    assert "nearest_rival_deviation" not in shown.bits.to_json()
    # a rival differing in more than a quarter of the bits is asked about them all at once
    monkeypatch.setattr(check_module, "RIVAL_BITS_FIRST_SHARE", 0.0)
    assert checker.check(image, np.eye(3), read).bits.rival_deviation is None
    assert np.array_equal(asked[-1], rival)
    photo_shows(1.0 + 0.3 * wobble)
    assert checker.check(image, np.eye(3), read).status == "contradicted"


def _read_next(code: np.ndarray, runner_up: np.ndarray) -> np.ndarray:
    """Decoder probabilities that read ``code``, sure of every bit but those where ``runner_up``
    differs: the word the decoder would read next."""
    sure = np.where(code == 1, 0.95, 0.05)
    return np.where(runner_up != code, np.where(code == 1, 0.6, 0.4), sure).astype(np.float32)


def test_the_decoders_runner_up_is_asked_in_the_photo(model: DeepMorphModel, locator: Locator) -> None:
    """A print of one word, read as a near word whose runner-up (by the decoder's log-odds) is
    the printed one: the runner-up passes the whole per-bit check there. Read next as a word the
    photo does not show, it does not; nor where no probabilities are given."""
    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(3))[0]
    photo, H = _small_print(model, payload, 80, seed=1)
    pyramid = ImagePyramid(photo)
    printed = model.codec.encode(payload)
    near = [model.codec.encode(p) for p in _near_payloads(payload)]
    read, other = near[0], near[1]
    assert np.array_equal(model.codec.runner_up(read, _read_next(read, printed)), printed)
    assert np.array_equal(model.codec.runner_up(read, _read_next(read, other)), other)
    asks = (pyramid, H, read)
    rest = (None, False, False, None, 0)
    assert checker.runner_up_passes(*asks, _read_next(read, printed), *rest)
    assert not checker.runner_up_passes(*asks, _read_next(read, other), *rest)
    assert not checker.runner_up_passes(*asks, None, *rest)


def test_a_word_whose_runner_up_passes_too_is_withdrawn(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two code words the photo both shows leave the payload undecided: a colour drawing's word
    that passes every bit rule is withdrawn where the decoder's runner-up passes them too, with
    that reason in its JSON; it passes where the runner-up does not, or where the decoder's
    probabilities are not given (a payload fused over frames). A black-and-white drawing's
    (the ghost's) is not asked: its models read no wrong payload without the rule."""
    import deepmorph_detect.check as check_module
    from deepmorph_detect.check import PayloadChecker
    from deepmorph_detect.refine import Alignment

    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(29))[0]
    code = model.codec.encode(payload)
    runner_up = min((model.codec.encode(p) for p in _near_payloads(payload)), key=lambda c: int((c != code).sum()))
    shown = {"runner-up": True}

    def evidence(pyramid, homography, asked_code, *args, **kwargs) -> BitEvidence:
        both = np.array_equal(asked_code, code) or (shown["runner-up"] and np.array_equal(asked_code, runner_up))
        return BitEvidence(np.asarray(asked_code), np.full(len(code), 1.0 if both else -1.0, np.float32), 0.9, 1.0)

    monkeypatch.setattr(checker.synthesis, "evidence", evidence)
    monkeypatch.setattr(checker.synthesis, "shown_on", lambda p, h, c, bits, *a: np.ones(len(bits), np.float32))
    monkeypatch.setattr(checker, "fit_morph", lambda *args, **kwargs: MorphFit(np.eye(3), 0.9, 0.85))
    monkeypatch.setattr(check_module, "refine_at", lambda *args, **kwargs: Alignment(np.eye(3), 0.9, 128))
    image = np.full((64, 64), 0.8, np.float32)
    read = DecodeResult(payload, True, 1, 0.92)
    probs = _read_next(code, runner_up)
    assert not checker.asks_runner_up
    assert checker.check(image, np.eye(3), read, probabilities=probs).status == "passed"
    monkeypatch.setattr(PayloadChecker, "asks_runner_up", property(lambda self: True))  # as a colour drawing's
    undecided = checker.check(image, np.eye(3), read, probabilities=probs)
    assert undecided.status == "contradicted" and not undecided.result.ok
    assert undecided.bits.runner_up_passes and not undecided.bits.agrees
    reason = "the code word the decoder read next passes the check too: the photo does not tell them apart"
    assert undecided.bits.reason == reason and disagreement_in(undecided.bits.to_json()) == reason
    assert broken_rules(0, 5.0, 0.0, None, 1.0, True) == ("runner-up",)
    assert checker.check(image, np.eye(3), read).status == "passed"  # no probabilities: not asked
    shown["runner-up"] = False
    decided = checker.check(image, np.eye(3), read, probabilities=probs)
    assert decided.status == "passed" and "runner_up_passes" not in decided.bits.to_json()


def test_a_word_is_asked_again_at_a_second_alignment_to_its_morph(model: DeepMorphModel, locator: Locator) -> None:
    """From an alignment a few pixels off, the photo aligned again to the printed word's morph in a
    grid of light still shows it; a near word (one payload bit flipped, several code bits), asked
    the same way from the same start, is not shown."""
    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(5))[0]
    photo, H = _small_print(model, payload, 160, seed=2)
    pyramid = ImagePyramid(photo)
    off = np.array([[1.0, 0.0, 2.0], [0.0, 1.0, -1.5], [0.0, 0.0, 1.0]]) @ H  # 2.5 px off
    fit = MorphFit(off, 0.9, 0.9)
    printed = model.codec.encode(payload)
    near = min((model.codec.encode(p) for p in _near_payloads(payload)), key=lambda c: int((c != printed).sum()))
    assert checker.shown_realigned(pyramid, fit, printed, 0.9, 0)
    assert not checker.shown_realigned(pyramid, fit, near, 0.9, 0)


def test_a_colour_repair_the_photo_does_not_show_once_aligned_again_is_withdrawn(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A colour drawing's word the code corrected, which every bit rule passes, is withdrawn where
    the photo aligned again to its morph does not show it (``shown_realigned``), with that reason
    in its JSON; a word read without corrections is not asked, nor a black-and-white drawing's."""
    from deepmorph_detect.check import PayloadChecker

    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(31))[0]
    code = model.codec.encode(payload)
    asked: list[np.ndarray] = []

    def shown_realigned(pyramid, fit, asked_code, aligned, light_grid) -> bool:
        asked.append(asked_code)
        return False

    monkeypatch.setattr(
        checker.synthesis,
        "evidence",
        lambda p, h, c, *a, **k: BitEvidence(np.asarray(c), np.ones(len(code), np.float32), 0.9, 1.0),
    )
    monkeypatch.setattr(checker, "fit_morph", lambda *args, **kwargs: MorphFit(np.eye(3), 0.9, 0.85))
    monkeypatch.setattr(checker, "rival_deviation", lambda *args, **kwargs: None)
    monkeypatch.setattr(checker, "shown_realigned", shown_realigned)
    image = np.full((64, 64), 0.8, np.float32)
    repaired = DecodeResult(payload, True, 1, 0.92)
    assert not checker.asks_realigned
    assert checker.check(image, np.eye(3), repaired, bitwise=True).status == "passed" and not asked
    monkeypatch.setattr(PayloadChecker, "asks_realigned", property(lambda self: True))  # as a colour drawing's
    withdrawn = checker.check(image, np.eye(3), repaired, bitwise=True)
    assert withdrawn.status == "contradicted" and not withdrawn.result.ok
    assert withdrawn.bits.realigned_disagrees and np.array_equal(asked[0], code)
    reason = "aligned again to its morph in a grid of light, the photo does not show its bits"
    assert withdrawn.bits.reason == reason and disagreement_in(withdrawn.bits.to_json()) == reason
    asked.clear()
    clean = DecodeResult(payload, True, 0, 0.92)
    assert checker.check(image, np.eye(3), clean, bitwise=True).status == "passed" and not asked


def test_a_word_its_morph_leaves_unexplained_is_withdrawn_whatever_flat_light_shows(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A word whose bits the photo shows with a shadow divided out, the photo as it is left 1.5
    unexplained: withdrawn, in the photo and in one lit by the drawing's own template. Allowing a
    shadow's excess passed wrong words of small prints in hard scenes."""
    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(23))[0]
    code = model.codec.encode(payload)
    shown = np.ones(len(code), np.float32)
    shadowed = shown + np.where(np.arange(len(code)) % 2 == 0, 1.5, -1.5).astype(np.float32)
    monkeypatch.setattr(checker, "fit_morph", lambda *args, **kwargs: MorphFit(np.eye(3), 0.9, 0.85))
    monkeypatch.setattr(
        checker.synthesis, "evidence", lambda *args, **kwargs: BitEvidence(code, shown, 0.9, 1.0, unlit=shadowed)
    )
    image = np.full((64, 64), 0.8, np.float32)
    for relit_from in (None, 0.9):
        checked = checker.check(image, np.eye(3), DecodeResult(payload, True, 1, 0.95), relit_from=relit_from)
        assert checked.status == "contradicted" and checked.bits.deviation == pytest.approx(1.5)
        assert checked.bits.reason.startswith("its morph does not explain the photo")


def test_a_photo_the_morph_does_not_explain_does_not_pass_the_bits() -> None:
    """A wrong payload from a scene without any print (a bar chart's 3-bit code, 16 code bits,
    read off another drawing aligned at 0.68) had only two bits contradicted and strong support
    on its weakest five: the first two rules passed it. Its evidence scatters far from +1, which
    a print of the word never does."""
    scattered = np.array([3.77, 29.89, 4.3, 15.77, 7.83, -2.48, 2.78, 13.06, 9.97, 13.08, 10.13, 9.86, 19.15, 16.45,
                          0.2, -1.04], np.float32)  # fmt: skip
    said = BitEvidence(np.zeros(16, np.uint8), scattered, 0.7, 1.0)
    assert said.contradicted <= MAX_CONTRADICTED and said.weakest_sum >= MIN_WEAKEST_SUM
    assert said.deviation == pytest.approx(8.91, abs=0.01) and said.deviation > MAX_DEVIATION
    assert not said.agrees
    assert said.reason == "its morph does not explain the photo where its bits act (deviation 8.91, at most 1.0)"
    assert said.to_json()["bits_deviation"] == pytest.approx(8.91, abs=0.01)
    # a print read with noise of +-0.5 about +1 on every bit still agrees
    noisy = 1.0 + 0.5 * np.cos(np.arange(16, dtype=np.float32))
    assert BitEvidence(np.zeros(16, np.uint8), noisy, 0.9, 1.0).agrees


def test_a_fused_payload_reports_its_own_per_bit_check(model: DeepMorphModel, locator: Locator) -> None:
    """A sequence's entry carries the check of the payload fused over its frames, not the last
    frame's: its morph fit and per-bit fields are replaced, or dropped when that check has none."""
    scene = SceneMaker(model, severity="medium", seed=14).make(drawings=1)
    (det,) = locator.locate(scene.image, camera=scene.camera)
    last_frame_bits = BitEvidence(np.zeros(38, np.uint8), np.ones(38, np.float32), 0.9, 1.0)
    det = replace(det, bits=last_frame_bits)
    assert det.to_json()["bits_contradicted"] == 0
    vague = np.ones(38, np.float32)
    vague[[1, 2, 3]] = -0.5
    fused_bits = BitEvidence(np.zeros(38, np.uint8), vague, 0.8, 1.0)
    verdicts = {
        "contradicted": lambda image, H, fused: PayloadCheck(
            replace(fused, ok=False), None, "contradicted", fused_bits
        ),
        "failed": lambda image, H, fused: PayloadCheck(replace(fused, ok=False), None, "failed"),
    }
    for status, check in verdicts.items():
        fuser = FrameFuser(model.codec, check)
        fuser.add("f00", [det], scene.image)
        (entry,) = fuser.results()
        assert entry["morph_check"] == status and entry["ok"] is False and "morph_fit" not in entry
        if status == "contradicted":
            assert entry["bits_contradicted"] == 3 and entry["weakest_bits_support"] == pytest.approx(-1.5 + 2)
            assert disagreement(
                entry["bits_contradicted"], entry["weakest_bits_support"], entry["bits_deviation"]
            ).startswith("the photo shows 3")
        else:
            assert not {"bits_contradicted", "weakest_bits_support", "bits_deviation"} & set(entry)


def test_a_steeply_tilted_blurred_print_gives_no_wrong_payload(locator: Locator) -> None:
    """Regression: a hard-severity capture (tests/data/photos/README.md) where a CRC collision,
    eight code bits from the truth, passed the morph check and the per-bit check."""
    truth = "111111010001011110111001"
    image = cv2.imread(str(PHOTOS / "tilted_blurred_print.jpg"))
    (det,) = locator.locate(image)
    payload = "".join(map(str, det.result.payload))
    assert not det.result.ok or payload == truth, f"wrong payload {payload} reported ok ({det.morph_check})"
    assert det.result.ok and det.morph_check == "passed"  # and the right one is read


def test_an_unsure_reading_that_needed_no_corrections_gives_no_wrong_payload(locator: Locator) -> None:
    """Regression: a hard-severity capture (tests/data/photos/README.md) whose first look read a
    CRC collision, 4 payload bits off, without corrections (so the per-bit check did not run)
    that passed the morph check. Its confidence is low, so the per-bit check now runs. (The
    tuned decoder no longer reads that collision from this photo; the reading the untuned one
    made is checked as such.)"""
    truth = "100110101010100010111010"
    image = cv2.imread(str(PHOTOS / "confident_looking_collision.jpg"))
    (det,) = locator.locate(image)
    payload = "".join(map(str, det.result.payload))
    assert not det.result.ok or payload == truth, f"wrong payload {payload} reported ok ({det.morph_check})"
    collision = DecodeResult(np.array([int(c) for c in "100111101010110011110010"], np.uint8), True, 0, 0.919)
    check = locator.check_payload(image, det.homography, collision)
    assert check.status == "contradicted" and not check.result.ok
    assert check.bits is not None and check.bits.contradicted > MAX_CONTRADICTED
    # the right payload, read the same way, passes
    right = replace(collision, payload=np.array([int(c) for c in truth], np.uint8))
    assert locator.check_payload(image, det.homography, right).status == "passed"


def test_the_per_bit_evidence_is_corrected_where_the_soft_rasterizer_misdraws_a_bit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The Feather cpu's pins, pushed along themselves into the chip's outline, change only
    where strokes overlap, which the soft union draws unlike a real renderer. Uncorrected, the
    evidence on clean real renders contradicts such bits and the per-bit check withdraws right
    payloads; checked against the word's own real render, every word is shown."""
    import deepmorph_detect.synthesis as synthesis
    from deepmorph.training.codec import train_model
    from deepmorph_detect.refine import Template

    train_model(
        Path(__file__).parent.parent / "data" / "feather" / "cpu.svg",
        tmp_path / "cpu.dmm",
        payload_bits=24,
        ecc_t=1,
        bounds={"move": 0.48},  # 2 % of the width: 40 variables for 38 code bits
        train={"steps": 1, "width": 32, "batch": 2, "threads": 1},
    )
    model = DeepMorphModel.load(tmp_path / "cpu.dmm").eval()  # the spread start: full-range bits
    viewbox = model.drawing.drawing.viewbox
    template = Template.from_svg(model.drawing.to_svg(model.drawing.neutral_values()[0]), viewbox, (48, 128))
    s = 256 / viewbox[2]
    H = np.array([[s, 0, -viewbox[0] * s], [0, s, -viewbox[1] * s], [0, 0, 1]])
    words = [model.codec.encode(p) for p in random_payloads(12, 24, np.random.default_rng(3))]
    photos = [
        ImagePyramid(
            render_svg(model.drawing.to_svg(model.morph_values(torch.from_numpy(w[None].astype(np.float32)))[0]), 256)
        )
        for w in words
    ]

    floor = synthesis.MIN_OWN_EVIDENCE

    def asked(floor: float) -> list[BitEvidence]:
        monkeypatch.setattr(synthesis, "MIN_OWN_EVIDENCE", floor)
        syn = synthesis.MorphSynthesis(model, template)
        return [syn.evidence(photo, H, word) for photo, word in zip(photos, words)]

    raw = asked(-np.inf)
    assert min(float(e.evidence.min()) for e in raw) < 0  # a clean render of the word contradicts a bit of it
    calibrated = asked(floor)
    assert all(e.agrees for e in calibrated), [round(float(e.evidence.min()), 2) for e in calibrated]
    assert sum(e.agrees for e in raw) < len(raw)  # and uncorrected, some right word is withdrawn


@pytest.fixture(scope="module")
def face_bundle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The yellow face emoji at the encoder's spread start (full-range bits), read in blue."""
    import deepmorph.plugin as commands
    import deepmorph_augment.plugin as augmentations
    import deepmorph_detect.plugin as detectors
    import deepmorph_primitives.plugin as primitives
    from deepmorph.training.codec import train_model
    from deepmorph_core.plugins import load_registry, set_default_registry

    bezier = pytest.importorskip("deepmorph_bezier.plugin", reason="the example Bézier plugin is not installed")
    set_default_registry(load_registry([primitives, augmentations, detectors, commands, bezier], entry_points=False))
    out = tmp_path_factory.mktemp("face") / "face.dmm"
    train_model(
        Path(__file__).parent.parent / "data" / "fluent-emoji-flat" / "face-without-mouth.svg",
        out,
        payload_bits=12,
        crc_bits=8,  # the code these tests were written for (a colour payload's default CRC is 12)
        ecc_t=1,
        bounds={"move": 0.5},
        train={"steps": 1, "width": 32, "batch": 2, "threads": 1},
    )
    return out


@pytest.fixture
def face(face_bundle: Path, with_bezier) -> DeepMorphModel:
    return DeepMorphModel.load(face_bundle).eval()


def _filling(model: DeepMorphModel, width: int) -> np.ndarray:
    """The homography (SVG units -> px) of a print whose viewBox fills a photo ``width`` px wide."""
    x, y, vw, _ = model.drawing.drawing.viewbox
    s = width / vw
    return np.array([[s, 0, -x * s], [0, s, -y * s], [0, 0, 1]])


def _face_synthesis(face: DeepMorphModel) -> MorphSynthesis:
    """The face's synthesis, reading its blue through the channel's renderer."""
    from deepmorph_detect.fastrender import channel_renderer
    from deepmorph_detect.refine import Template

    renderer = channel_renderer(face.drawing.channel)
    neutral = face.drawing.to_svg(face.drawing.neutral_values()[0])
    template = Template.from_svg(neutral, face.drawing.drawing.viewbox, (48, 128), renderer)
    return MorphSynthesis(face, template, renderer=renderer)


def _colour_photo(model: DeepMorphModel, code: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A 256-px print of ``code``'s morph, its ink faded a third of the way to gray and its
    white balance warmed, blurred and noisy, in the model's reading channel; and its homography."""
    from deepmorph_core.luminance import LUMA_WEIGHTS
    from deepmorph_core.render import render_svg_rgb

    values = model.morph_values(torch.from_numpy(code[None].astype(np.float32)))[0]
    rgb = render_svg_rgb(model.drawing.to_svg(values), 256)
    faded = rgb + 0.35 * (rgb @ np.asarray(LUMA_WEIGHTS, np.float32)[:, None] - rgb)
    channel = np.asarray(model.drawing.channel, dtype=np.float32)
    photo = cv2.GaussianBlur(np.clip(faded * (1.0, 0.97, 0.85), 0, 1) @ channel, (0, 0), 0.8)
    photo = np.clip(photo * 0.8 + 0.1 + rng.normal(0, 0.01, photo.shape), 0, 1).astype(np.float32)
    return photo, _filling(model, 256)


def test_a_colour_print_is_asked_in_its_own_colours(face: DeepMorphModel) -> None:
    """Printing and capture change each colour differently (faded ink, a white balance). The
    yellow face is read in blue, where its render shows the face and the eyes' dark brown
    alike and the photo does not. The light fitted per colour channel shows every bit of the
    printed word and leaves less of the photo unexplained than one gray fitted to it; a word
    near it still does not agree."""
    assert np.argmax(face.drawing.channel) == 2  # read in blue
    synthesis = _face_synthesis(face)
    rng = np.random.default_rng(5)
    gains = []
    for payload in random_payloads(4, 12, rng):
        code = face.codec.encode(payload)
        photo, H = _colour_photo(face, code, rng)
        pyramid = ImagePyramid(photo)
        in_colour = synthesis.evidence(pyramid, H, code)
        assert in_colour.agrees and in_colour.contradicted == 0, in_colour.reason
        # with no light divided out (which would take up some of the inks' change too)
        in_gray = synthesis.evidence(pyramid, H, code, in_colour=False, lit=False)
        unlit = synthesis.evidence(pyramid, H, code, lit=False)
        assert 1 - unlit.fit**2 < 0.8 * (1 - in_gray.fit**2)  # a third less of the photo left unexplained
        # how much the morph leaves unexplained is the photo's as it is, lit or not (what a
        # rival's deviation alone needs)
        assert unlit.deviation == in_colour.deviation
        gains.append(in_gray.deviation - in_colour.deviation)
        near = face.codec.encode(_near_payloads(payload)[0])
        assert not synthesis.evidence(pyramid, H, near).agrees
    assert np.mean(gains) > 0.03, gains


def test_a_bits_evidence_is_its_definition_with_the_motion_projected_out(
    model: DeepMorphModel, locator: Locator
) -> None:
    """Each bit's evidence is ``(|P(photo - T(c ^ e_j))|^2 - |P(photo - T(c))|^2) / |P(T(c ^ e_j) - T(c))|^2``
    with ``P`` projecting out what a small motion of the word's render explains, whatever
    algebra computes it: here the projected residuals are formed explicitly, in the light the
    synthesis fits, on a real print's renders, with and without a cast shadow's grid."""
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(11))[0]
    photo, H = _small_print(model, payload, 80, seed=11)
    synthesis = locator.checker.synthesis
    code = model.codec.encode(payload)
    rectified, soft, _, _ = synthesis._asked_in(ImagePyramid(photo), H, synthesis.variants(code), True)
    blurred = _blurred(soft, 1.5).reshape(*soft.shape[:2], -1)
    fields = synthesis._light_fields(rectified.shape)
    for grid in (None, GridLight.of(soft[0], 1.5, 4)):
        models = synthesis._in_light(rectified, blurred, fields, grid)
        basis = synthesis._motion_basis(models[0].reshape(rectified.shape))
        residuals = rectified.ravel()[None] - models
        residuals -= (residuals @ basis) @ basis.T
        changes = models[1:] - models[0]
        changes -= (changes @ basis) @ basis.T
        defined = ((residuals[1:] ** 2).sum(1) - (residuals[0] ** 2).sum()) / (changes**2).sum(1)
        assert np.allclose(synthesis._ask(rectified, blurred, fields, grid), defined, rtol=1e-6, atol=1e-8)


def test_some_bits_are_asked_as_the_whole_word_asks_them(
    model: DeepMorphModel, locator: Locator, face: DeepMorphModel
) -> None:
    """A bit's evidence depends on the word's render and its own variant only: asked about a few
    bits, rendering only their variants (as the check asks a rival's differing bits first), the
    photo says what it says of them asked about the whole word, in gray and in colour. (The
    Bézier plugin flattens a batch's curves to one piece count, within 0.05 px of the curve, so
    the face's renders differ by that between batches.)"""
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(4))[0]
    photo, H = _small_print(model, payload, 80, seed=4)
    near_payload = _near_payloads(payload)[2]
    near = model.codec.encode(near_payload)
    differ = np.flatnonzero(near != model.codec.encode(payload))
    synthesis, pyramid = locator.checker.synthesis, ImagePyramid(photo)
    H = locator.checker.fit_morph(pyramid, H, near_payload).homography  # aligned to its morph, as the check asks
    whole = synthesis.evidence(pyramid, H, near)
    assert whole.evidence[differ].sum() < 0  # the photo shows the printed word's bits there
    assert np.allclose(synthesis.shown_on(pyramid, H, near, differ), whole.evidence[differ], atol=1e-4)
    colour = _face_synthesis(face)
    rng = np.random.default_rng(7)
    code = face.codec.encode(random_payloads(1, 12, rng)[0])
    photo, H = _colour_photo(face, code, rng)
    some = np.array([0, 3, len(code) - 1])
    for in_colour in (True, False):
        whole = colour.evidence(ImagePyramid(photo), H, code, in_colour=in_colour)
        assert np.allclose(
            colour.shown_on(ImagePyramid(photo), H, code, some, in_colour), whole.evidence[some], atol=0.03
        )


def test_bits_drawn_by_the_real_renderer_say_what_the_soft_rasterizer_s_say(
    model: DeepMorphModel, locator: Locator, face: DeepMorphModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The screen's evidence (``drawn_on``: the word and its one-bit variants drawn by the real
    renderer) tells the printed word's bits from a near word's as the soft rasterizer's does, bit
    for bit within a tenth of a bit's change; a variant the renderer draws no differently shows 0,
    not support; and a colour drawing's bits are not asked so."""
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(4))[0]
    photo, H = _small_print(model, payload, 80, seed=4)
    synthesis, pyramid = locator.checker.synthesis, ImagePyramid(photo)
    code = model.codec.encode(payload)
    every = np.arange(len(code))
    soft = synthesis.shown_on(pyramid, H, code, every)
    drawn = synthesis.drawn_on(pyramid, H, code, every)
    assert drawn.min() > 0.3 and np.median(np.abs(drawn - soft)) < 0.1
    near_payload = _near_payloads(payload)[2]
    near = model.codec.encode(near_payload)
    differ = np.flatnonzero(near != code)
    at = locator.checker.fit_morph(pyramid, H, near_payload).homography
    drawn_near, soft_near = synthesis.drawn_on(pyramid, at, near, differ), synthesis.shown_on(pyramid, at, near, differ)
    assert drawn_near.sum() < 0 and drawn_near.min() < -0.5  # the photo shows the printed word's there
    assert np.median(np.abs(drawn_near - soft_near)) < 0.1
    word = model.drawing.to_svg(model.morph_values(torch.from_numpy(code[None].astype(np.float32)))[0])
    with monkeypatch.context() as m:  # every variant drawn as the word
        m.setattr(
            synthesis, "renderer", lambda svg, width, viewbox, draw=synthesis.renderer: draw(word, width, viewbox)
        )
        assert np.all(synthesis.drawn_on(pyramid, H, code, differ) == 0)
    with pytest.raises(ValueError, match="colour"):
        _face_synthesis(face).drawn_on(
            pyramid, H, face.codec.encode(random_payloads(1, 12, np.random.default_rng(7))[0]), differ[:1]
        )


def test_a_colour_print_is_asked_in_colour_only_where_the_drawing_aligned(
    face: DeepMorphModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The colours' extra freedom also explains clutter; a weak reading is asked in colour where
    the unmorphed drawing aligned at 0.8 or better (in a lit photo: where the photo itself did),
    else in the reading channel's gray; at its second alignment (``shown_realigned``) as there."""
    from deepmorph_detect.check import DRAWING_LIKE_ALIGNMENT

    locator = Locator(face, detector=None)
    checker = locator.checker
    payload = random_payloads(1, 12, np.random.default_rng(6))[0]
    photo, H = _colour_photo(face, face.codec.encode(payload), np.random.default_rng(6))
    asked: list[tuple[bytes, bool]] = []  # (code word, in colour) of every word asked
    realigned: list[bool] = []  # in colour, of each ask at a second alignment
    synthesis = checker.synthesis
    evidence, shown_on, shown_realigned = synthesis.evidence, synthesis.shown_on, checker.shown_realigned

    def realigning(*a):
        asks = len(asked)
        shown = shown_realigned(*a)
        realigned.extend(colour for _, colour in asked[asks:])
        del asked[asks:]
        return shown

    monkeypatch.setattr(synthesis, "evidence", lambda *a: asked.append((a[2].tobytes(), a[3])) or evidence(*a))
    monkeypatch.setattr(synthesis, "shown_on", lambda *a: asked.append((a[2].tobytes(), a[4])) or shown_on(*a))
    monkeypatch.setattr(checker, "shown_realigned", realigning)
    weak = DecodeResult(payload, ok=True, corrected_bits=1, confidence=0.9)
    pyramid = ImagePyramid(photo)
    assert checker.check(pyramid, H, weak).status == "passed"
    for relit_from in (DRAWING_LIKE_ALIGNMENT - 0.2, DRAWING_LIKE_ALIGNMENT + 0.1):
        checker.check(pyramid, H, weak, relit_from=relit_from)
    word = face.codec.encode(payload).tobytes()
    assert [colour for code, colour in asked if code == word] == [True, False, True]
    assert realigned == [True, False, True]
    # a rival word passing too is asked as the word before it was
    for (before, colour_before), (code, colour) in zip(asked, asked[1:]):
        if code != word:
            assert before == word and colour == colour_before


def _shadowed_colour_photo(
    model: DeepMorphModel, code: np.ndarray, seed: int, angle: float, offset: float, shade: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """A 256-px print of ``code``'s morph under a branch's cast shadow (a band a tenth of the
    print wide that takes ``shade`` of the light, with a soft edge) across it, blurred and noisy
    (noise by ``seed``), in the model's reading channel; and its homography."""
    from deepmorph_core.render import render_svg_rgb

    values = model.morph_values(torch.from_numpy(code[None].astype(np.float32)))[0]
    rgb = render_svg_rgb(model.drawing.to_svg(values), 256)
    y, x = np.mgrid[0:256, 0:256].astype(np.float32)
    across = (x - 128) * np.cos(angle) + (y - 128) * np.sin(angle) - offset * 256
    light = 1 - shade * cv2.GaussianBlur((np.abs(across) < 0.05 * 256).astype(np.float32), (0, 0), 1.5)
    photo = cv2.GaussianBlur((rgb * light[..., None]) @ np.asarray(model.drawing.channel, np.float32), (0, 0), 0.8)
    noise = np.random.default_rng(seed).normal(0, 0.01, photo.shape)
    photo = np.clip(photo * 0.8 + 0.1 + noise, 0, 1).astype(np.float32)
    return photo, _filling(model, 256)


def test_the_light_of_a_cast_shadow_is_read_off_the_flat_of_the_print(face: DeepMorphModel) -> None:
    """Where the render is flat and light, the light divided out is the shadow's: on the paper
    in the band, the photo's brightness there over the paper's away from it (half the light,
    less the camera's black level), and one away from it."""
    from deepmorph_detect.template_light import far_from_edges

    synthesis = _face_synthesis(face)
    code = face.codec.encode(random_payloads(1, 12, np.random.default_rng(2))[0])
    photo, H = _shadowed_colour_photo(face, code, 2, angle=0.8, offset=0.0)
    rectified = synthesis.rectified(ImagePyramid(photo), H)
    render = synthesis.variants(code)[0][0]
    light = synthesis.shadows(rectified, render)
    h, w = rectified.shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    across = np.abs((x - w / 2) * np.cos(0.8) + (y - h / 2) * np.sin(0.8)) / w  # in print widths
    paper = (far_from_edges(render, 3) > 0) & (render.min(axis=0) > 0.95)
    inside, outside = paper & (across < 0.02), paper & (across > 0.15)
    assert inside.sum() > 10 and outside.sum() > 200
    assert np.median(light[outside]) == pytest.approx(1.0, abs=0.05)
    shaded = np.median(rectified[inside]) / np.median(rectified[outside])  # (0.8 * 0.5 + 0.1) / 0.9
    assert np.median(light[inside]) == pytest.approx(shaded, abs=0.05)


def test_a_cast_shadow_moves_the_bits_evidence_less_once_its_light_is_divided_out(face: DeepMorphModel) -> None:
    """A shadow's sharp edge across the face's fill is a change no smooth light field fits;
    near a bit it outweighs the bit's change. With its light divided out, the per-bit evidence
    of a shadowed print stays nearer that of the same print unshadowed, a near word is still
    refused, and the deviation (whether the morph explains the photo at all) is the unlit one."""
    synthesis = _face_synthesis(face)
    rng = np.random.default_rng(5)
    lit_shift, unlit_shift = [], []
    for k, payload in enumerate(random_payloads(8, 12, rng)):
        code = face.codec.encode(payload)
        where = {"angle": 0.5 + 0.45 * k, "offset": 0.08 * (k % 3 - 1)}
        photo, H = _shadowed_colour_photo(face, code, k, **where)
        unshadowed, _ = _shadowed_colour_photo(face, code, k, shade=0.0, **where)
        clean = synthesis.evidence(ImagePyramid(unshadowed), H, code, lit=False).evidence
        lit = synthesis.evidence(ImagePyramid(photo), H, code)
        unlit = synthesis.evidence(ImagePyramid(photo), H, code, lit=False)
        lit_shift.append(np.abs(lit.evidence - clean).mean())
        unlit_shift.append(np.abs(unlit.evidence - clean).mean())
        assert lit.deviation == unlit.deviation
        assert not synthesis.evidence(ImagePyramid(photo), H, face.codec.encode(_near_payloads(payload)[k])).agrees
    assert all(np.less(lit_shift, unlit_shift)), (lit_shift, unlit_shift)
    assert np.mean(lit_shift) < 0.85 * np.mean(unlit_shift), (lit_shift, unlit_shift)


def test_a_colour_reading_the_code_corrected_must_show_its_morph_beyond_noise(
    locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reading that needed corrections must gain REPAIRED_COLOUR_MORPH_GAIN over the unmorphed
    drawing where the drawing is in colour (faint edges let a repaired wrong word fit as well as
    no morph at all); black ink, and any reading without corrections, only more than nothing."""
    from deepmorph_detect.check import MIN_MORPH_GAIN, REPAIRED_COLOUR_MORPH_GAIN

    checker = locator.checker
    bits = np.zeros(locator.model.codec.spec.payload_bits, np.uint8)
    repaired, clean = DecodeResult(bits, True, 1, 0.9), DecodeResult(bits, True, 0, 0.99)
    assert not locator.model.drawing.colour
    assert checker.least_gain(repaired) == checker.least_gain(clean) == MIN_MORPH_GAIN
    monkeypatch.setattr(type(locator.model.drawing), "colour", property(lambda self: True))
    assert checker.least_gain(repaired) == REPAIRED_COLOUR_MORPH_GAIN > MIN_MORPH_GAIN
    assert checker.least_gain(clean) == MIN_MORPH_GAIN


@pytest.mark.parametrize(
    ("whole_frame", "corrected", "aligned", "colour", "passes"),
    [
        (True, 2, 0.675, False, False),  # a frame filled by another icon: refused whatever its bits show
        (True, 2, 0.85, False, True),  # a frame-filling print of the drawing
        (True, 0, 0.675, False, True),  # read without corrections: the bits decide
        (False, 2, 0.675, False, True),  # a proposed print: the bits decide
        (True, 2, 0.675, True, True),  # colour drawings are not held to it: a right one passed at 0.727
    ],
)
def test_a_repaired_whole_frame_reading_of_another_drawing_is_refused(
    model: DeepMorphModel,
    locator: Locator,
    monkeypatch: pytest.MonkeyPatch,
    whole_frame: bool,
    corrected: int,
    aligned: float,
    colour: bool,
    passes: bool,
) -> None:
    """A whole-frame reading the code corrected passes only where the unmorphed drawing aligned to
    the photo at WHOLE_FRAME_REPAIRED_ALIGNMENT or better, even when its bits are all shown: a
    photo of another icon filling the frame passed a chip's bit check so at 0.675."""
    from deepmorph_detect.check import WHOLE_FRAME_REPAIRED_ALIGNMENT

    assert aligned == 0.85 or aligned < WHOLE_FRAME_REPAIRED_ALIGNMENT <= 0.85
    checker = locator.checker
    payload = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(31))[0]
    code = model.codec.encode(payload)
    shown = BitEvidence(code, np.ones(len(code), np.float32), 0.9, 1.0)
    monkeypatch.setattr(type(model.drawing), "colour", property(lambda self: colour))
    monkeypatch.setattr(checker, "fit_morph", lambda *args, **kwargs: MorphFit(np.eye(3), aligned + 0.04, aligned))
    monkeypatch.setattr(checker.synthesis, "evidence", lambda *args, **kwargs: shown)
    monkeypatch.setattr(checker, "rival_deviation", lambda *args, **kwargs: None)
    image = np.full((64, 64), 0.8, np.float32)
    checked = checker.check(image, np.eye(3), DecodeResult(payload, True, corrected, 0.9), whole_frame=whole_frame)
    assert checked.result.ok is passes
    assert checked.status == ("passed" if passes else "failed")
