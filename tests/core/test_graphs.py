"""ONNX graphs of the networks: exported per decoder kind, checked against PyTorch, stored in and
reloaded from bundles, and a damaged or hostile stored graph left out cleanly, never run."""

from __future__ import annotations

import json
from pathlib import Path

import onnx
import pytest
import torch
from onnx import TensorProto, helper
from safetensors import safe_open
from safetensors.torch import load_file, save_file

from deepmorph_core.codec import CodecSpec
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning
from deepmorph_core.graphs import GraphError, OnnxNetwork, check_graph
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.networks import DecoderConfig, fused_for_inference
from tests.conftest import make_svg

SVG = make_svg(
    '<g stroke="black" stroke-width="2" fill="none" dm:move="2"><polyline points="4 6 12 4 20 6"/>'
    '<circle cx="12" cy="14" r="4"/></g>'
)
IO = ({"image": [1, 1, 8, 8]}, {"out": [1, 2, 8, 8]})


def tiny_model(spatial_transformer: bool, readout: bool = False) -> DeepMorphModel:
    """A small untrained model of each decoder kind; the transformer's last layer is moved off
    the identity so that its resampling (GridSample) really shifts pixels, and the readout off
    zero so that it adds to the logits."""
    config = DecoderConfig(stem=4, channels=(8, 8), hidden=16, spatial_transformer=spatial_transformer, readout=readout)
    torch.manual_seed(0)
    model = DeepMorphModel.create(
        SVG.decode(), "tiny.svg", {}, CodecSpec(payload_bits=4, crc_bits=8, bch_t=0), 32, {}, {}, {}, config
    )
    if model.decoder.align is not None:
        torch.nn.init.normal_(model.decoder.align.head[-1].weight, std=0.3)
    if model.decoder.readout is not None:
        torch.nn.init.normal_(model.decoder.readout.weight, std=0.1)
    return model.eval()


@pytest.fixture(
    scope="module",
    params=[(False, False), (True, False), (True, True)],
    ids=["cnn", "spatial-transformer", "spatial-transformer+readout"],
)
def stored(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bundle of each decoder kind with its decoder's graph stored."""
    model = tiny_model(*request.param)
    assert model.store_decoder_graph()
    path = tmp_path_factory.mktemp("graphs") / "tiny.dmm"
    model.save(path)
    return path


def test_each_decoder_kind_exports_and_runs_as_pytorch_does(stored: Path) -> None:
    model = DeepMorphModel.load(stored)
    graph = model.graphs["decoder"]
    ops = {node.op_type for node in onnx.load_from_string(graph.data).graph.node}
    assert ("GridSample" in ops) == model.meta.decoder.spatial_transformer
    assert graph.meta.max_abs_diff <= 1e-4 and graph.meta.inputs == {"image": [1, 1, *model.image_size]}
    fast = OnnxNetwork(graph.data, graph.meta.inputs, graph.meta.outputs)
    generator = torch.Generator().manual_seed(7)
    frames = [torch.rand(1, 1, *model.image_size, generator=generator) for _ in range(3)]
    assert fast.difference(fused_for_inference(model.decoder), frames) < 1e-4
    assert fast.difference(model.decoder, frames) < 1e-4  # batch norms folded or not
    assert model.info()["graphs"]["decoder"]["sha256"] == graph.meta.sha256
    if model.meta.decoder.spatial_transformer:  # the transformer resamples: a plain decoder reads otherwise
        plain = fused_for_inference(model.decoder)
        plain.align = None
        assert fast.difference(plain, frames) > 1e-3
    if model.meta.decoder.readout:  # the graph holds the readout: without it the logits differ
        cnn_only = fused_for_inference(model.decoder)
        cnn_only.readout = None
        assert fast.difference(cnn_only, frames) > 1e-3


def test_a_graph_of_weights_trained_further_is_not_saved(stored: Path, tmp_path: Path) -> None:
    model = DeepMorphModel.load(stored)
    with torch.no_grad():
        model.decoder.head[-1].bias.add_(0.1)
    model.save(tmp_path / "further.dmm")
    assert DeepMorphModel.load(tmp_path / "further.dmm").graphs == {}


def _edited(source: Path, target: Path, tensors_edit=None, meta_edit=None) -> Path:
    tensors = load_file(str(source))
    with safe_open(str(source), "pt") as fh:
        meta = json.loads(fh.metadata()["deepmorph"])
    if tensors_edit:
        tensors_edit(tensors)
    if meta_edit:
        meta_edit(meta)
    save_file(tensors, str(target), metadata={"deepmorph": json.dumps(meta)})
    return target


def _flip_byte(t: dict) -> None:
    data = t["graph.decoder"].clone()
    data[len(data) // 2] ^= 0xFF
    t["graph.decoder"] = data


def _as_detector(t: dict) -> None:
    t["graph.detector"] = t["graph.decoder"].clone()


def _set_size(size: int):
    return lambda m: m["graphs"]["decoder"].update(size=size)


def test_a_damaged_stored_graph_is_left_out_with_one_warning(stored: Path, tmp_path: Path) -> None:
    cases = {
        "flipped": (_flip_byte, None, "damaged"),
        "cut": (lambda t: t.update({"graph.decoder": t["graph.decoder"][:-10]}), None, "not the"),
        "int8": (lambda t: t.update({"graph.decoder": t["graph.decoder"].to(torch.int8)}), None, "torch.int8"),
        "missing": (lambda t: t.pop("graph.decoder"), None, "bytes are missing"),
        "unrecorded": (None, lambda m: m["graphs"].clear(), "no record"),
        "oversized": (None, _set_size(400_000_000), "far more than"),
        "other-weights": (None, lambda m: m["graphs"]["decoder"].update(weights_sha256="0" * 64), "other weights"),
        "no-network": (_as_detector, lambda m: m["graphs"].update(detector=m["graphs"]["decoder"]), "no weights"),
    }
    for name, (tensors_edit, meta_edit, message) in cases.items():
        path = _edited(stored, tmp_path / f"{name}.dmm", tensors_edit, meta_edit)
        with pytest.warns(DeepMorphWarning, match=message) as caught:
            model = DeepMorphModel.load(path)
        assert len(caught) == 1, name
        assert "detector" not in model.graphs, name
        if name != "no-network":
            assert "decoder" not in model.graphs, name
        assert model.codec.spec.payload_bits == 4  # the model itself is whole


def test_a_graph_record_that_breaks_the_rules_is_one_clear_error(stored: Path, tmp_path: Path) -> None:
    for edit, message in (
        (lambda m: m["graphs"].update({"Bad Name!": m["graphs"]["decoder"]}), "graphs"),
        (lambda m: m["graphs"]["decoder"].update(sha256="xyz"), "sha256"),
        (lambda m: m["graphs"]["decoder"]["inputs"].update(image=[1, -1]), "inputs"),
    ):
        path = _edited(stored, tmp_path / "rule.dmm", meta_edit=edit)
        with pytest.raises(DeepMorphError, match=f"not a usable DeepMorph model file .*{message}"):
            DeepMorphModel.load(path)


def _model(nodes: list, initializers: list | None = None, domain: str = "", out_shape=(1, 2, 8, 8)) -> bytes:
    graph = helper.make_graph(
        nodes,
        "g",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 1, 8, 8])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, list(out_shape))],
        initializers or [],
    )
    opsets = [helper.make_opsetid("", 18)] + ([helper.make_opsetid(domain, 1)] if domain else [])
    return helper.make_model(graph, opset_imports=opsets).SerializeToString()


