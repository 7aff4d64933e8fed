"""The universal detector: ink squares, the held-out rule, its file, training and resume, and the
shipped network finding drawings it was never trained on."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from deepmorph.training.loop import Interrupted, read_log
from deepmorph.training.universal import (
    PANEL_DRAWINGS,
    PoolSceneMaker,
    UniversalConfig,
    held_out,
    load_pool,
    train_universal,
)
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.plugins import default_registry
from deepmorph_detect.camera import project
from deepmorph_detect.centrenet import CentreNetDetector
from deepmorph_detect.locate import Locator, detector_for
from deepmorph_detect.metrics import corner_error
from deepmorph_detect.scenes import SceneMaker
from deepmorph_detect.universal import (
    UNIVERSAL_PATH,
    UniversalDetector,
    ink_square,
    load_universal,
    merged_with_mirrored,
    shared_runner,
    unmirrored,
)
from tests.pretend_cuda import pretend_cuda

DATA = Path(__file__).resolve().parents[1] / "data"
FOLDERS = [DATA / "feather", DATA / "flat-color-icons"]


def test_ink_square_is_centred_on_the_ink_box_and_as_wide_as_its_longer_side() -> None:
    svg = '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 50"><rect x="60" y="10" width="30" height="20"/></svg>'
    square = ink_square(svg, (0, 0, 100, 50))
    # ink box x 60..90, y 10..30: centre (75, 20), side 30
    np.testing.assert_allclose(square, [[60, 5], [90, 5], [90, 35], [60, 35]], atol=0.5)


def test_ink_square_of_a_blank_drawing_is_its_viewbox() -> None:
    svg = '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 10 20"><rect width="1" height="1" fill="#fff"/></svg>'
    np.testing.assert_allclose(ink_square(svg, (0, 0, 10, 20)), [[0, 0], [10, 0], [10, 20], [0, 20]])


def test_held_out_drawings_are_the_panels_and_one_in_eight_by_name() -> None:
    assert all(held_out(name) for name in PANEL_DRAWINGS)
    names = [f"icon-{i}" for i in range(4000)]
    share = sum(held_out(n) for n in names) / len(names)
    assert 0.10 < share < 0.15  # 32 / 256 = 0.125
    by_hash = next(n for n in names if hashlib.sha256(n.encode()).digest()[0] < 32)
    assert held_out(by_hash)
    pool = load_pool(FOLDERS)
    trained = {d.name for drawings in pool.sets.values() for d in drawings}
    assert trained and not any(held_out(n) for n in trained)


def test_pool_scenes_mark_each_print_by_its_ink_square() -> None:
    pool = load_pool(FOLDERS, limit=6)
    scene = PoolSceneMaker(pool, (320, 240), "easy", seed=3, camera_width=None).make(drawings=2)
    drawings = [p for p in scene.placements if p.kind == "drawing"]
    assert drawings
    gray = scene.image.astype(np.float32).mean(-1) / 255
    for p in drawings:
        x0, y0 = np.floor(p.corners.min(0)).astype(int)
        x1, y1 = np.ceil(p.corners.max(0)).astype(int)
        inside = gray[max(y0, 0) : y1, max(x0, 0) : x1]
        # the square holds ink: its darkest pixels are darker than the paper around them
        assert inside.min() < np.percentile(inside, 90) - 0.2


def _config(steps: int) -> UniversalConfig:
    return UniversalConfig(steps=steps, batch=2, workers=0, checkpoint_every=2, log_every=1, seed=5)


def test_it_trains_on_the_device_it_is_given(tmp_path: Path) -> None:
    """``device="cuda"`` on a pretend CUDA device (``tests/pretend_cuda.py``): no operation mixes
    the device's tensors with the CPU's, the file records the device and holds the graph, and the
    weights are the CPU's (the pretend device computes as the CPU does)."""
    on_cpu, on_cuda = tmp_path / "cpu.safetensors", tmp_path / "cuda.safetensors"
    train_universal(FOLDERS, on_cpu, _config(2).model_copy(update={"device": "cpu"}), limit=3)
    with pretend_cuda() as device:
        train_universal(FOLDERS, on_cuda, _config(2).model_copy(update={"device": "cuda"}), limit=3)
    assert not device.mixes, device.mixes
    a, b = load_universal(on_cpu), load_universal(on_cuda)
    assert a[2].record.device == "cpu" and b[2].record.device == "cuda" and b[1] is not None
    for key, val in a[0].state_dict().items():
        assert torch.equal(val, b[0].state_dict()[key]), key


