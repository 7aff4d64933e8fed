"""A print narrower in the photo than the decoder's frame that does not read is reported as too
small (move closer, print larger), in the API, the JSON and ``decode``'s text."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.codec import DecodeResult
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.protocols import Candidate
from deepmorph_core.render import render_svg
from deepmorph_detect.locate import Locator
from deepmorph_detect.results import Located
from deepmorph_detect.scenes import close_up_photo
from tests.conftest import table_text

app = application()


def small_prints(model, count: int = 12) -> list[tuple[np.ndarray, np.ndarray]]:
    """Hard close-ups whose drawing spans about 40 camera pixels (the ghost reads about a third)."""
    rng = np.random.default_rng(0)
    photos = []
    for _ in range(count):
        payload = rng.integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8)
        photos.append((close_up_photo(render_svg(model.encode(payload), 200), "hard", rng, size=64), payload))
    return photos


def test_unread_small_prints_are_too_small_and_read_ones_are_not(model, locator) -> None:
    flagged = read = 0
    for photo, payload in small_prints(model):
        for found in locator.locate(photo):
            assert found.needs_px == model.width == 96
            assert 30 < found.width_px < 50
            if found.result.ok:
                assert np.array_equal(found.result.payload, payload)
                assert not found.too_small and "too_small" not in found.to_json()
                read += 1
            else:
                assert found.too_small
                assert found.to_json()["too_small"] == {"width_px": round(found.width_px, 1), "needs_px": 96.0}
                flagged += 1
    assert flagged >= 3 and read >= 3
    # the same unread drawing at twice the size in the photo is not too small: another reason
    unread = next(f for photo, _ in small_prints(model) for f in locator.locate(photo) if not f.result.ok)
    wide = replace(unread, corners=unread.corners * 3, homography=np.diag([3.0, 3.0, 1.0]) @ unread.homography)
    assert wide.width_px > 96 and not wide.too_small


def test_an_unread_print_filling_little_of_a_photo_is_not_called_too_small(model) -> None:
    """The whole image framed by its ink reports an unread print as too small only where the
    print fills at least half the image's width (a tiny scan). In a photo three times as wide
    such an alignment (0.68 here) is no better than the one a patch of another drawing's ink got
    in a scene without any print (0.64): neither is reported."""
    whole_only = Locator(model, detector="none")
    unread = [photo for photo, _ in small_prints(model) if any(f.too_small for f in whole_only.locate(photo))]
    assert len(unread) >= 3
    for photo in unread:
        h, w = photo.shape[:2]
        wide = np.full((3 * h, 3 * w, *photo.shape[2:]), np.median(photo), dtype=photo.dtype)
        wide[h : 2 * h, w : 2 * w] = photo
        assert not [f for f in whole_only.locate(wide) if not f.result.ok]


def test_decode_says_a_print_is_too_small(model, locator, tmp_path: Path) -> None:
    photo = next(p for p, _ in small_prints(model) if any(f.too_small for f in locator.locate(p)))
    path = tmp_path / "small.png"
    cv2.imwrite(str(path), photo)
    shown = CliRunner().invoke(app, ["decode", str(BUNDLED_MODEL), str(path)])
    assert shown.exit_code == 4, shown.output
    assert "NOT READ: too small to read (" in shown.output and "px across, needs 96)" in shown.output
    data = json.loads(CliRunner().invoke(app, ["decode", str(BUNDLED_MODEL), str(path), "--json"]).output)
    (detection,) = data[0]["detections"]
    assert detection["too_small"]["needs_px"] == 96.0 and not detection["ok"]


def test_a_print_is_as_wide_as_it_would_be_seen_head_on_at_its_distance() -> None:
    """A print's width in the photo is what ``train --pixels``, ``capacity --print-mm
    --distance-cm`` and the photo simulator mean by it: its width seen head-on at its distance
    (the camera's focal length over the distance, for a print one unit wide). A tilt about any
    axis, and a turn, leave it so, while the mean of the frame's top and bottom edges shrinks
    with a tilt about the vertical axis (a 200-px print tilted 15° and turned measured 196.5 px)."""
    from deepmorph_detect.camera import Camera, homography_from_pose, project
    from deepmorph_detect.results import across_px, measure_width

    cam = Camera.default(640, 480)
    square = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    distance = cam.fx / 200.0  # 200 px across, head-on
    for axis in ([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.7071, 0.7071, 0.0]):
        for tilt in (0.0, 15.0, 30.0):
            tilted, _ = cv2.Rodrigues(np.radians(tilt) * np.array(axis))
            turned, _ = cv2.Rodrigues(np.array([0.0, 0.0, 0.3]))
            rvec, _ = cv2.Rodrigues(tilted @ turned)
            H = homography_from_pose(cam, rvec.reshape(3), np.array([0.05, -0.03, 1.0]) * distance)
            corners = project(H, square)
            assert across_px(H, square) == pytest.approx(200.0, rel=0.01)
            found = Located(
                DecodeResult(np.zeros(5, np.uint8), True, 0, 1.0), np.ones(5), corners=corners, homography=H
            )
            assert found.width_px == pytest.approx(across_px(H, square))
            if axis[0] == 0.0 and tilt == 15.0:
                assert measure_width(corners) < 198.0
    # a degenerate map gives the edges as seen, never an error
    assert replace(found, homography=np.zeros((3, 3))).width_px == measure_width(corners)


def test_info_gives_the_smallest_print() -> None:
    data = json.loads(CliRunner().invoke(app, ["info", str(BUNDLED_MODEL), "--json"]).output)
    assert data["smallest_print_px"] == 96 == data["image_size"][1]
    shown = CliRunner().invoke(app, ["info", str(BUNDLED_MODEL)])
    assert "96 px across in a photo" in table_text(shown.output)


def test_which_unread_drawings_are_reported(locator) -> None:
    """An unread drawing is reported on its alignment alone: never a blind proposer's; the whole
    image's only where it fills half the image and the photo shows it whole (at 0.8, or 0.6 when
    too small); a detector's that knows the drawing from 0.6. Cases from 640 x 480 photos unless said."""
    unread = DecodeResult(np.zeros(5, np.uint8), False, -1, 0.9)

    def located(width: float, correlation: float, left: float = 0.0, top: float = 0.0, outline=None) -> Located:
        corners = np.array([[0, 0], [width, 0], [width, width], [0, width]], np.float64) + (left, top)
        corners = corners if outline is None else np.array(outline, np.float64)
        H = cv2.getPerspectiveTransform(locator.frame_corners.astype(np.float32), corners.astype(np.float32))
        return Located(
            unread, np.full(5, 0.5, np.float32), corners=corners, homography=H, correlation=correlation, needs_px=96.0
        )

    def proposal(whole: bool = False, blind: bool = False) -> Candidate:
        return Candidate(np.zeros((4, 2)), 1.0, (0, 0, 1, 1), np.eye(3) if whole else None, blind=blind)

    reports = locator.reports_unread
    photo = (480, 640)
    assert not reports(located(400, 0.99), proposal(blind=True), photo)
    # a patch of another drawing's ink a third of the frame wide (0.82 in a scene without any print)
    assert not reports(located(218, 0.82), proposal(whole=True), photo)
    assert reports(located(400, 0.82), proposal(whole=True), photo)
    assert not reports(located(5493, 0.81), proposal(whole=True), photo)  # a degenerate frame, 8.6 times the image
    assert not reports(located(400, 0.75), proposal(whole=True), photo)
    assert reports(located(41, 0.72), proposal(whole=True), (64, 64))  # a tiny scan, too small to read
    assert not reports(located(41, 0.64), proposal(whole=True), photo)
    assert reports(located(150, 0.62), proposal(), photo) and not reports(located(150, 0.58), proposal(), photo)
    # the ink running off the image: clutter framed from the whole image, not a print it shows whole
    inside, off = located(400, 0.86, 200, 40), located(400, 0.86, 330, 40)
    assert locator.shown_whole(inside.homography, photo) and reports(inside, proposal(whole=True), photo)
    assert not locator.shown_whole(off.homography, photo)
    assert not reports(off, proposal(whole=True), photo)
    assert not reports(located(400, 0.86, -200, 40), proposal(whole=True), photo)
    assert not reports(located(400, 0.86, 100, 300), proposal(whole=True), photo)
    # inside, but an outline no flat print makes (0.12 of its width from the nearest): bent to fit clutter
    bent = located(0, 0.86, outline=[[100, 100], [500, 60], [540, 420], [80, 300]])
    assert locator.aligner.bent(bent.homography, photo)
    assert not locator.shown_whole(bent.homography, photo) and not reports(bent, proposal(whole=True), photo)


