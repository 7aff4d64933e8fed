"""``deepmorph train-detector``: targets, a short run that learns, checkpoints and exact resume."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.detector import DetectorConfig, SceneBatches, quad_loss, targets_for, train_detector
from deepmorph.training.loop import Interrupted, read_log
from deepmorph_core.bundle import ValidationRecord
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.network import (
    INPUT_SIZE,
    STRIDE,
    DetectorNet,
    fused_for_inference,
    normalise_input,
    standardise,
    stored_weights,
)
from deepmorph_detect.scenes import SceneMaker
from tests.pretend_cuda import pretend_cuda

app = application()  # the command line's own commands and every installed plugin's

runner = CliRunner()


def test_targets_mark_each_drawing_centre_and_corners() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    scene = SceneMaker(model, INPUT_SIZE, "easy", seed=2).make(drawings=2, distractors=1)
    heat, corners, mask = targets_for(scene.placements, INPUT_SIZE)
    drawings = [p for p in scene.placements if p.kind == "drawing"]
    assert heat.shape == (1, INPUT_SIZE[1] // STRIDE, INPUT_SIZE[0] // STRIDE)
    assert int((heat >= 0.999).sum()) == len(drawings)
    for y, x in zip(*np.nonzero(heat[0] >= 0.999)):
        quad = corners[:, y, x].reshape(4, 2) * STRIDE + (np.array([x, y]) + 0.5) * STRIDE
        assert any(np.allclose(quad, p.corners, atol=1e-3) for p in drawings)
    assert mask.sum() <= 9 * len(drawings)


def test_quad_loss_ignores_the_cyclic_order_of_corners() -> None:
    target = torch.randn(1, 8, 3, 3)
    mask = torch.ones(1, 1, 3, 3)
    rolled = torch.roll(target.view(1, 4, 2, 3, 3), 1, dims=1).reshape(1, 8, 3, 3)
    assert quad_loss(rolled, target, mask).item() < 1e-6
    assert quad_loss(target + 1, target, mask).item() == pytest.approx(1.0)


def test_folding_batch_norms_keeps_the_detector_outputs() -> None:
    """The locator runs the detector with its batch norms folded into the convolutions: the
    same heatmap and corners as the trained network, which itself is left as it was."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    net = DetectorNet(int(model.meta.detector.config.get("width", 32)))
    net.load_state_dict(stored_weights(model.detector_state))
    net.eval()
    fused = fused_for_inference(net)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in fused.modules())
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in net.modules())
    x = torch.randn(2, 1, INPUT_SIZE[1], INPUT_SIZE[0])
    with torch.no_grad():
        for a, b in zip(net(x), fused(x)):
            torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4)


def test_detector_input_is_standardised_as_the_network_was_trained() -> None:
    rng = np.random.default_rng(0)
    for gray in (rng.random((192, 256), dtype=np.float32), np.full((192, 256), 0.7, np.float32)):
        torch.testing.assert_close(
            torch.from_numpy(standardise(gray)), normalise_input(torch.from_numpy(gray)[None, None])[0, 0]
        )


def _config(steps: int) -> DetectorConfig:
    return DetectorConfig(
        steps=steps, batch=2, width=8, workers=0, threads=1, checkpoint_every=100, log_every=1, seed=4, start="scratch"
    )