def test_short_training_checkpoints_and_resumes_exactly(tmp_path: Path) -> None:
    straight = tmp_path / "straight.safetensors"
    train_universal(FOLDERS, straight, _config(4), limit=5)
    cut = tmp_path / "cut.safetensors"

    def stop_at_2(m: dict) -> None:
        if m["step"] == 2:
            raise KeyboardInterrupt

    with pytest.raises(Interrupted, match=rf"checkpoint written to {re.escape(str(cut))} \(continue with --resume\)$"):
        train_universal(FOLDERS, cut, _config(4), limit=5, on_log=stop_at_2)
    assert [line["step"] for line in read_log(cut.with_suffix(".log.jsonl"))] == [1, 2]
    _, graph, meta, _ = load_universal(cut)
    assert meta.record.step == 2 and not meta.record.finished and graph is None
    train_universal(FOLDERS, cut, _config(4), resume=True, limit=5)
    a, b = load_universal(straight), load_universal(cut)
    assert b[2].record.finished and b[2].record.step == 4
    assert a[1] is not None and b[1] is not None and a[1].data == b[1].data
    for key, val in a[0].state_dict().items():
        assert torch.equal(val, b[0].state_dict()[key]), key
    usable = {f.name: min(5, sum(not held_out(svg.stem) for svg in f.glob("*.svg"))) for f in FOLDERS}
    assert b[2].training_set["sets"] == usable
    with pytest.raises(DeepMorphError, match="already exists"):
        train_universal(FOLDERS, cut, _config(4), limit=5)
    with pytest.raises(DeepMorphError, match="no interrupted training"):
        train_universal(FOLDERS, cut, _config(4), resume=True, limit=5)


def test_a_damaged_detector_file_is_one_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(UNIVERSAL_PATH.read_bytes()[:5000])
    with pytest.raises(DeepMorphError, match="not a usable DeepMorph detector file"):
        load_universal(bad)
    with pytest.raises(DeepMorphError, match="cannot read detector file"):
        load_universal(tmp_path / "missing.safetensors")
    with pytest.raises(DeepMorphError, match="format 'deepmorph-model/1'"):
        load_universal(BUNDLED_MODEL)


def test_the_shipped_detector_is_whole_and_was_not_trained_on_the_benchmarked_drawings() -> None:
    _, graph, meta, tensors = load_universal(UNIVERSAL_PATH)
    assert graph is not None and meta.record.finished
    assert not any(k.startswith("dtrain.") for k in tensors)  # no optimiser state shipped
    assert set(meta.training_set["sets"]) == {"feather", "flat-color-icons", "fluent-emoji-flat"}
    assert "panel" in meta.training_set["held_out_rule"]


def test_a_model_without_its_own_detector_uses_the_universal_one() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    registry = default_registry()
    assert isinstance(detector_for(model, None, registry), CentreNetDetector)  # the ghost has its own
    assert not isinstance(detector_for(model, None, registry), UniversalDetector)
    model.meta.detector = None
    assert isinstance(detector_for(model, None, registry), UniversalDetector)
    assert detector_for(model, "none", registry) is None


def test_the_universal_detector_finds_the_held_out_ghost_and_the_chain_reads_it() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    locator = Locator(model, detector="universal")
    found = read = 0
    for seed in range(6):
        scene = SceneMaker(model, severity="medium", seed=100 + seed).make(drawings=1, distractors=1)
        truth = next(p for p in scene.placements if p.kind == "drawing")
        candidates = locator.detector.detect(scene.image.astype(np.float32).mean(-1) / 255)
        # the corners in any cyclic order: alignment settles the turn
        errors = [min(corner_error(np.roll(c.corners, k, 0), truth.corners) for k in range(4)) for c in candidates]
        found += bool(errors) and min(errors) < 0.08 * np.ptp(truth.corners[:, 0])
        results = locator.locate(scene.image)
        read += any(r.result.ok and np.array_equal(r.result.payload, truth.payload) for r in results)
    assert found >= 5 and read >= 5


