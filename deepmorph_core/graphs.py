"""ONNX graphs of the networks: exported once, checked against PyTorch, stored, run by ONNX Runtime.

A network (batch norms folded: :func:`~deepmorph_core.networks.fused_for_inference`) is
exported for one input shape by ``torch.onnx.export``, the ``torch.export``-based exporter
(:func:`export`), and kept only when ONNX Runtime gives PyTorch's outputs on a few inputs
(:func:`make_graph`, within :data:`TOLERANCE`). Training stores the decoder's graph in the
bundle, detector training the detector's (:class:`StoredGraph`: the bytes and their
:class:`~deepmorph_core.bundle.GraphMeta`); the photo chain runs them (:class:`OnnxNetwork`) and
``deepmorph export`` writes them out for other programs (``docs/export.md``).

A graph read from a bundle is data from a file that may be hostile. It is run only when it
is whole (its length and SHA-256 as recorded), exported from the weights beside it
(:func:`read_graphs`), and, before ONNX Runtime sees it (:func:`check_graph`), a well-formed
model of the standard operator set whose operators are all in :data:`ALLOWED_OPS` (no control
flow, no custom operators), with every weight inside it (no external files), the expected
inputs and outputs, and every intermediate tensor of a static shape of bounded size. Anything
else is a :class:`GraphError`, and the caller runs PyTorch instead.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import logging
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from deepmorph_core.bundle import GraphMeta
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning

#: The ONNX operator set of exported graphs (the exporter's lowest; with IR 10, ONNX Runtime 1.17 and later).
OPSET = 18
#: Largest difference from PyTorch's outputs a graph may show on the check inputs.
TOLERANCE = 1e-3
#: What the exporter emits for DeepMorph's networks, and a few plain tensor operators more.
ALLOWED_OPS = frozenset(
    "Abs Add AveragePool BatchNormalization Cast Clip Concat Constant Conv Div Einsum Flatten Gemm "
    "GridSample Identity MatMul Max MaxPool Min Mul Neg Pow ReduceMean Relu Reshape Resize Sigmoid "
    "Slice Sqrt Squeeze Sub Transpose Unsqueeze".split()
)
#: Most elements of any tensor inside a graph (a quarter of a gigabyte of float32).
MAX_TENSOR_ELEMENTS = 1 << 26
#: A stored graph may be at most this many times its network's weights, plus :data:`GRAPH_SLACK`.
GRAPH_SIZE_FACTOR = 2
GRAPH_SLACK = 16 * 1024 * 1024


class GraphError(DeepMorphError):
    """A network that cannot be exported, or a graph that cannot be trusted or run."""


@dataclass(frozen=True)
class StoredGraph:
    """An ONNX graph (serialised ``ModelProto`` bytes) and what the bundle records of it."""

    data: bytes
    meta: GraphMeta


def weights_fingerprint(tensors: Mapping[str, Tensor], name: str) -> str:
    """SHA-256 of the bundle tensors filed under ``name.`` (names, types, shapes, bytes): what
    ties a stored graph to the weights it was exported from."""
    digest = hashlib.sha256()
    for key in sorted(k for k in tensors if k.startswith(name + ".")):
        t = tensors[key].detach().cpu().contiguous()
        digest.update(f"{key}|{t.dtype}|{tuple(t.shape)}|".encode())
        digest.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def weights_bytes(tensors: Mapping[str, Tensor], name: str) -> int:
    """Bytes of the bundle tensors filed under ``name.``."""
    return sum(t.numel() * t.element_size() for k, t in tensors.items() if k.startswith(name + "."))


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """The exporter's chatter (progress lines, warnings about optional packages) kept off the
    user's terminal."""
    logger = logging.getLogger("torch.onnx")
    level = logger.level
    logger.setLevel(logging.ERROR)
    sink = io.StringIO()
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            warnings.simplefilter("ignore")
            yield
    finally:
        logger.setLevel(level)


