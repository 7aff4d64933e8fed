"""``deepmorph train-verifier``: labels, the threshold rule, a short run stored in the bundle and
read back, and the errors it gives."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.verifier import (
    SCENE_FRAME,
    VerifierConfig,
    print_labels,
    scores,
    threshold_for,
    train_verifier,
    turned,
)
from deepmorph_core.bundled import BUNDLED_DRAWING, BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.locate import Locator
from deepmorph_detect.scenes import SceneMaker
from deepmorph_detect.verifier import proposal_crop, stored_verifier

app = application()
runner = CliRunner()


@pytest.fixture(scope="module")
def universal_ghost(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bundled ghost without its own detector: read with the universal detector, as a model
    fresh from ``deepmorph train`` is."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    model.meta.detector = None
    model.detector_state = {}
    model.graphs.pop("detector", None)
    path = tmp_path_factory.mktemp("verifier") / "ghost.dmm"
    model.save(path)
    return path


@pytest.fixture(scope="module")
def trained(universal_ghost: Path) -> Path:
    """A verifier from a short run (seconds): too short to sort well, long enough for the bundle."""
    out = universal_ghost.with_name("verified.dmm")
    train_verifier(universal_ghost, out, VerifierConfig(scenes=6, check_scenes=3, steps=60, batch=16, workers=0))
    return out


def test_a_proposal_is_a_print_where_it_lies_on_one(universal_ghost: Path) -> None:
    model = DeepMorphModel.load(universal_ghost)
    scene = SceneMaker(model, SCENE_FRAME, "medium", seed=4).make(drawings=1, distractors=1, aruco=True)
    middles = np.array([np.mean(p.corners, 0) for p in scene.placements])
    labels = print_labels(middles, scene)
    assert labels.tolist() == [p.kind == "drawing" for p in scene.placements]
    (drawing,) = [p for p in scene.placements if p.kind == "drawing"]
    diagonal = float(np.linalg.norm(drawing.corners[2] - drawing.corners[0]))
    near = np.mean(drawing.corners, 0) + [0.3 * diagonal, 0]
    far = np.mean(drawing.corners, 0) + [0.4 * diagonal, 0]
    assert print_labels(np.array([near, far]), scene).tolist() == [True, False]
    assert print_labels(np.zeros((0, 2)), scene).tolist() == []


def test_the_threshold_is_half_the_lowest_held_out_print_at_most_its_cap() -> None:
    assert threshold_for(np.array([0.9, 0.04, 0.7])) == pytest.approx(0.02)
    assert threshold_for(np.array([0.9, 0.6])) == pytest.approx(0.1)
    assert threshold_for(np.array([0.9, 0.6]), most=0.2) == pytest.approx(0.2)


def test_training_turns_crops_by_any_angle() -> None:
    """A detector's outline says nothing of the print's turn: crops are turned by random angles
    (a quarter turn is rot90's, pixel for pixel)."""
    crops = torch.zeros(3, 1, 64, 64)
    crops[:, :, 10:20, 30:34] = 1
    out = turned(crops, np.array([0.0, np.pi / 2, np.pi / 4]))
    torch.testing.assert_close(out[0], crops[0], atol=1e-5, rtol=0)
    torch.testing.assert_close(out[1], torch.rot90(crops[1], 1, (1, 2)), atol=1e-5, rtol=0)
    assert float(out[2].sum()) == pytest.approx(float(crops[2].sum()), rel=0.05)  # the bar turned, not lost
    assert not torch.allclose(out[2], crops[2], atol=0.1)


def test_a_short_run_stores_a_verifier_the_locator_uses(trained: Path) -> None:
    model = DeepMorphModel.load(trained)
    meta = model.meta.verifier
    assert meta is not None and 0 < meta.threshold <= 0.1
    check = meta.check
    assert check.scenes == 6 and check.prints >= 3
    # the rule keeps every held-out print: the threshold is at most half the lowest one's score
    assert check.prints_kept == check.prints and check.searched_prints_kept == check.searched_prints
    assert meta.threshold <= check.lowest_print_score / 2 + 1e-9
    assert meta.config["scenes"] == 6 and meta.crops > meta.print_crops > 0
    assert "verifier" in model.graphs and model.graphs["verifier"].meta.outputs == {"probability": [4]}
    net = stored_verifier(model)
    locator = Locator(model)
    assert locator.aligner.verifier is not None and locator.aligner.verifier.threshold == meta.threshold
    assert Locator(model, use_verifier=False).aligner.verifier is None
    # the graph ONNX Runtime runs scores a proposal as the network does
    scene = SceneMaker(model, SCENE_FRAME, "hard", seed=5).make(drawings=1, distractors=1)
    gray = locator.frame(scene.image, None)[0]
    for placement in scene.placements:
        want = float(scores(net, proposal_crop(gray, placement.corners)[None])[0])
        assert locator.aligner.verifier.score(gray, placement.corners) == pytest.approx(want, abs=1e-5)


def test_info_shows_the_verifier(trained: Path) -> None:
    result = runner.invoke(app, ["info", str(trained), "--json"])
    assert result.exit_code == 0, result.output
    shown = json.loads(result.stdout)["verifier"]
    assert shown["threshold"] == DeepMorphModel.load(trained).meta.verifier.threshold
    text = runner.invoke(app, ["info", str(trained)]).stdout
    assert "verifier" in text and "prints kept" in text


def test_a_bundle_with_its_verifier_damaged_is_refused(trained: Path, tmp_path: Path) -> None:
    model = DeepMorphModel.load(trained)
    model.verifier_state = {k: v for k, v in model.verifier_state.items() if "logit" not in k}
    model.graphs.pop("verifier", None)
    model.save(tmp_path / "cut.dmm")
    with pytest.raises(DeepMorphError, match="verifier's weights do not fit: logit"):
        Locator(DeepMorphModel.load(tmp_path / "cut.dmm"))
    model.verifier_state = {}
    model.save(tmp_path / "none.dmm")
    with pytest.raises(DeepMorphError, match=r"verifier weights are missing"):
        DeepMorphModel.load(tmp_path / "none.dmm")


def test_the_command_refuses_a_model_with_its_own_detector_and_an_existing_out(
    universal_ghost: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out.dmm"
    result = runner.invoke(app, ["train-verifier", str(BUNDLED_MODEL), "--out", str(out)])
    assert result.exit_code != 0 and "has its own detector" in result.output
    assert "Traceback" not in result.output and not out.exists()
    out.write_bytes(b"keep me")
    result = runner.invoke(app, ["train-verifier", str(universal_ghost), "--out", str(out)])
    assert result.exit_code != 0 and "already exists" in result.output
    assert out.read_bytes() == b"keep me"


def test_the_command_trains_in_place(universal_ghost: Path, tmp_path: Path) -> None:
    model = tmp_path / "ghost.dmm"
    model.write_bytes(universal_ghost.read_bytes())
    args = ["--scenes", "3", "--check-scenes", "2", "--steps", "20", "--workers", "0", "--json"]
    result = runner.invoke(app, ["train-verifier", str(model), "--out", str(model), *args])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["check"]["scenes"] == 4
    assert DeepMorphModel.load(model).meta.verifier.threshold == summary["threshold"]


def test_export_writes_the_verifier_graph_a_host_program_can_run(trained: Path, tmp_path: Path) -> None:
    """``verifier.onnx`` with its manifest entry: the crop the manifest describes, at its four
    quarter turns, scored by ONNX Runtime, gives the chain's score."""
    import onnxruntime

    result = runner.invoke(app, ["export", str(trained), "--out", str(tmp_path / "export"), "--json"])
    assert result.exit_code == 0, result.output
    manifest = json.loads((tmp_path / "export" / "manifest.json").read_text())
    entry = manifest["verifier"]
    model = DeepMorphModel.load(trained)
    assert entry["threshold"] == model.meta.verifier.threshold and entry["input"]["shape"] == [4, 1, 64, 64]
    session = onnxruntime.InferenceSession(str(tmp_path / "export" / entry["file"]))
    scene = SceneMaker(model, SCENE_FRAME, "medium", seed=6).make(drawings=1, distractors=1)
    locator = Locator(model)
    gray = locator.frame(scene.image, None)[0]
    for placement in scene.placements:
        crop = proposal_crop(gray, placement.corners)
        turned = np.stack([np.rot90(crop, k) for k in range(4)])[:, None].astype(np.float32)
        (probability,) = session.run(None, {entry["input"]["name"]: turned})
        assert float(probability.max()) == pytest.approx(
            locator.aligner.verifier.score(gray, placement.corners), abs=1e-5
        )


def test_train_ends_with_a_verifier_for_a_print_size(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """``train --pixels``: once the codec is written and validated, its proposal verifier is
    trained on the training's seed and threads and stored in the same bundle (here with short
    verifier settings, as the fixture's); ``--json`` reports it. Without ``--pixels`` no verifier
    is trained unless ``--verifier`` asks, and the bundle stores which was chosen."""
    import deepmorph.training.verifier as verifier_module

    class Short(VerifierConfig):
        scenes: int = 4
        check_scenes: int = 2
        steps: int = 30
        batch: int = 16
        workers: int = 0

    monkeypatch.setattr(verifier_module, "VerifierConfig", Short)
    base = ["train", str(BUNDLED_DRAWING), "--steps", "2", "--batch", "2", "--threads", "1", "--payload-bits", "4"]
    base += ["--validation", "0", "--seed", "3"]
    out = tmp_path / "sized.dmm"
    result = runner.invoke(app, [*base, "--pixels", "64", "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    reported = json.loads(result.stdout)["verifier"]
    model = DeepMorphModel.load(out)
    meta = model.meta.verifier
    assert meta is not None and model.meta.train["verifier"] is True and "verifier" in model.graphs
    assert reported["threshold"] == meta.threshold and reported["bundle"] == str(out)
    assert meta.config["seed"] == 3 and meta.config["scenes"] == 4 and meta.threads == 1
    assert meta.check.prints_kept == meta.check.prints > 0
    assert Locator(model).aligner.verifier is not None
    plain = tmp_path / "plain.dmm"
    result = runner.invoke(app, [*base, "--out", str(plain)])
    assert result.exit_code == 0, result.output
    model = DeepMorphModel.load(plain)
    assert model.meta.verifier is None and model.meta.train["verifier"] is False
    asked = tmp_path / "asked.dmm"
    result = runner.invoke(app, [*base, "--verifier", "--out", str(asked)])
    assert result.exit_code == 0, result.output
    assert "verifier: threshold" in result.stdout
    assert DeepMorphModel.load(asked).meta.verifier is not None