def test_a_quad_found_in_the_mirrored_photo_comes_back_with_its_corners_in_their_roles() -> None:
    quad = np.array([[100.0, 50.0], [180.0, 60.0], [170.0, 140.0], [90.0, 130.0]])  # TL, TR, BR, BL
    in_mirror = np.array([[640 - x, y] for x, y in quad])[[1, 0, 3, 2]]  # the mirror's TL is the TR
    np.testing.assert_allclose(unmirrored(in_mirror, 640), quad)


def test_mirrored_peaks_merge_with_their_prints_and_add_the_prints_missed() -> None:
    square = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]])
    first, second = square + 50, square + 400
    shifted = np.roll(first + 10, 1, 0)  # the same print, its corners listed from another one
    merged = merged_with_mirrored([(first, 0.6)], [(shifted, 0.3), (second, 0.25)])
    assert [score for _, score in merged] == [0.6, 0.25]
    np.testing.assert_allclose(merged[0][0], first + 10 / 3)  # averaged by score, in the photo's order
    np.testing.assert_allclose(merged[1][0], second)
    assert merged_with_mirrored([(first, 0.6)], []) == [(first, 0.6)]


def test_flip_testing_finds_the_same_prints_in_a_photo_and_in_its_mirror_image() -> None:
    """Read mirrored too, the detector proposes in a photo's mirror image the mirror images of
    what it proposes in the photo; read once, it does not quite (the network is not symmetric)."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    detector = Locator(model, detector="universal").detector
    scene = SceneMaker(model, severity="hard", seed=7).make(drawings=2, distractors=1)
    gray = scene.image.astype(np.float32).mean(-1) / 255
    mirror = np.ascontiguousarray(gray[:, ::-1])
    ink = np.array(detector.square, dtype=np.float64)

    def squares(image: np.ndarray, mirrored: bool) -> list[tuple[np.ndarray, float]]:
        out = []
        for c in detector.detect(image):
            to_image = cv2.getPerspectiveTransform(detector.frame.astype(np.float32), c.corners.astype(np.float32))
            quad = project(to_image, ink)
            out.append((unmirrored(quad, image.shape[1]) if mirrored else quad, c.score))
        return sorted(out, key=lambda q: tuple(q[0].mean(0).round()))

    def same(a: list, b: list) -> bool:
        return len(a) == len(b) and all(
            abs(sa - sb) < 1e-4 and min(np.abs(np.roll(qa, k, 0) - qb).max() for k in range(4)) < 1e-2
            for (qa, sa), (qb, sb) in zip(a, b)
        )

    assert detector.flip_test and len(squares(gray, False)) >= 2
    assert same(squares(gray, False), squares(mirror, True))
    detector.flip_test = False
    assert not same(squares(gray, False), squares(mirror, True))


def test_the_detector_proposes_in_stages_the_photos_own_then_merged_with_its_mirror_images() -> None:
    """``detect`` is the last stage; the first is the photo read once; a proposal the merge
    leaves alone is the same candidate in both stages."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    detector = Locator(model, detector="universal").detector
    scene = SceneMaker(model, severity="hard", seed=7).make(drawings=2, distractors=1)
    gray = scene.image.astype(np.float32).mean(-1) / 255

    def key(c) -> tuple:  # noqa: ANN001
        return (c.corners.tobytes(), c.score)

    own, merged = detector.detect_in_stages(gray)
    assert [key(c) for c in merged] == [key(c) for c in detector.detect(gray)]
    detector.flip_test = False
    try:
        (alone,) = detector.detect_in_stages(gray)
        assert [key(c) for c in alone] == [key(c) for c in own] == [key(c) for c in detector.detect(gray)]
    finally:
        detector.flip_test = True
    # each of the photo's own proposals is in the merged ones, as it was or averaged with its mirror image's
    assert len(merged) >= len(own)
    for c in own:
        side = np.linalg.norm(c.corners - np.roll(c.corners, 1, 0), axis=1).mean()
        assert min(np.linalg.norm(m.corners.mean(0) - c.corners.mean(0)) for m in merged) < 0.35 * side


def test_the_network_is_loaded_once_per_process() -> None:
    assert shared_runner() is shared_runner()