def _without_provenance(proto: Any) -> Any:
    """``proto`` without what the exporter records of where it ran: each node's source file,
    line and stack trace (absolute paths of this machine) and its FX names. A graph's bytes then
    depend only on the network and its weights, not on the checkout it was exported from."""
    graphs = [proto.graph]
    while graphs:
        graph = graphs.pop()
        for node in graph.node:
            del node.metadata_props[:]
            node.doc_string = ""
            graphs.extend(attr.g for attr in node.attribute if attr.HasField("g"))
        for value in (*graph.input, *graph.output, *graph.value_info):
            del value.metadata_props[:]
    return proto


def export(module: nn.Module, example: Tensor, inputs: Sequence[str], outputs: Sequence[str]) -> bytes:
    """``module`` (eval mode, on the CPU) as a serialised ONNX model for inputs of ``example``'s
    shape, by ``torch.onnx.export`` (``dynamo=True``, with onnxscript).

    Raises:
        GraphError: the exporter failed (or is not installed).
    """
    try:
        with _quiet():
            program = torch.onnx.export(
                module,
                (example,),
                dynamo=True,
                input_names=list(inputs),
                output_names=list(outputs),
                opset_version=OPSET,
                verbose=False,
                optimize=True,
            )
            return _without_provenance(program.model_proto).SerializeToString()
    except Exception as exc:  # the exporter fails in many ways (tracing, translation, a missing onnxscript)
        why = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
        raise GraphError(f"torch.onnx.export failed: {why}") from None


def _shape(value: object) -> list[int] | None:
    """Static dimensions of an ONNX ``ValueInfoProto`` of a tensor, or None when any is unknown."""
    kind = value.type  # type: ignore[attr-defined]
    if not kind.HasField("tensor_type") or not kind.tensor_type.HasField("shape"):
        return None
    dims = kind.tensor_type.shape.dim
    if any(not d.HasField("dim_value") or d.dim_value < 1 for d in dims):
        return None
    return [int(d.dim_value) for d in dims]


def check_graph(data: bytes, inputs: Mapping[str, Sequence[int]], outputs: Mapping[str, Sequence[int]]) -> None:
    """Refuse a graph that is not safe and fit to run (see the module): malformed, other
    operators, external data, other inputs or outputs, or an intermediate tensor of unknown or
    excessive size.

    Raises:
        GraphError: saying what is wrong.
    """
    import onnx
    from onnx import shape_inference

    try:
        proto = onnx.load_from_string(data)  # reads nothing beside the bytes
    except Exception as exc:  # protobuf raises its own kinds on malformed bytes
        raise GraphError(f"not a well-formed ONNX model ({type(exc).__name__})") from None
    graph = proto.graph
    domains = {o.domain for o in proto.opset_import} | {n.domain for n in graph.node}
    if domains - {"", "ai.onnx"} or proto.functions:
        raise GraphError("it uses operators outside the standard ONNX set")
    unknown = sorted({n.op_type for n in graph.node} - ALLOWED_OPS)
    if unknown:
        raise GraphError(f"it uses operators a DeepMorph network does not: {', '.join(unknown[:5])}")
    tensors = list(graph.initializer)
    for node in graph.node:
        for attr in node.attribute:
            if attr.type in (onnx.AttributeProto.GRAPH, onnx.AttributeProto.GRAPHS):
                raise GraphError("it holds subgraphs")
            tensors.extend([attr.t] if attr.HasField("t") else [])
            tensors.extend(attr.tensors)
    if graph.sparse_initializer or any(
        t.data_location == onnx.TensorProto.EXTERNAL or len(t.external_data) for t in tensors
    ):
        raise GraphError("its weights are not all inside it")
    try:
        onnx.checker.check_model(proto)
    except Exception as exc:  # the checker raises its own kinds
        raise GraphError(f"not a well-formed ONNX model ({type(exc).__name__})") from None
    initialised = {t.name for t in graph.initializer}
    ins = [v for v in graph.input if v.name not in initialised]
    for what, got, want in (("inputs", ins, inputs), ("outputs", list(graph.output), outputs)):
        found = {v.name: _shape(v) for v in got}
        expected = {k: list(v) for k, v in want.items()}
        if found != expected or any(v.type.tensor_type.elem_type != onnx.TensorProto.FLOAT for v in got):
            raise GraphError(f"its {what} are {found}, expected float32 {expected}")
    try:
        inferred = shape_inference.infer_shapes(proto, check_type=True, strict_mode=True, data_prop=True).graph
    except Exception as exc:  # shape inference raises its own kinds on inconsistent graphs
        raise GraphError(f"its tensor shapes do not add up ({type(exc).__name__})") from None
    shapes = {v.name: _shape(v) for v in [*inferred.value_info, *inferred.output]}
    for node in inferred.node:
        for name in node.output:
            shape = shapes.get(name)
            if shape is None or int(np.prod(shape, dtype=np.int64)) > MAX_TENSOR_ELEMENTS:
                raise GraphError(f"its tensor {name[:40]!r} has no static shape of a bounded size")