def test_scene_workers_make_each_step_once_and_in_order() -> None:
    """With scene-making workers the loader gives the batches it gives without them: each step
    once, in order, also from a resumed start (each worker used to make every step, so
    ``--workers 2`` trained on every batch twice)."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    cfg = DetectorConfig(steps=5, batch=1, width=8, workers=2, threads=1, seed=3)

    def images(workers: int) -> list[torch.Tensor]:
        loader = torch.utils.data.DataLoader(
            SceneBatches(model, cfg, 1, 5),
            batch_size=None,
            num_workers=workers,
            multiprocessing_context="fork" if workers else None,
        )
        return [batch[0] for batch in loader]

    alone, shared = images(0), images(2)
    assert len(alone) == len(shared) == 4
    for a, b in zip(alone, shared):
        assert torch.equal(a, b)
    assert not torch.equal(alone[0], alone[1])


def test_short_training_checkpoints_and_resumes_exactly(tmp_path: Path) -> None:
    straight = tmp_path / "straight.dmm"
    train_detector(BUNDLED_MODEL, straight, _config(4))

    cut = tmp_path / "cut.dmm"

    def stop_at_2(m: dict) -> None:
        if m["step"] == 2:
            raise KeyboardInterrupt

    with pytest.raises(Interrupted, match=rf"checkpoint written to {re.escape(str(cut))} \(continue with --resume\)$"):
        train_detector(BUNDLED_MODEL, cut, _config(4), on_log=stop_at_2)
    assert [line["step"] for line in read_log(cut.with_suffix(".detector.log.jsonl"))] == [1, 2]
    half = DeepMorphModel.load(cut)
    assert half.meta.detector is not None and half.meta.detector.record.step == 2
    assert set(half.graphs) == {"decoder"}  # the decoder's is kept; a detector graph comes at the end
    res = runner.invoke(app, ["train-detector", str(BUNDLED_MODEL), "--out", str(cut), "--resume"])
    assert res.exit_code == 0, res.output
    a, b = DeepMorphModel.load(straight), DeepMorphModel.load(cut)
    assert a.meta.detector.record.finished and b.meta.detector.record.step == 4
    assert a.graphs["detector"].data == b.graphs["detector"].data
    for key, val in a.detector_state.items():
        assert torch.equal(val, b.detector_state[key]), key
    # the codec networks are carried over untouched
    base = DeepMorphModel.load(BUNDLED_MODEL)
    for key, val in base.decoder.state_dict().items():
        assert torch.equal(val, b.decoder.state_dict()[key])


def test_fine_tuning_starts_from_the_bundles_detector_and_keeps_its_history(tmp_path: Path) -> None:
    """``--fine-tune`` trains the detector already in the bundle further (at a tiny learning
    rate one step barely moves it, where a fresh start would replace it), records the run it
    came from, and refuses another width with a clear error."""
    base = tmp_path / "base.dmm"
    train_detector(BUNDLED_MODEL, base, _config(2))
    tuned = tmp_path / "tuned.dmm"
    args = [
        "train-detector",
        str(base),
        "--out",
        str(tuned),
        "--steps",
        "1",
        "--batch",
        "2",
        "--channels",
        "8",
        "--from-scratch",
    ]
    res = runner.invoke(app, [*args, "--workers", "0", "--fine-tune", "--lr", "1e-6", "--seed", "5"])
    assert res.exit_code == 0, res.output
    before, after = DeepMorphModel.load(base), DeepMorphModel.load(tuned)
    for key, val in before.detector_state.items():
        if val.is_floating_point() and "running" not in key:
            torch.testing.assert_close(after.detector_state[key], val, atol=1e-4, rtol=0)
    assert after.meta.detector.config["fine_tune"] and after.meta.detector.record.step == 1
    (earlier,) = after.meta.detector.earlier
    assert earlier["record"]["step"] == 2 and earlier["config"]["seed"] == 4
    res = runner.invoke(app, ["info", str(tuned)])
    assert "fine-tuned after 2 steps" in " ".join(res.output.split()), res.output
    wider = ["train-detector", str(base), "--out", str(tmp_path / "wider.dmm"), "--steps", "1", "--channels", "16"]
    res = runner.invoke(app, [*wider, "--workers", "0", "--fine-tune"])
    assert res.exit_code == 1 and "width 8, not 16" in " ".join(res.output.split()), res.output


def test_by_default_a_detector_is_a_short_fine_tune_of_the_universal_one(tmp_path: Path) -> None:
    """Without options the network starts from the shipped universal detector, whose run the
    bundle records; a width other than the universal detector's is a clear error."""
    from deepmorph_detect.universal import UNIVERSAL_PATH, load_universal

    assert DetectorConfig().start == "universal" and DetectorConfig().steps <= 400
    out = tmp_path / "tuned.dmm"
    args = ["train-detector", str(BUNDLED_MODEL), "--out", str(out), "--steps", "1", "--batch", "2", "--workers", "0"]
    res = runner.invoke(app, [*args, "--lr", "1e-6"])
    assert res.exit_code == 0, res.output
    universal, _, meta, _ = load_universal(UNIVERSAL_PATH)
    tuned = DeepMorphModel.load(out)
    for key, val in universal.state_dict().items():
        if val.is_floating_point() and "running" not in key:
            torch.testing.assert_close(tuned.detector_state[f"detector.{key}"], val, atol=1e-4, rtol=0)
    (earlier,) = tuned.meta.detector.earlier
    assert earlier["record"]["step"] == meta.record.step and "universal" in earlier["config"]
    res = runner.invoke(app, [*args[:2], "--out", str(tmp_path / "narrow.dmm"), "--steps", "1", "--channels", "8"])
    assert res.exit_code == 1 and f"width {meta.width}, not 8" in " ".join(res.output.split()), res.output


