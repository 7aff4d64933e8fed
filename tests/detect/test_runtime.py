"""The photo chain runs the graphs the bundle stores with ONNX Runtime: PyTorch's outputs and
readings, and PyTorch again, with a warning, where no usable graph can be had."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphWarning
from deepmorph_core.graphs import GraphError, OnnxNetwork
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.networks import fused_for_inference
from deepmorph_detect.centrenet import TorchDetector, stored_net
from deepmorph_detect.locate import Locator
from deepmorph_detect.network import INPUT_SIZE
from deepmorph_detect.runtime import onnx_or_torch


@pytest.fixture(scope="module")
def model() -> DeepMorphModel:
    return DeepMorphModel.load(BUNDLED_MODEL)


def _torch_detector(model: DeepMorphModel) -> TorchDetector:
    return TorchDetector(fused_for_inference(stored_net(model)).to(memory_format=torch.channels_last))


def test_the_bundled_model_stores_both_graphs_and_the_locator_runs_them(model: DeepMorphModel) -> None:
    assert set(model.graphs) == {"decoder", "detector"}
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeepMorphWarning)  # nothing exported, nothing refused
        locator = Locator(model)
    assert isinstance(locator.reader.decoder, OnnxNetwork)
    assert locator.detector is not None and isinstance(locator.detector.net, OnnxNetwork)


def test_stored_graphs_give_the_networks_outputs(model: DeepMorphModel) -> None:
    generator = torch.Generator().manual_seed(11)
    W, H = INPUT_SIZE
    photos = [torch.rand(1, 1, H, W, generator=generator) for _ in range(2)]
    frames = [torch.rand(1, 1, *model.image_size, generator=generator) for _ in range(2)]
    for name, reference, inputs in (
        ("detector", _torch_detector(model), photos),
        ("decoder", fused_for_inference(model.decoder), frames),
    ):
        graph = model.graphs[name]
        fast = OnnxNetwork(graph.data, graph.meta.inputs, graph.meta.outputs)
        assert fast.difference(reference, inputs) < 1e-4, name


def test_locator_readings_match_pytorch(model: DeepMorphModel) -> None:
    """On real scenes the chain with ONNX Runtime reads what it reads with PyTorch's networks."""
    from deepmorph_detect.scenes import SceneMaker

    fast = Locator(model)
    slow = Locator(model)
    slow.reader.decoder = fused_for_inference(model.decoder)
    slow.detector.net = _torch_detector(model)
    maker = SceneMaker(model, (640, 480), "medium", seed=21)
    for _ in range(3):
        scene = maker.make(drawings=1, distractors=1)
        a, b = fast.locate(scene.image), slow.locate(scene.image)
        assert [d.result.payload.tolist() for d in a] == [d.result.payload.tolist() for d in b]
        for x, y in zip(a, b):
            np.testing.assert_allclose(x.corners, y.corners, atol=0.05)


def test_an_unusable_graph_is_exported_again_and_a_failed_export_keeps_pytorch(model: DeepMorphModel) -> None:
    decoder = fused_for_inference(model.decoder)
    frames = [torch.rand(1, 1, *model.image_size)]
    wrong = replace(model.graphs["detector"], meta=model.graphs["decoder"].meta)  # other inputs than it says
    alone = DeepMorphModel.load(BUNDLED_MODEL)
    alone.graphs["decoder"] = wrong
    with pytest.warns(DeepMorphWarning) as caught:
        fast = onnx_or_torch(alone, "decoder", decoder, frames, lambda: model.graphs["decoder"])
    assert isinstance(fast, OnnxNetwork) and alone.graphs["decoder"] is model.graphs["decoder"]
    assert "is not used" in str(caught[0].message) and "exported one" in str(caught[1].message)

    def no_export() -> None:
        raise GraphError("torch.onnx.export failed: no way")

    alone.graphs.clear()
    with pytest.warns(DeepMorphWarning, match="PyTorch runs its decoder: no ONNX graph could be made"):
        assert onnx_or_torch(alone, "decoder", decoder, frames, no_export) is decoder
    with torch.no_grad():
        decoder.head[-1].bias.add_(1.0)  # the graph is now of another network
    with pytest.warns(DeepMorphWarning, match="differ from PyTorch's"):
        assert onnx_or_torch(None, "decoder", decoder, frames, lambda: model.graphs["decoder"]) is decoder


def test_decode_with_a_damaged_graph_warns_once_and_reads(tmp_path: Path) -> None:
    """The command line: one ``warning:`` line, the graph exported again, the payload read."""
    from safetensors import safe_open
    from safetensors.torch import load_file, save_file

    from deepmorph_core.image_io import save_gray
    from deepmorph_core.render import render_svg

    tensors = load_file(str(BUNDLED_MODEL))
    data = tensors["graph.decoder"].clone()
    data[1000] ^= 0x55
    tensors["graph.decoder"] = data
    with safe_open(str(BUNDLED_MODEL), "pt") as fh:
        meta = fh.metadata()
    damaged = tmp_path / "damaged.dmm"
    save_file(tensors, str(damaged), metadata=meta)
    m = DeepMorphModel.load(BUNDLED_MODEL)
    save_gray(render_svg(m.encode(0xA1B2C3), 300), tmp_path / "code.png")
    result = CliRunner().invoke(application(), ["decode", str(damaged), str(tmp_path / "code.png")])
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.startswith("warning:")]
    assert len(lines) == 2, result.output  # the damaged graph left out, then exported again
    assert "damaged" in lines[0] and "exported one" in lines[1]
    assert "0xA1B2C3" in result.output and "NOT VERIFIED" not in result.output