def test_a_model_without_its_own_detector_exports_the_universal_one(tmp_path: Path) -> None:
    import json

    from deepmorph.export import export_model

    model = DeepMorphModel.load(BUNDLED_MODEL)
    model.meta.detector = None
    model.detector_state = {}
    model.graphs.pop("detector", None)
    bare = tmp_path / "bare.dmm"
    model.save(bare)
    summary = export_model(bare, tmp_path / "onnx", bundle=tmp_path / "stored.dmm")
    assert set(summary.graphs) == {"decoder", "detector"} and any("universal" in n for n in summary.notes)
    manifest = json.loads((tmp_path / "onnx" / "manifest.json").read_text())
    det = manifest["detector"]
    assert det["name"] == "universal" and det["sha256"] == load_universal(UNIVERSAL_PATH)[1].meta.sha256
    md = model.drawing
    np.testing.assert_allclose(
        det["quadrilateral"]["corners"], ink_square(md.to_svg(md.neutral_values()[0]), md.drawing.viewbox), atol=1e-3
    )
    # the universal graph is not stored in the bundle, which holds no detector weights
    assert set(DeepMorphModel.load(tmp_path / "stored.dmm").graphs) == {"decoder"}


def test_a_blind_reading_is_checked_for_the_drawing_where_its_morph_fits_as_no_other_drawing_does_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The universal detector proposes every drawing. A confident reading of one it found skips
    the per-bit check where its decoded morph fits the photo at ``TRUSTED_MORPH_FIT`` or better;
    below that, where the drawing aligned at ``DRAWING_LIKE_ALIGNMENT`` or better, it is asked
    only whether its morph explains the photo; else it takes the whole per-bit check."""
    import deepmorph_detect.check as check_module
    from deepmorph_detect.synthesis import BitEvidence

    model = DeepMorphModel.load(BUNDLED_MODEL)
    locator = Locator(model, detector="universal")
    scene = SceneMaker(model, severity="easy", seed=5).make(drawings=1)
    truth = scene.placements[0]
    asked: list[int] = []
    evidence = locator.checker.synthesis.evidence

    def faint_bits(*args: object) -> BitEvidence:
        """The photo's evidence, with three bits shown flipped yet the morph explaining it: what
        the bars of a bar chart give, whose moves a homography nearly absorbs."""
        asked.append(1)
        real = evidence(*args)
        flipped = real.evidence.copy()
        flipped[:3] = -0.9
        return BitEvidence(real.code, flipped, real.fit, real.blur_px)

    monkeypatch.setattr(locator.checker.synthesis, "evidence", faint_bits)

    def read() -> object:
        return next(d for d in locator.locate(scene.image) if np.array_equal(d.result.payload, truth.payload))

    det = read()
    assert det.result.ok and det.result.corrected_bits == 0
    assert det.result.confidence >= check_module.CHECK_BELOW_CONFIDENCE
    assert det.morph.correlation >= check_module.TRUSTED_MORPH_FIT and asked == [] and det.bits is None
    monkeypatch.setattr(check_module, "TRUSTED_MORPH_FIT", det.morph.correlation + 0.001)
    det = read()
    assert asked and det.morph.unmorphed_correlation >= check_module.DRAWING_LIKE_ALIGNMENT
    assert det.result.ok and det.bits.explained and not det.bits.agrees  # asked only whether it is the drawing
    monkeypatch.setattr(check_module, "DRAWING_LIKE_ALIGNMENT", det.morph.unmorphed_correlation + 0.001)
    # the whole check, which three flipped bits fail: nothing is vouched for (and a blind
    # proposer's drawing whose payload is not read is not reported)
    assert [d for d in locator.locate(scene.image) if d.result.ok] == []


def test_a_proposal_that_is_not_the_drawing_takes_the_wider_searches_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each wider search costs a proposal of another drawing about 17 ms: they run in flat light
    only, after the quick path in the photo fell short."""
    import deepmorph_detect.align as align_module

    model = DeepMorphModel.load(BUNDLED_MODEL)
    locator = Locator(model, detector="universal")
    scene = SceneMaker(model, severity="medium", seed=8).make(drawings=0, distractors=1)
    gray = scene.image.astype(np.float32).mean(-1) / 255
    candidates = locator.detector.detect(gray)
    assert candidates, "the universal detector proposes the other drawing"
    searches: list[bool] = []
    real = align_module.refine
    monkeypatch.setattr(
        align_module, "refine", lambda *a, **k: searches.append(k.get("accept") is not None) or real(*a, **k)
    )
    from deepmorph_detect.refine import ImagePyramid

    assert locator.aligner.verify(ImagePyramid(gray), candidates[:1], gray) == []
    assert searches == [False, True]  # the photo's quick path, then flat light with the wider searches