def _weight(external: bool = False) -> TensorProto:
    w = helper.make_tensor("w", TensorProto.FLOAT, [2, 1, 1, 1], [1.0, 2.0])
    if external:
        w.ClearField("float_data")
        w.data_location = TensorProto.EXTERNAL
        w.external_data.add(key="location", value="../../../etc/passwd")
    return w


def test_graphs_a_network_would_not_hold_are_refused_before_onnx_runtime() -> None:
    conv = helper.make_node("Conv", ["image", "w"], ["out"])
    fine = _model([conv], [_weight()])
    check_graph(fine, *IO)
    fast = OnnxNetwork(fine, *IO)
    x = torch.rand(1, 1, 8, 8)
    torch.testing.assert_close(fast(x), torch.cat([x, 2 * x], 1))
    big = helper.make_node("Expand", ["image", "shape"], ["big"])
    shape = helper.make_tensor("shape", TensorProto.INT64, [4], [1, 1, 1 << 16, 1 << 16])
    cases = {
        b"not a graph at all": "well-formed",
        _model([conv], [_weight(external=True)]): "inside it",
        _model([helper.make_node("Steal", ["image"], ["out"], domain="evil.ops")], domain="evil.ops"): "standard",
        _model([helper.make_node("RandomNormalLike", ["image"], ["out"])], out_shape=(1, 1, 8, 8)): "RandomNormalLike",
        _model([conv], [_weight()], out_shape=(1, 3, 8, 8)): "outputs",
        _model([big, helper.make_node("Relu", ["big"], ["out"])], [shape]): "operators",
    }
    for data, message in cases.items():
        with pytest.raises(GraphError, match=message):
            OnnxNetwork(data, *IO)
    # an allowed operator asked for a huge intermediate tensor: refused by its size
    huge = _model(
        [
            helper.make_node("Resize", ["image", "", "scales"], ["big"]),
            helper.make_node("AveragePool", ["big"], ["out"], kernel_shape=[8192, 8192], strides=[8192, 8192]),
        ],
        [helper.make_tensor("scales", TensorProto.FLOAT, [4], [1, 2, 8192, 8192])],
    )
    with pytest.raises(GraphError, match="bounded size"):
        check_graph(huge, *IO)


def test_a_network_the_exporter_cannot_export_is_a_clean_error() -> None:
    from deepmorph_core.graphs import make_graph

    class Broken(torch.nn.Module):
        def forward(self, x: torch.Tensor) -> torch.Tensor:
            raise RuntimeError("no way through")

    with pytest.raises(GraphError, match="torch.onnx.export failed"):
        make_graph(Broken(), [torch.rand(1, 1, 8, 8)], "image", ["out"], "0" * 64)
