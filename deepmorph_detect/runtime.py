"""The photo chain's two networks, the detector and the decoder, run by ONNX Runtime.

Both are small convolution stacks run on one image at a time, where PyTorch's eager mode
spends much of its time between the layers (dispatch, and oneDNN converting each feature map to
its blocked layout and back). ONNX Runtime fuses each convolution with its ReLU, plans its
memory once and keeps one layout: on one core the decoder takes about half of PyTorch's time,
with or without a spatial transformer.

On a CUDA device (``Locator(..., device="cuda")``, ``decode --device``) both run in PyTorch
on that device instead (:class:`DeviceNetwork`): ONNX Runtime's CPU build is what the package
installs.

The graphs come from the bundle, where training stored them (:mod:`deepmorph_core.graphs`). A
bundle without one (written before graphs were stored, or by an interrupted run) has it
exported once per process, kept with the loaded model, and a warning says how to store it.
:func:`onnx_or_torch` checks every graph against the PyTorch network on a few inputs before
using it, and keeps PyTorch, with a warning, where no graph can be had or a graph disagrees.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence

import torch
from torch import Tensor, nn

from deepmorph_core.errors import DeepMorphWarning
from deepmorph_core.graphs import TOLERANCE, GraphError, OnnxNetwork, StoredGraph
from deepmorph_core.model import DeepMorphModel

Network = Callable[[Tensor], "Tensor | tuple[Tensor, ...]"]


def _warn(text: str) -> None:
    warnings.warn(DeepMorphWarning(text), stacklevel=3)


def _checked(stored: StoredGraph, net: Network, examples: Sequence[Tensor]) -> tuple[OnnxNetwork | None, str]:
    """``stored`` run by ONNX Runtime when it passes the checks and gives ``net``'s outputs;
    otherwise ``None`` and why."""
    try:
        fast = OnnxNetwork(stored.data, stored.meta.inputs, stored.meta.outputs)
        diff = fast.difference(net, examples)
    except GraphError as exc:
        return None, str(exc)
    if diff <= TOLERANCE:
        return fast, ""
    return None, f"its outputs differ from PyTorch's by {diff:.3g}"


class DeviceNetwork:
    """A PyTorch network run on a device (eval mode, no gradients): its input moved there, its
    outputs brought back to the CPU, so that it is called as the CPU's networks are."""

    def __init__(self, net: nn.Module, device: str) -> None:
        self.device = torch.device(device)
        self.net = net.to(self.device).eval()

    def __call__(self, x: Tensor) -> Tensor | tuple[Tensor, ...]:
        with torch.inference_mode():
            out = self.net(x.to(self.device))
        if isinstance(out, tuple):
            return tuple(o.cpu() for o in out)
        return out.cpu()


def onnx_or_torch(
    model: DeepMorphModel | None,
    name: str,
    net: Network,
    examples: Sequence[Tensor],
    export: Callable[[], StoredGraph],
    graph: StoredGraph | None = None,
    device: str = "cpu",
    module: Callable[[], nn.Module] | None = None,
) -> Network:
    """The network ``name`` of ``model`` run by ONNX Runtime, or ``net`` (PyTorch) itself; on
    another device than the CPU, the module ``module`` makes run there (:class:`DeviceNetwork`).

    The graph is the one ``model.graphs`` holds, else the one ``export`` makes (then kept in
    ``model.graphs``, so that other locators of the same model share it and a save stores it).
    It is used when it passes the checks (:class:`~deepmorph_core.graphs.OnnxNetwork`) and gives
    ``net``'s outputs on ``examples`` within :data:`~deepmorph_core.graphs.TOLERANCE`;
    otherwise a warning says why and ``net`` runs. Either is called the same way, on a tensor
    of the examples' shape.

    Args:
        model: the loaded model (``None``: the graph is exported and not kept).
        name: the network's name in the bundle (``decoder``, ``detector``).
        net: the PyTorch network (eval mode, batch norms folded), or a callable around it.
        examples: inputs the graph is checked on.
        export: makes the graph from ``net``'s weights.
        graph: the stored graph to use for a network of no model (the universal detector's).
        device: a resolved torch device name (:func:`~deepmorph_core.device.resolve_device`).
        module: makes the network as a module called as ``net`` is, for ``device`` (default:
            ``net`` itself); called only off the CPU.
    """
    if device != "cpu":
        target = module() if module is not None else net
        if not isinstance(target, nn.Module):
            raise TypeError(f"onnx_or_torch: {name} on {device} needs the network as a module")
        return DeviceNetwork(target, device)
    label = (model.source if model is not None else None) or "the model"
    stored = model.graphs.get(name) if model is not None else graph
    if stored is not None:
        fast, problem = _checked(stored, net, examples)
        if fast is not None:
            return fast
        if model is not None:
            model.graphs.pop(name, None)
        _warn(f"{label}: its stored ONNX graph {name!r} is not used: {problem}")
    t0 = time.perf_counter()
    try:
        stored = export()
    except GraphError as exc:
        _warn(f"{label}: PyTorch runs its {name}: no ONNX graph could be made ({exc})")
        return net
    fast, problem = _checked(stored, net, examples)
    if fast is None:
        _warn(f"{label}: PyTorch runs its {name}: the exported ONNX graph is not usable ({problem})")
        return net
    if model is not None:
        model.graphs[name] = stored
        _warn(
            f"{label} holds no ONNX graph of its {name}: exported one in {time.perf_counter() - t0:.1f} s"
            + (f" (`deepmorph export {label} --bundle {label}` stores it)" if model.source else "")
        )
    return fast


__all__ = ["DeviceNetwork", "onnx_or_torch"]