class OnnxNetwork:
    """A checked ONNX graph (:func:`check_graph`) run by ONNX Runtime on as many CPU threads as
    ``torch.get_num_threads()`` says when it is made (one in the photo benchmarks), called like
    the PyTorch network it stands for: a float32 tensor in, a tensor (or a tuple) out.

    Raises:
        GraphError: the graph fails the checks, or ONNX Runtime cannot load it.
    """

    def __init__(self, data: bytes, inputs: Mapping[str, Sequence[int]], outputs: Mapping[str, Sequence[int]]) -> None:
        import onnxruntime as ort

        check_graph(data, inputs, outputs)
        options = ort.SessionOptions()
        options.intra_op_num_threads = max(1, torch.get_num_threads())
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        options.log_severity_level = 3  # errors only
        try:
            self._session = ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # ONNX Runtime's errors derive from Exception alone
            raise GraphError(f"ONNX Runtime cannot load it: {str(exc).splitlines()[0][:160]}") from None
        self._input = next(iter(inputs))
        self._n_outputs = len(outputs)

    def __call__(self, x: Tensor) -> Tensor | tuple[Tensor, ...]:
        feed = {self._input: np.ascontiguousarray(x.detach().numpy(), dtype=np.float32)}
        outs = tuple(torch.from_numpy(o) for o in self._session.run(None, feed))
        return outs if self._n_outputs > 1 else outs[0]

    def difference(self, reference: Callable[[Tensor], object], examples: Sequence[Tensor]) -> float:
        """The largest absolute difference between this graph's outputs and ``reference``'s on
        ``examples`` (infinite where a value is not finite or a shape differs).

        Raises:
            GraphError: ONNX Runtime fails to run the graph.
        """
        worst = 0.0
        for x in examples:
            with torch.inference_mode():
                want = reference(x)
            try:
                got = self(x)
            except Exception as exc:  # ONNX Runtime's errors derive from Exception alone
                raise GraphError(f"ONNX Runtime cannot run it: {str(exc).splitlines()[0][:160]}") from None
            want_all = want if isinstance(want, tuple) else (want,)
            got_all = got if isinstance(got, tuple) else (got,)
            if len(want_all) != len(got_all):
                return float("inf")
            for a, b in zip(want_all, got_all):
                if not isinstance(a, Tensor) or a.shape != b.shape:
                    return float("inf")
                diff = float((a.float() - b.float()).abs().max())
                worst = max(worst, diff if np.isfinite(diff) else float("inf"))
        return worst


