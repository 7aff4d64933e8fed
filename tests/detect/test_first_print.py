"""``locate(first=True)``: the first print read, alone, before any other drawing's wider searches;
and the full search unchanged by its quick looks being taken first."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.locate import Locator
from deepmorph_detect.scenes import Scene, SceneMaker


@pytest.fixture(scope="module")
def universal() -> Locator:
    """The bundled ghost read with the universal detector (blind: it proposes other drawings too)."""
    return Locator(DeepMorphModel.load(BUNDLED_MODEL), detector="universal")


def _scene(locator: Locator, seed: int, drawings: int = 1) -> Scene:
    return SceneMaker(locator.model, severity="medium", seed=seed).make(drawings=drawings, distractors=1)


def _payloads(found: list) -> list[bytes]:  # noqa: ANN001
    return [np.asarray(d.result.payload, np.uint8).tobytes() for d in found if d.result.ok]


def _calls(monkeypatch: pytest.MonkeyPatch, owner: object, name: str) -> list[tuple]:
    """The arguments of each call of ``owner.name`` from now on (the method still runs)."""
    calls: list[tuple] = []
    real = getattr(owner, name)
    monkeypatch.setattr(owner, name, lambda *args: calls.append(args) or real(*args))
    return calls


def test_the_first_print_is_read_before_the_other_drawing_proposed_above_it_is_searched(
    universal: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Seed 1: the universal detector scores the other drawing above the print. Every print read
    searches it in flat light; the first print read does not, and gives the same payload."""
    scene = _scene(universal, seed=1)
    (truth,) = [p for p in scene.placements if p.kind == "drawing"]
    flat_light = _calls(monkeypatch, universal.aligner, "in_flat_light")
    every = universal.locate(scene.image)
    assert flat_light, "the other drawing's outline is searched in flat light"
    flat_light.clear()
    first = universal.locate(scene.image, first=True)
    assert flat_light == []
    assert len(first) == 1 and first[0].result.ok
    assert _payloads(first) == [np.asarray(truth.payload, np.uint8).tobytes()]
    assert _payloads(first)[0] in _payloads(every)


def test_a_print_read_in_the_photo_itself_leaves_its_mirror_image_unread(
    universal: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The universal detector reads the photo, then its mirror image: the first print read from
    the photo's own proposals ends the search before the network runs again."""
    scene = _scene(universal, seed=2)
    (truth,) = [p for p in scene.placements if p.kind == "drawing"]
    runs = _calls(monkeypatch, universal.detector, "_peaks")
    every = universal.locate(scene.image)
    assert len(runs) == 2
    runs.clear()
    first = universal.locate(scene.image, first=True)
    assert len(runs) == 1
    assert _payloads(first) == [np.asarray(truth.payload, np.uint8).tobytes()]
    assert _payloads(first)[0] in _payloads(every)


def test_a_print_no_earlier_stage_proposes_is_read_in_a_later_one_each_outline_looked_at_once(
    universal: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where a stage's proposals read nothing, the next stage's are tried; an outline proposed
    again there keeps the quick look it had."""
    scene = _scene(universal, seed=1)
    (truth,) = [p for p in scene.placements if p.kind == "drawing"]
    gray, _, _ = universal.frame(scene.image, None)
    every = universal.proposals(scene.image, gray)
    centre = truth.corners.mean(0)
    others = [c for c in every if np.linalg.norm(c.corners.mean(0) - centre) > 0.5 * np.ptp(truth.corners[:, 0])]
    assert others and len(others) < len(every)
    monkeypatch.setattr(universal.detector, "detect_in_stages", lambda image: iter([others, every]))
    calls = _calls(monkeypatch, universal.aligner, "quick_look")
    first = universal.locate(scene.image, first=True)
    looked = [cand for _, cand, _ in calls]
    assert _payloads(first) == [np.asarray(truth.payload, np.uint8).tobytes()]
    assert len(looked) == len(every) and {id(c) for c in looked} == {id(c) for c in every}


def test_of_two_prints_the_first_read_comes_alone(universal: Locator) -> None:
    scene = _scene(universal, seed=3, drawings=2)
    every = _payloads(universal.locate(scene.image))
    assert len(every) == 2
    first = universal.locate(scene.image, first=True)
    assert len(first) == 1 and _payloads(first)[0] in every


def test_quick_looks_taken_first_leave_every_alignment_as_it_was(universal: Locator) -> None:
    """The full search takes the quick looks of every outline before the wider searches of any:
    the same alignments as taking each outline's in turn."""
    for seed in (1, 4, 13):
        scene = _scene(universal, seed)
        gray, _, pyramid = universal.frame(scene.image, None)
        candidates = universal.proposals(scene.image, gray)
        looks = universal.aligner.quick_looks(pyramid, candidates, gray)
        assert any(look is not None and not look.final for look in looks)
        before = universal.aligner.verify(pyramid, candidates, gray, looks)
        after = universal.aligner.verify(pyramid, candidates, gray)
        assert [a.candidate for a in before] == [a.candidate for a in after]
        for a, b in zip(before, after, strict=True):
            assert a.alignment.correlation == b.alignment.correlation
            np.testing.assert_array_equal(a.alignment.homography, b.alignment.homography)


def test_decode_first_gives_one_drawing_per_image(tmp_path: Path) -> None:
    scene = SceneMaker(DeepMorphModel.load(BUNDLED_MODEL), severity="easy", seed=3).make(drawings=2, distractors=1)
    photo = tmp_path / "two.png"
    cv2.imwrite(str(photo), scene.image)  # BGR
    counts = {}
    for flags in ([], ["--first"]):
        done = CliRunner().invoke(application(), ["decode", str(BUNDLED_MODEL), str(photo), "--json", *flags])
        assert done.exit_code == 0, done.output
        (entry,) = json.loads(done.stdout)
        counts[" ".join(flags)] = sum(d["ok"] for d in entry["detections"])
    assert counts == {"": 2, "--first": 1}


def test_a_sequence_read_with_first_follows_one_drawing(tmp_path: Path) -> None:
    import deepmorph

    scene = SceneMaker(DeepMorphModel.load(BUNDLED_MODEL), severity="easy", seed=3).make(drawings=2, distractors=1)
    frames = tmp_path / "frames"
    frames.mkdir()
    for k in range(2):
        cv2.imwrite(str(frames / f"{k}.png"), scene.image)
    model = deepmorph.load(BUNDLED_MODEL, device="cpu")
    assert len(model.decode(scene.image, bgr=True, first=True)) == 1
    every = model.decode_sequence(frames).detections
    first = model.decode_sequence(frames, first=True).detections
    assert sum(d["ok"] for d in every) == 2
    assert [d["ok"] for d in first] == [True] and first[0]["payload"] in [d["payload"] for d in every]
