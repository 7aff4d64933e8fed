"""The proposal verifier in the photo chain: its crop, its ONNX graph, and the gate before a blind
proposal's wider searches (a trained one: tests/app/test_verifier_training.py)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.protocols import Candidate
from deepmorph_detect.align import QuickLook
from deepmorph_detect.locate import Locator
from deepmorph_detect.scenes import SceneMaker
from deepmorph_detect.verifier import (
    CROP_SIZE,
    ProposalVerifier,
    VerifierNet,
    proposal_crop,
    quarter_turns,
    verifier_graph,
)


def _photo() -> np.ndarray:
    rng = np.random.default_rng(0)
    return cv2.GaussianBlur(rng.random((240, 320)).astype(np.float32), (0, 0), 3)


QUAD = np.array([[50.0, 40.0], [200.0, 60.0], [190.0, 170.0], [60.0, 160.0]])


def test_the_crop_turns_with_the_corner_order() -> None:
    """The detector does not know which corner is the drawing's top left: its corners rolled by
    one give the same crop turned by a quarter turn, pixel for pixel, so the best score over the
    four turns does not depend on the order."""
    gray = _photo()
    crop = proposal_crop(gray, QUAD)
    assert crop.shape == (CROP_SIZE, CROP_SIZE) and crop.dtype == np.float32
    for k in range(1, 4):
        rolled = proposal_crop(gray, np.roll(QUAD, k, 0))
        np.testing.assert_allclose(rolled, np.rot90(crop, -k), atol=1e-5)
        assert np.abs(rolled - crop).max() > 0.1


def test_the_crop_is_stretched_whatever_the_exposure() -> None:
    gray = _photo()
    dim = proposal_crop(0.2 + 0.3 * gray, QUAD)
    np.testing.assert_allclose(dim, proposal_crop(gray, QUAD), atol=1e-4)
    assert np.percentile(dim, 50) == pytest.approx(0.5, abs=0.3)
    assert dim.min() >= -0.5 and dim.max() <= 1.5


def test_the_graph_scores_as_pytorch_and_the_score_ignores_the_corner_order() -> None:
    torch.manual_seed(3)
    net = VerifierNet().eval()
    for module in net.modules():  # batch norms that are not the identity
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.2, 0.2)
            module.running_var.uniform_(0.5, 2.0)
    graph = verifier_graph(net)
    assert graph.meta.inputs == {"crops": [4, 1, CROP_SIZE, CROP_SIZE]}
    gray = _photo()
    with torch.inference_mode():
        want = float(torch.sigmoid(net(quarter_turns(torch.from_numpy(proposal_crop(gray, QUAD))[None, None]))).max())
    verifier = ProposalVerifier(net, 0.5)
    assert verifier.score(gray, QUAD) == pytest.approx(want, abs=1e-5)
    assert verifier.score(gray, np.roll(QUAD, 1, 0)) == pytest.approx(want, abs=1e-5)
    assert verifier.turns_away(gray, QUAD) == (want < 0.5)


@pytest.fixture(scope="module")
def universal() -> Locator:
    """The bundled ghost read with the universal detector (blind: it proposes other drawings too)."""
    return Locator(DeepMorphModel.load(BUNDLED_MODEL), detector="universal")


def _searches(monkeypatch: pytest.MonkeyPatch, locator: Locator) -> list[object]:
    calls: list[object] = []
    real = locator.aligner.in_flat_light
    monkeypatch.setattr(locator.aligner, "in_flat_light", lambda *args: calls.append(args) or real(*args))
    return calls


def test_a_blind_outline_turned_away_skips_the_wider_searches_and_keeps_its_quick_look(
    universal: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Seed 1: the other drawing's outline is searched in flat light. With a verifier that turns
    every proposal away (threshold 1) it is not, the print (aligned at once) still reads the
    same payload; at threshold 0 the searches run as without a verifier."""
    scene = SceneMaker(universal.model, severity="medium", seed=1).make(drawings=1, distractors=1)
    (truth,) = [p.payload for p in scene.placements if p.kind == "drawing"]
    searches = _searches(monkeypatch, universal)
    without = universal.locate(scene.image)
    assert searches and [d.result.payload.tolist() for d in without if d.result.ok] == [truth.tolist()]
    net = VerifierNet().eval()
    for threshold, searched in ((1.0, False), (0.0, True)):
        searches.clear()
        monkeypatch.setattr(universal.aligner, "verifier", ProposalVerifier(net, threshold))
        found = universal.locate(scene.image)
        assert bool(searches) == searched
        assert [d.result.payload.tolist() for d in found if d.result.ok] == [truth.tolist()]


def test_the_verifier_decides_on_blind_outlines_only(universal: Locator, monkeypatch: pytest.MonkeyPatch) -> None:
    """An outline from a detector that knows the drawing is searched whatever a verifier says:
    it proposes nothing else."""
    scene = SceneMaker(universal.model, severity="medium", seed=1).make(drawings=1, distractors=0)
    gray, _, pyramid = universal.frame(scene.image, None)
    (truth,) = [p for p in scene.placements if p.kind == "drawing"]
    monkeypatch.setattr(universal.aligner, "verifier", ProposalVerifier(VerifierNet().eval(), 1.0))
    searches = _searches(monkeypatch, universal)
    weak = QuickLook(None, final=False, weak=True)
    for blind, searched in ((True, False), (False, True)):
        searches.clear()
        cand = Candidate(truth.corners, 0.9, (0, 0, gray.shape[1], gray.shape[0]), blind=blind, sized=blind)
        universal.aligner.align_outline(pyramid, cand, gray, weak)
        assert bool(searches) == searched


def test_a_model_without_a_verifier_has_none() -> None:
    """Bundles from before the verifier (the bundled ghost) load and locate as before."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    assert model.meta.verifier is None and model.verifier_state == {}
    assert Locator(model, detector="universal").aligner.verifier is None