def make_graph(
    module: nn.Module, examples: Sequence[Tensor], inputs: str, outputs: Sequence[str], weights_sha256: str
) -> StoredGraph:
    """Export ``module`` (eval mode, on the CPU) for one input of ``examples[0]``'s shape and
    check the graph against it on every example.

    Args:
        module: the network as it runs, batch norms folded.
        examples: inputs the graph is checked on (a few, seeded).
        inputs: the name of the graph's input.
        outputs: the names of the module's outputs, in order.
        weights_sha256: :func:`weights_fingerprint` of the weights the bundle stores for it.

    Raises:
        GraphError: export failed, the graph fails the checks, or its outputs differ from
            PyTorch's by more than :data:`TOLERANCE`.
    """
    data = export(module, examples[0], [inputs], outputs)
    with torch.inference_mode():
        got = module(examples[0])
    shapes = [list(t.shape) for t in (got if isinstance(got, tuple) else (got,))]
    meta_inputs = {inputs: list(examples[0].shape)}
    meta_outputs = dict(zip(outputs, shapes))
    diff = OnnxNetwork(data, meta_inputs, meta_outputs).difference(module, examples)
    if not diff <= TOLERANCE:
        raise GraphError(f"its outputs differ from PyTorch's by {diff:.3g} (more than {TOLERANCE:g})")
    meta = GraphMeta(
        size=len(data),
        sha256=hashlib.sha256(data).hexdigest(),
        weights_sha256=weights_sha256,
        inputs=meta_inputs,
        outputs=meta_outputs,
        opset=OPSET,
        exporter=f"torch.onnx.export (dynamo), torch {torch.__version__.split('+')[0]}",
        max_abs_diff=float(f"{diff:.3g}"),
    )
    return StoredGraph(data, meta)


def read_graphs(
    path: str | Path, metas: Mapping[str, GraphMeta], tensors: Mapping[str, Tensor]
) -> dict[str, StoredGraph]:
    """The graphs a bundle stores that are whole and belong to its weights; each other one is
    left out with a :class:`~deepmorph_core.errors.DeepMorphWarning` (the network then runs
    from its weights: exported anew, or PyTorch).

    Args:
        path: the bundle (named in warnings).
        metas: the bundle's ``graphs`` metadata.
        tensors: every tensor of the bundle (``graph.<name>`` and the networks' weights).
    """
    found: dict[str, StoredGraph] = {}
    names = set(metas) | {k.removeprefix("graph.") for k in tensors if k.startswith("graph.")}
    for name in sorted(names):
        meta, tensor = metas.get(name), tensors.get(f"graph.{name}")
        limit = GRAPH_SIZE_FACTOR * weights_bytes(tensors, name) + GRAPH_SLACK
        if meta is None:
            problem = "the bundle has no record of it"
        elif tensor is None:
            problem = "its bytes are missing"
        elif weights_bytes(tensors, name) == 0:
            problem = "the bundle holds no weights of that network"
        elif max(meta.size, tensor.numel()) > limit:
            problem = f"{max(meta.size, tensor.numel())} bytes is far more than its network's weights"
        elif tensor.dtype != torch.uint8 or tensor.dim() != 1 or tensor.numel() != meta.size:
            problem = f"its bytes are {tensor.dtype} {tuple(tensor.shape)}, not the {meta.size} recorded"
        else:
            data = tensor.numpy().tobytes()
            if hashlib.sha256(data).hexdigest() != meta.sha256:
                problem = "it is damaged (its SHA-256 differs from the one recorded)"
            elif weights_fingerprint(tensors, name) != meta.weights_sha256:
                problem = "it was exported from other weights than the bundle's"
            else:
                found[name] = StoredGraph(data, meta)
                continue
        warnings.warn(DeepMorphWarning(f"{path}: the stored ONNX graph {name!r} is not used: {problem}"), stacklevel=3)
    return found


__all__ = [
    "ALLOWED_OPS",
    "MAX_TENSOR_ELEMENTS",
    "OPSET",
    "TOLERANCE",
    "GraphError",
    "OnnxNetwork",
    "StoredGraph",
    "check_graph",
    "export",
    "make_graph",
    "read_graphs",
    "weights_bytes",
    "weights_fingerprint",
]