def test_a_model_trained_for_wider_prints_reads_no_payload_from_narrower_ones(locator) -> None:
    """A model trained with ``--pixels`` (here the ghost, told it was trained for prints 150 px
    wide) reads prints at least that wide, and calls a narrower one too small even where its
    payload reads (as the ghost's own locator shows): it was never validated there, so no
    payload comes back."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    model.meta.train["print_px"] = 150
    assert model.print_px == model.smallest_print_px == 150
    trained_wider = Locator(model)
    rng = np.random.default_rng(3)
    payload = rng.integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8)
    art = render_svg(model.encode(payload), 400)
    narrow = [close_up_photo(art, "easy", rng, size=160) for _ in range(3)]
    wide = [close_up_photo(art, "easy", rng, size=260) for _ in range(3)]
    assert all(f.result.ok for photo in narrow for f in locator.locate(photo))
    blind = Locator(model, detector="universal")  # whose unread proposals are never reported
    for reader in (trained_wider, blind):
        refused = [f for photo in narrow for f in reader.locate(photo)]
        assert len(refused) == 3 and all(96 < f.width_px < 150 for f in refused)
        assert all(not f.result.ok and f.too_small and not f.result.payload.any() for f in refused)
        assert all(f.to_json()["too_small"]["needs_px"] == 150.0 for f in refused)
    read = [f for photo in wide for f in trained_wider.locate(photo)]
    assert len(read) == 3 and all(f.width_px >= 150 and f.result.ok for f in read)
    assert all(np.array_equal(f.result.payload, payload) for f in read)


def test_a_print_aligned_too_narrow_is_read_by_its_first_looks_alone(locator, monkeypatch) -> None:
    """A print aligned narrower than ``NARROW_SHARE`` of the width a model was trained for is too
    small whatever it reads: its first looks are read (a passing one says it is the drawing),
    and none of the later looks, realignments or whole-image framings is tried. Aligned at the
    width it needs, the later looks are tried as before."""
    import deepmorph_detect.locate as locate_module

    model = DeepMorphModel.load(BUNDLED_MODEL)
    model.meta.train["print_px"] = 150
    trained_wider = Locator(model)
    later: list[str] = []
    monkeypatch.setattr(trained_wider.reader, "read_again", lambda *a, **k: later.append("second looks") or iter(()))
    monkeypatch.setattr(trained_wider.aligner, "as_flat_sheet", lambda *a, **k: later.append("flat sheet"))
    monkeypatch.setattr(locate_module, "whole_frame", lambda *a, **k: later.append("whole frame") or [])
    rng = np.random.default_rng(3)
    payload = rng.integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8)
    narrow = close_up_photo(render_svg(model.encode(payload), 400), "easy", rng, size=160)
    (refused,) = trained_wider.locate(narrow)
    assert refused.too_small and refused.morph_check == "passed" and later == []

    gray, _, pyramid, (aligned,) = trained_wider._proposed(narrow, None)
    assert trained_wider.aligned_too_narrow(aligned.alignment)
    asked: list[bool] = []

    def unread(*args, first_only: bool = False, **kwargs) -> tuple:
        asked.append(first_only)
        result = DecodeResult(np.zeros_like(payload), False, -1, 0.5)
        return aligned.alignment.homography, locate_module.PayloadCheck(result, None, "not run"), np.full(8, 0.5)

    monkeypatch.setattr(trained_wider, "_read_and_check", unread)
    cam = trained_wider.frame(narrow, None)[1]
    found = trained_wider.decode_drawing(gray, pyramid, aligned.alignment, 1.0, cam, "detector", True)
    assert not found.result.ok and asked == [True] and later == []
    model.meta.train["print_px"] = int(refused.width_px)  # as wide as it needs: the later looks too
    assert not trained_wider.aligned_too_narrow(aligned.alignment)
    trained_wider.decode_drawing(gray, pyramid, aligned.alignment, 1.0, cam, "detector", True)
    assert asked[1] is False and "flat sheet" in later


def located_print(
    locator: Locator, across: float, along: float, corrected: int, ok: bool = True, every_way: bool = False
) -> Located:
    """A reading of a print seen ``across`` px wide and ``along`` px high (a tilt about its
    horizontal axis foreshortens it so), needing 96 px, read with ``corrected`` corrections."""
    corners = np.array([[0, 0], [across, 0], [across, along], [0, along]], np.float64) + 40.0
    H = cv2.getPerspectiveTransform(locator.frame_corners.astype(np.float32), corners.astype(np.float32))
    result = DecodeResult(np.ones(5, np.uint8), ok, corrected if ok else -1, 0.95)
    return Located(result, np.full(5, 0.5, np.float32), corners=corners, homography=H, needs_px=96.0,
                   needs_every_way=every_way)  # fmt: skip


def test_a_colour_print_narrower_than_the_frame_keeps_a_payload_only_read_without_corrections(locator) -> None:
    """Narrower than the decoder's frame, a colour print's reading that needed corrections is
    refused (too small), one without is kept; black ink keeps both, and a model trained for
    wider prints refuses any narrower reading. As wide as the frame or wider, nothing is refused."""
    from deepmorph_detect.locate import refuses_narrow_reading

    def read(width: float, corrected: int, ok: bool = True) -> Located:
        return located_print(locator, width, width, corrected, ok=ok)

    narrow, wide = 62.0, 120.0
    assert read(narrow, 1).too_narrow and not read(wide, 1).too_narrow
    assert refuses_narrow_reading(read(narrow, 1), None, colour=True)
    assert refuses_narrow_reading(read(narrow, 2), None, colour=True)
    assert not refuses_narrow_reading(read(narrow, 0), None, colour=True)
    assert not refuses_narrow_reading(read(narrow, 2), None, colour=False)
    assert not refuses_narrow_reading(read(wide, 2), None, colour=True)
    assert refuses_narrow_reading(read(narrow, 0), 150, colour=False)
    assert not refuses_narrow_reading(read(narrow, 0, ok=False), None, colour=True)  # nothing read, nothing refused


def test_a_colour_print_seen_steeply_is_as_narrow_as_its_tilt_leaves_it(locator) -> None:
    """A print wide enough head-on but foreshortened by its tilt to fewer pixels than the decoder's
    frame along one direction: where its width counts every way (a colour drawing's,
    ``needs_every_way``), it is too narrow there, its corrected reading is refused (any reading
    under half the frame), and it is reported seen too steeply; a black-and-white one counts its
    head-on width, as before."""
    from deepmorph_detect.locate import refuses_narrow_reading
    from deepmorph_detect.results import too_small_reason

    def read(across: float, along: float, corrected: int, every_way: bool) -> Located:
        return located_print(locator, across, along, corrected, every_way=every_way)

    steep = read(135.0, 26.0, 1, every_way=True)
    assert steep.width_px == pytest.approx(135.0) and steep.along_tilt_px == pytest.approx(26.0)
    assert steep.too_narrow and refuses_narrow_reading(steep, None, colour=True)
    assert not refuses_narrow_reading(read(135.0, 60.0, 0, every_way=True), None, colour=True)
    # under half the frame along its tilt (COLOUR_FLOOR_SHARE), even a reading without corrections
    assert refuses_narrow_reading(read(135.0, 26.0, 0, every_way=True), None, colour=True)
    assert not refuses_narrow_reading(read(135.0, 26.0, 0, every_way=True), None, colour=False)
    assert not read(135.0, 26.0, 1, every_way=False).too_narrow  # black ink: its head-on width
    assert not read(135.0, 110.0, 3, every_way=True).too_narrow  # tilted, still wide enough every way
    size = steep.size_json()
    assert size == {"width_px": 135.0, "needs_px": 96.0, "along_tilt_px": 26.0}
    assert too_small_reason(size) == "seen too steeply to read (26 px along its tilt, 135 px across; needs 96)"
    small = read(80.0, 60.0, 1, every_way=True).size_json()
    assert too_small_reason(small) == "too small to read (80 px across, needs 96)"
    assert "along_tilt_px" not in read(80.0, 60.0, 1, every_way=False).size_json()


def _read_with_every_check_passing(locator, monkeypatch, corrections: list[int], confidence: float = 0.9) -> tuple:
    """A print of payload 0 in an easy close-up, aligned; its looks give a reading of payload 0
    with each of ``corrections`` in turn, and every reading checked passes. Returns the photo's
    gray, pyramid and alignment, and the list the corrections of each checked reading go to."""
    from deepmorph_detect.check import MorphFit, PayloadCheck
    from deepmorph_detect.read import Reading

    rng = np.random.default_rng(3)
    payload = np.zeros(locator.model.codec.spec.payload_bits, np.uint8)
    photo = close_up_photo(render_svg(locator.model.encode(payload), 400), "easy", rng, size=160)
    gray, _, pyramid, (aligned,) = locator._proposed(photo, None)
    probs = np.full(locator.model.codec.spec.code_bits, 0.9, np.float32)
    checked: list[int] = []

    def passes(pyramid, H, result, *args, **kwargs) -> PayloadCheck:
        checked.append(result.corrected_bits)
        return PayloadCheck(result, MorphFit(H, 0.95, 0.94), "passed")

    def looks(*args, **kwargs):
        return ((Reading(DecodeResult(payload, True, c, confidence), probs), None) for c in list(corrections))

    monkeypatch.setattr(locator.checker, "check", passes)
    monkeypatch.setattr(locator.reader, "looks", looks)
    return gray, pyramid, aligned.alignment, checked


def test_a_print_keeping_only_uncorrected_readings_looks_on_for_one(locator, monkeypatch) -> None:
    """Where a reading with corrections would be refused for the print's size
    (``keeps_only_uncorrected``), a passing one is kept aside and the looks go on: a later
    reading without corrections wins; without one, the reading kept aside is returned (and
    refused as too small), and the corrected readings after it are not checked."""
    corrections: list[int] = []
    gray, pyramid, alignment, checked = _read_with_every_check_passing(locator, monkeypatch, corrections)
    monkeypatch.setattr(locator, "keeps_only_uncorrected", lambda H: True)
    for looks, kept, asked in (([2, 1, 0], 0, [2, 0]), ([2, 1], 2, [2])):
        checked.clear()
        corrections[:] = looks
        _, verdict, _ = locator._read_and_check(gray, pyramid, alignment, "detector", True, False)
        assert verdict.status == "passed" and verdict.result.corrected_bits == kept and checked == asked
    monkeypatch.setattr(locator, "keeps_only_uncorrected", lambda H: False)  # wide enough: the first passing wins
    checked.clear()
    _, verdict, _ = locator._read_and_check(gray, pyramid, alignment, "detector", True, False)
    assert verdict.result.corrected_bits == 2 and checked == [2]


def test_a_reading_repaired_too_far_is_not_vouched_for_in_its_templates_light(locator, monkeypatch) -> None:
    """In a photo lit by the drawing's own template a reading that needed more than
    ``RELIT_MAX_CORRECTIONS`` corrections is not checked and counts as not read (a wrong word
    with 4 passed every rule there); in the photo itself the check decides, as before."""
    from deepmorph_detect.check import RELIT_MAX_CORRECTIONS

    looks = [RELIT_MAX_CORRECTIONS + 1, RELIT_MAX_CORRECTIONS]
    corrections = list(looks)
    gray, pyramid, alignment, checked = _read_with_every_check_passing(locator, monkeypatch, corrections, 0.86)
    monkeypatch.setattr(locator, "keeps_only_uncorrected", lambda H: False)
    for relit_from, asked in ((0.9, looks[1:]), (None, looks[:1])):
        checked.clear()
        _, verdict, _ = locator._read_and_check(gray, pyramid, alignment, "detector", True, False, relit_from)
        assert verdict.status == "passed" and verdict.result.corrected_bits == asked[0] and checked == asked
    corrections.pop()  # relit, only the reading repaired too far: not read
    _, verdict, _ = locator._read_and_check(gray, pyramid, alignment, "detector", True, False, 0.9)
    assert not verdict.result.ok and verdict.status == "not run"


def test_a_colour_print_too_narrow_for_its_frame_is_not_read_again_in_its_templates_light(locator, monkeypatch) -> None:
    """A print not read is aligned and read again in the light its template shows, unless its
    readings with corrections would be refused for its size (``keeps_only_uncorrected``: a colour
    print narrower than the decoder's frame along its tilt, where that light takes up the morph's
    edges); the grid of light is tried either way. Black ink is always lit so."""
    import deepmorph_detect.locate as locate_module

    rng = np.random.default_rng(3)
    payload = np.zeros(locator.model.codec.spec.payload_bits, np.uint8)
    photo = close_up_photo(render_svg(locator.model.encode(payload), 400), "easy", rng, size=160)
    gray, _, pyramid, (aligned,) = locator._proposed(photo, None)
    cam = locator.frame(photo, None)[1]
    tried: list[str] = []

    def unread(*args, **kwargs) -> tuple:
        result = DecodeResult(np.zeros_like(payload), False, -1, 0.5)
        return aligned.alignment.homography, locate_module.PayloadCheck(result, None, "not run"), np.full(8, 0.5)

    monkeypatch.setattr(locator, "_read_and_check", unread)
    monkeypatch.setattr(locator.aligner, "as_flat_sheet", lambda *a, **k: None)
    monkeypatch.setattr(locator.light, "align", lambda *a, **k: tried.append("template's light"))
    monkeypatch.setattr(locate_module, "realign_in_light_field", lambda *a, **k: tried.append("grid of light"))
    assert aligned.alignment.correlation >= locate_module.BLIND_READ_CORRELATION
    assert locator.relights(aligned.alignment)  # black ink
    for narrow, expected in ((False, ["template's light", "grid of light"]), (True, ["grid of light"])):
        tried.clear()
        monkeypatch.setattr(locator, "keeps_only_uncorrected", lambda H, narrow=narrow: narrow)
        assert locator.relights(aligned.alignment) is not narrow
        found = locator.decode_drawing(gray, pyramid, aligned.alignment, 1.0, cam, "detector", True)
        assert not found.result.ok and tried == expected


def test_a_payload_fused_over_frames_of_a_print_too_narrow_is_refused_too() -> None:
    """Fused over the frames of a sequence, the readings of a print narrower than its model was
    trained for (the ghost, told it was trained for prints 150 px wide) give no payload either:
    the sequence's entry says too small. At its width, the same frames fuse to the payload."""
    from deepmorph_detect.reading import SequenceReader

    model = DeepMorphModel.load(BUNDLED_MODEL)
    rng = np.random.default_rng(3)
    payload = rng.integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8)
    art = render_svg(model.encode(payload), 400)
    frames = [close_up_photo(art, "easy", rng, size=160) for _ in range(3)]
    entries = {}
    for trained_px in (None, 150):
        model.meta.train["print_px"] = trained_px
        reader = SequenceReader(Locator(model))
        for i, frame in enumerate(frames):
            reader.add(f"frame{i}", frame)
        (entries[trained_px],) = reader.fused()
    assert entries[None]["ok"] and entries[None]["payload"]["bits"] == "".join(map(str, payload))
    refused = entries[150]
    assert not refused["ok"] and refused["frames"] == 3
    assert refused["too_small"]["needs_px"] == 150.0 and 96 < refused["too_small"]["width_px"] < 150
