"""The detector and the decoder run by ONNX Runtime: the photo chain's two networks, per frame.

Both networks are small convolution stacks on one image at a time, where PyTorch's eager mode
spends much of its time between the layers (dispatch, and oneDNN converting each feature map to
its blocked layout and back). ONNX Runtime's CPU engine fuses each convolution with its ReLU,
plans its memory once and keeps one layout throughout: on one core the decoder takes about 0.6x
torch's time, and the detector somewhat more.

The graphs are built here, layer by layer, from the trained weights (:func:`detector_graph`,
:func:`decoder_graph`) with ``onnx.helper``: no exporter is involved, since PyTorch's
TorchScript-based ONNX exporter is deprecated and the newer one traces for seconds. Only the
layer types these two networks use are known; a network with anything else (a decoder with a
spatial transformer, say) raises :class:`Unsupported` and the caller keeps PyTorch.
:func:`onnx_or_torch` checks the graph's outputs against the PyTorch network's on two inputs
before it is used, and keeps PyTorch where they differ or ONNX Runtime cannot run the graph.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import onnx
import onnxruntime as ort
import torch
from onnx import TensorProto, helper, numpy_helper
from torch import Tensor, nn

from deepmorph_core.networks import Decoder
from deepmorph_detect.network import STRIDE, DetectorNet

OPSET = 17

# what ONNX Runtime raises when it cannot load or run a graph (each derives from Exception alone)
_RUNTIME_ERRORS: tuple[type[Exception], ...] = tuple(
    getattr(ort.capi.onnxruntime_pybind11_state, name)
    for name in ("Fail", "InvalidArgument", "InvalidGraph", "InvalidProtobuf", "NotImplemented", "RuntimeException")
    if hasattr(ort.capi.onnxruntime_pybind11_state, name)
)


class Unsupported(ValueError):
    """The network holds a layer the graph builder does not know."""


class _Graph:
    """Nodes and weights of one graph under construction, with fresh names."""

    def __init__(self) -> None:
        self.nodes: list[onnx.NodeProto] = []
        self.weights: list[onnx.TensorProto] = []
        self._count = 0

    def name(self, stem: str) -> str:
        self._count += 1
        return f"{stem}_{self._count}"

    def weight(self, array: np.ndarray, stem: str) -> str:
        name = self.name(stem)
        self.weights.append(numpy_helper.from_array(np.ascontiguousarray(array, dtype=np.float32), name))
        return name

    def node(self, op: str, inputs: Sequence[str], **attributes: object) -> str:
        out = self.name(op.lower())
        self.nodes.append(helper.make_node(op, list(inputs), [out], **attributes))
        return out

    def module(self, module: nn.Module, x: str) -> str:
        """``module`` (a fused eval-mode layer or a Sequential of them) applied to ``x``."""
        if isinstance(module, nn.Sequential):
            for layer in module:
                x = self.module(layer, x)
            return x
        if isinstance(module, nn.Identity):
            return x
        if isinstance(module, nn.ReLU):
            return self.node("Relu", [x])
        if isinstance(module, nn.Flatten) and module.start_dim == 1 and module.end_dim == -1:
            return self.node("Flatten", [x], axis=1)
        if isinstance(module, nn.Conv2d) and module.groups == 1 and module.padding_mode == "zeros":
            if isinstance(module.padding, str):
                raise Unsupported(f"convolution with padding {module.padding!r}")
            inputs = [x, self.weight(module.weight.detach().numpy(), "w")]
            if module.bias is not None:
                inputs.append(self.weight(module.bias.detach().numpy(), "b"))
            ph, pw = module.padding
            return self.node(
                "Conv",
                inputs,
                kernel_shape=list(module.kernel_size),
                strides=list(module.stride),
                pads=[ph, pw, ph, pw],
                dilations=list(module.dilation),
            )
        if isinstance(module, nn.Linear):
            inputs = [x, self.weight(module.weight.detach().numpy(), "w")]
            if module.bias is not None:
                inputs.append(self.weight(module.bias.detach().numpy(), "b"))
            return self.node("Gemm", inputs, transB=1)
        raise Unsupported(f"no ONNX graph for {type(module).__name__}")

    def model(self, inputs: list[onnx.ValueInfoProto], outputs: dict[str, list[int]]) -> bytes:
        """The graph as a serialised ONNX model; ``outputs`` maps output names to shapes."""
        graph = helper.make_graph(
            self.nodes,
            "deepmorph",
            inputs,
            [helper.make_tensor_value_info(o, TensorProto.FLOAT, shape) for o, shape in outputs.items()],
            self.weights,
        )
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)])
        model.ir_version = 8  # what ONNX Runtime releases of the last years all read
        onnx.checker.check_model(model)
        return model.SerializeToString()


def detector_graph(net: DetectorNet, height: int, width: int) -> bytes:
    """The detector (batch norms folded: ``fused_for_inference``) as an ONNX model for
    ``(1, 1, height, width)`` inputs: outputs the heatmap logits and the corner offsets."""
    with torch.inference_mode():  # the feature maps' sizes for this input size
        probe8 = net.down8(net.stem(torch.zeros(1, 1, height, width)))
        probe16 = net.down16(probe8)
    g = _Graph()
    f8 = g.module(net.down8, g.module(net.stem, "image"))
    f16 = g.module(net.down16, f8)
    # bilinear upsampling to f8's size, as F.interpolate(align_corners=False)
    size = g.name("size")
    g.weights.append(numpy_helper.from_array(np.array([1, probe16.shape[1], *probe8.shape[2:]], np.int64), size))
    up = g.node(
        "Resize",
        [f16, "", "", size],
        mode="linear",
        coordinate_transformation_mode="pytorch_half_pixel",
    )
    f = g.module(net.fuse, g.node("Concat", [up, f8], axis=1))
    heat, corners = g.module(net.heat, f), g.module(net.corners, f)
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 1, height, width])
    cells = [height // STRIDE, width // STRIDE]
    return g.model([image], {heat: [1, 1, *cells], corners: [1, 8, *cells]})


def decoder_graph(decoder: Decoder) -> bytes:
    """The decoder (batch norms folded) as an ONNX model for ``(1, 1, H, W)`` images: logits.

    Raises:
        Unsupported: the decoder has a spatial transformer (PyTorch runs it).
    """
    if decoder.align is not None:
        raise Unsupported("a decoder with a spatial transformer")
    g = _Graph()
    centred = g.node("Sub", ["image", g.weight(np.array(0.5), "half")])  # white +0.5, ink -0.5
    logits = g.module(decoder.head, g.module(decoder.features, centred))
    h, w = decoder.image_size
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 1, h, w])
    return g.model([image], {logits: [1, decoder.head[-1].out_features]})


class OnnxNetwork:
    """An ONNX model run on as many CPU threads as ``torch.get_num_threads()`` says when it is
    made (one in the photo benchmarks), called like the PyTorch network it replaces: a
    ``(1, 1, H, W)`` float32 tensor in, a tensor (or a tuple of them) out."""

    def __init__(self, graph: bytes, n_outputs: int) -> None:
        options = ort.SessionOptions()
        options.intra_op_num_threads = max(1, torch.get_num_threads())
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        options.log_severity_level = 3  # errors only
        self._session = ort.InferenceSession(graph, options, providers=["CPUExecutionProvider"])
        self._n_outputs = n_outputs

    def __call__(self, x: Tensor) -> Tensor | tuple[Tensor, ...]:
        feed = {"image": np.ascontiguousarray(x.detach().numpy(), dtype=np.float32)}
        outs = tuple(torch.from_numpy(o) for o in self._session.run(None, feed))
        return outs if self._n_outputs > 1 else outs[0]


def agrees(a: Tensor | tuple[Tensor, ...], b: Tensor | tuple[Tensor, ...], tolerance: float) -> bool:
    """Whether two networks' outputs (tensors or tuples of them) match within ``tolerance``."""
    pairs = zip(a, b) if isinstance(a, tuple) else [(a, b)]
    return all(x.shape == y.shape and float((x - y).abs().max()) <= tolerance for x, y in pairs)


def onnx_or_torch(
    net: nn.Module, build: Callable[[], bytes], example: Tensor, tolerance: float = 1e-3
) -> Callable[[Tensor], Tensor | tuple[Tensor, ...]]:
    """``net`` (eval mode, batch norms folded) run by ONNX Runtime from the graph ``build``
    makes, when it builds, loads and gives ``net``'s outputs on ``example`` and on ``example``
    upside down (within ``tolerance``); ``net`` itself otherwise. Either is called the same
    way, on a ``(1, 1, H, W)`` tensor of ``example``'s size."""
    inputs = (example, example.flip(-2))
    try:
        with torch.inference_mode():
            want = [net(x) for x in inputs]
        n_outputs = len(want[0]) if isinstance(want[0], tuple) else 1
        fast = OnnxNetwork(build(), n_outputs)
        if all(agrees(w, fast(x), tolerance) for w, x in zip(want, inputs)):
            return fast
    except (Unsupported, onnx.checker.ValidationError, *_RUNTIME_ERRORS):
        pass
    return net


__all__ = ["OPSET", "OnnxNetwork", "Unsupported", "agrees", "decoder_graph", "detector_graph", "onnx_or_torch"]
