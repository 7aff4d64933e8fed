"""The detector and the decoder run by ONNX Runtime: the same outputs as PyTorch, or PyTorch."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.networks import Decoder, DecoderConfig
from deepmorph_detect.locate import Locator
from deepmorph_detect.network import INPUT_SIZE, DetectorNet, fused_for_inference, stored_weights
from deepmorph_detect.runtime import OnnxNetwork, Unsupported, decoder_graph, detector_graph, onnx_or_torch


@pytest.fixture(scope="module")
def model() -> DeepMorphModel:
    return DeepMorphModel.load(BUNDLED_MODEL)


def _trained_detector(model: DeepMorphModel) -> nn.Module:
    net = DetectorNet(int(model.meta.detector.config.get("width", 32)))
    net.load_state_dict(stored_weights(model.detector_state))
    return fused_for_inference(net)


def test_detector_graph_gives_the_networks_outputs(model: DeepMorphModel) -> None:
    net = _trained_detector(model)
    W, H = INPUT_SIZE
    fast = OnnxNetwork(detector_graph(net, H, W), 2)
    for seed in range(3):
        x = torch.randn(1, 1, H, W, generator=torch.Generator().manual_seed(seed))
        with torch.inference_mode():
            want = net(x)
        got = fast(x)
        assert isinstance(got, tuple) and len(got) == 2
        for a, b in zip(want, got):
            torch.testing.assert_close(b, a, rtol=1e-4, atol=1e-4)


def test_detector_graph_for_another_input_size(model: DeepMorphModel) -> None:
    """Odd sizes round the strided feature maps up; the upsampling must land on them."""
    net = _trained_detector(model)
    fast = OnnxNetwork(detector_graph(net, 100, 150), 2)
    x = torch.rand(1, 1, 100, 150)
    with torch.inference_mode():
        for a, b in zip(net(x), fast(x)):
            torch.testing.assert_close(b, a, rtol=1e-4, atol=1e-4)


def test_decoder_graph_gives_the_networks_logits(model: DeepMorphModel) -> None:
    decoder = fused_for_inference(model.decoder)
    fast = OnnxNetwork(decoder_graph(decoder), 1)
    x = torch.rand(1, 1, *model.image_size)
    with torch.inference_mode():
        torch.testing.assert_close(fast(x), decoder(x), rtol=1e-4, atol=1e-4)


def test_the_locator_runs_both_networks_by_onnx_runtime(model: DeepMorphModel) -> None:
    locator = Locator(model)
    assert isinstance(locator.reader.decoder, OnnxNetwork)
    assert locator.detector is not None and isinstance(locator.detector.net, OnnxNetwork)


def test_unsupported_layers_keep_pytorch(model: DeepMorphModel) -> None:
    stn = Decoder(model.codec.spec.code_bits, model.image_size, DecoderConfig(spatial_transformer=True)).eval()
    with pytest.raises(Unsupported, match="spatial transformer"):
        decoder_graph(stn)
    example = torch.rand(1, 1, *model.image_size)
    assert onnx_or_torch(stn, lambda: decoder_graph(stn), example) is stn

    class Softened(nn.Module):  # a layer the builder does not know
        def __init__(self) -> None:
            super().__init__()
            self.features = nn.Sequential(nn.Conv2d(1, 2, 3), nn.Sigmoid())

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return self.features(x)

    odd = Softened().eval()
    with pytest.raises(Unsupported, match="Sigmoid"):
        decoder_graph_like(odd)
    assert onnx_or_torch(odd, lambda: decoder_graph_like(odd), torch.rand(1, 1, 8, 8)) is odd


def decoder_graph_like(net: nn.Module) -> bytes:
    """A graph of ``net.features`` alone, through the same builder as the decoder's."""
    from deepmorph_detect import runtime

    g = runtime._Graph()
    out = g.module(net.features, "image")
    image = runtime.helper.make_tensor_value_info("image", runtime.TensorProto.FLOAT, [1, 1, 8, 8])
    return g.model([image], {out: [1, 2, 6, 6]})


def test_a_graph_that_disagrees_keeps_pytorch(model: DeepMorphModel) -> None:
    """A graph that builds and runs but computes something else is caught by the check."""
    decoder = fused_for_inference(model.decoder)
    other = fused_for_inference(Decoder(model.codec.spec.code_bits, model.image_size).eval())
    example = torch.rand(1, 1, *model.image_size)
    assert onnx_or_torch(decoder, lambda: decoder_graph(other), example) is decoder
    assert onnx_or_torch(decoder, lambda: b"not an ONNX model", example) is decoder  # ONNX Runtime refuses it
    assert isinstance(onnx_or_torch(decoder, lambda: decoder_graph(decoder), example), OnnxNetwork)


def test_locator_readings_match_pytorch(model: DeepMorphModel) -> None:
    """On real scenes the chain with ONNX Runtime reads what it reads with PyTorch's networks."""
    from deepmorph_detect.scenes import SceneMaker

    fast = Locator(model)
    slow = Locator(model)
    slow.reader.decoder = fused_for_inference(model.decoder)
    slow.detector.net = _trained_detector(model)
    maker = SceneMaker(model, (640, 480), "medium", seed=21)
    for _ in range(3):
        scene = maker.make(drawings=1, distractors=1)
        a, b = fast.locate(scene.image), slow.locate(scene.image)
        assert [d.result.payload.tolist() for d in a] == [d.result.payload.tolist() for d in b]
        for x, y in zip(a, b):
            np.testing.assert_allclose(x.corners, y.corners, atol=0.05)