def test_an_existing_file_other_than_the_model_is_not_replaced(tmp_path: Path) -> None:
    drawing = tmp_path / "ghost.svg"
    drawing.write_text("<svg/>")
    res = runner.invoke(app, ["train-detector", str(BUNDLED_MODEL), "--out", str(drawing), "--steps", "1"])
    assert res.exit_code == 1 and "already exists" in " ".join(res.output.split()), res.output
    assert drawing.read_text() == "<svg/>"


def test_resume_without_checkpoint_is_a_clear_error(tmp_path: Path) -> None:
    res = runner.invoke(app, ["train-detector", str(BUNDLED_MODEL), "--out", str(BUNDLED_MODEL), "--resume"])
    assert res.exit_code == 1 and "no interrupted detector training" in res.output


def test_width_option_sets_the_stored_network_and_the_locator_runs_it(tmp_path: Path) -> None:
    """``--channels`` picks the detector's channel width; the bundle records it, and the locator
    builds the network at that width from the bundle alone."""
    out = tmp_path / "slim.dmm"
    args = ["train-detector", str(BUNDLED_MODEL), "--out", str(out), "--steps", "1", "--batch", "2", "--channels", "8"]
    res = runner.invoke(app, [*args, "--workers", "0", "--from-scratch", "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)  # one JSON object, nothing else on stdout (docs/cli.md)
    assert set(data) == {"written", "bundle", "log", "plot", "steps", "elapsed_s", "metrics"}
    assert data["bundle"] == str(out) and data["steps"] == 1 and {"loss", "recall", "corner"} <= set(data["metrics"])
    model = DeepMorphModel.load(out)
    assert model.meta.detector.config["width"] == 8
    assert model.detector_state["detector.stem.0.0.weight"].shape[0] == 4  # width // 2 channels
    from deepmorph_detect.centrenet import CentreNetDetector

    detector = CentreNetDetector.from_model(model)
    image = SceneMaker(model, (320, 240), "easy", seed=1).make(drawings=1).image
    assert isinstance(detector.detect(image), list)
    res = runner.invoke(app, [*args[:-2], "--channels", "4", "--from-scratch"])
    assert res.exit_code != 0 and "--channels" in res.output


def test_a_new_detector_replaces_the_stored_close_up_validation(tmp_path: Path) -> None:
    """Close-ups validated after ``train`` found prints without a detector; once one is trained,
    the chain they measured has changed, so the record is taken again (renders are kept)."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    common = {"severity": "medium", "samples": 2, "read": 0, "wrong": 0, "seconds": 0.0}
    model.meta.validation = [
        ValidationRecord(name="renders", description="kept", **common),
        ValidationRecord(name="close-ups", description="stale", missed=2, **common),
    ]
    start = tmp_path / "m.dmm"
    model.save(start)
    train_detector(start, start, _config(1))
    records = {r.name: r for r in DeepMorphModel.load(start).meta.validation}
    assert records["renders"].description == "kept"
    assert records["close-ups"].description != "stale" and records["close-ups"].samples == 2


def test_the_detector_trains_and_resumes_on_the_device_it_is_given(tmp_path: Path) -> None:
    """``device="cuda"`` on a pretend CUDA device (``tests/pretend_cuda.py``): the network, its
    batches and, on resuming, the optimiser's state go to the device, no operation mixes the two,
    the bundle records the device and stores CPU weights and the detector's graph, and the
    weights are those the CPU trains (the pretend device computes as the CPU does)."""
    on_cpu = tmp_path / "cpu.dmm"
    train_detector(BUNDLED_MODEL, on_cpu, _config(3).model_copy(update={"device": "cpu"}))
    cut = tmp_path / "cuda.dmm"

    def stop_at_1(m: dict) -> None:
        if m["step"] == 1:
            raise KeyboardInterrupt

    with pretend_cuda() as device:
        with pytest.raises(Interrupted):
            train_detector(BUNDLED_MODEL, cut, _config(3).model_copy(update={"device": "cuda"}), on_log=stop_at_1)
        train_detector(cut, cut, resume=True)
    assert not device.mixes, device.mixes
    a, b = DeepMorphModel.load(on_cpu), DeepMorphModel.load(cut)
    assert a.meta.detector.record.device == "cpu" and b.meta.detector.record.device == "cuda"
    assert "detector" in b.graphs
    for key, val in a.detector_state.items():
        assert type(b.detector_state[key]) is torch.Tensor and torch.equal(val, b.detector_state[key]), key


def test_the_commands_options_are_the_declared_settings() -> None:
    """``train-detector``'s options take their defaults, bounds and help from
    :class:`DetectorSettings`, which :class:`DetectorConfig` inherits; the command has no
    literal default of its own (a changed one, in a fresh process, reaches it)."""
    import inspect

    from deepmorph.cli.photo_commands import train_detector_cmd
    from deepmorph.training.detector_settings import DetectorSettings
    from deepmorph.training.settings import exposed
    from tests.app.test_train_settings import declared

    options, config = declared(train_detector_cmd), DetectorConfig()
    for field, setting in exposed(DetectorSettings).items():
        if setting.option in ("seed", "threads", "device"):  # the options every command shares, with their own help
            continue
        assert options[field].default == getattr(config, field), field
        assert options[field].flags == (f"--{setting.option}",) and options[field].help == setting.help
        assert (options[field].min, options[field].max) == (setting.ge, setting.le), field
    params = inspect.signature(train_detector_cmd).parameters
    assert params["seed"].default == config.seed and params["fine_tune"].default == config.fine_tune
    assert (config.start == "scratch") == params["from_scratch"].default
    changed = subprocess.run([sys.executable, "-c", DETECTOR_CHANGED], cwd=Path(__file__).resolve().parents[2],
                             capture_output=True, text=True, timeout=300)  # fmt: skip
    assert changed.returncode == 0, changed.stderr
    assert json.loads(changed.stdout) == [301, 7e-4]  # no literal default of its own


DETECTOR_CHANGED = """
import dataclasses, json
import deepmorph.training.detector_settings as settings
settings.DETECTOR_DEFAULTS = dataclasses.replace(settings.DETECTOR_DEFAULTS, steps=301, lr=7e-4)
from tests.app.test_train_settings import declared
from deepmorph.cli.photo_commands import train_detector_cmd
cli = declared(train_detector_cmd)
print(json.dumps([cli["steps"].default, cli["lr"].default]))
"""
