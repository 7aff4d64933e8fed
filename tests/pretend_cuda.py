"""A pretend CUDA device on the CPU, to check that the ``--device cuda`` paths keep their
tensors together where no GPU is at hand (CI never has one).

Tensors "on the device" are :class:`OnDevice` tensors: CPU tensors whose ``.device`` says
``cuda:0``. A torch function mode (:class:`PretendCuda`) sends factories and ``.to()`` calls that
name CUDA to the CPU and marks what they return; marks pass on through every operation (the
tensor subclass's default behaviour). Where a call mixes marked tensors with unmarked ones of
one or more dimensions, as CUDA refuses to (a zero-dimensional CPU tensor is allowed, as on
CUDA; so are CPU index tensors in ``x[idx]``), asks for ``.numpy()`` of a marked one, or draws
random numbers for the device from a CPU generator (CUDA refuses that too), the mode records the
project's innermost frame. The numbers are the CPU's; only placement is checked.
"""

from __future__ import annotations

import collections
import copy
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import torch
from torch.overrides import TorchFunctionMode

CUDA = torch.device("cuda", 0)
ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"deepmorph", "deepmorph_core", "deepmorph_augment", "deepmorph_detect", "deepmorph_primitives"}
# torch's own bookkeeping, where the pretend device's marks do not follow (gradients come back
# unmarked): what it mixes is not the project's doing
TORCH_OWN = ("/torch/optim/", "/torch/autograd/", "/torch/_tensor.py", "/torch/nn/utils/")
FACTORIES = {
    torch.zeros, torch.ones, torch.empty, torch.full, torch.arange, torch.linspace, torch.logspace, torch.tensor,
    torch.as_tensor, torch.rand, torch.randn, torch.randint, torch.randperm, torch.eye, torch.scalar_tensor,
    torch.zeros_like, torch.ones_like, torch.empty_like, torch.full_like, torch.rand_like, torch.randn_like,
    torch.randint_like,
}  # fmt: skip


class OnDevice(torch.Tensor):
    """A CPU tensor that says it is on ``cuda:0``."""

    @property
    def device(self) -> torch.device:  # type: ignore[override]
        return CUDA

    @property
    def is_cuda(self) -> bool:  # type: ignore[override]
        return True


def _in_project(filename: str) -> str | None:
    """``filename`` relative to the repository when it is in one of the packages, else None."""
    try:
        rel = Path(filename).resolve().relative_to(ROOT)
    except ValueError:
        return None
    return rel.as_posix() if rel.parts and rel.parts[0] in PACKAGES else None


def _names_cuda(where: Any) -> bool:
    if isinstance(where, torch.Tensor):
        return isinstance(where, OnDevice)
    return torch.device(where).type == "cuda" if isinstance(where, (str, torch.device)) else False


def _plain(t: torch.Tensor) -> torch.Tensor:
    with torch._C.DisableTorchFunctionSubclass():
        return t.view_as(t)


def _mark(out: Any) -> Any:
    if isinstance(out, torch.Tensor) and not isinstance(out, OnDevice):
        return out.as_subclass(OnDevice)
    if isinstance(out, (tuple, list)):
        return type(out)(_mark(o) for o in out)
    return out


def _tensors(x: Any, found: list[torch.Tensor]) -> list[torch.Tensor]:
    if isinstance(x, torch.Tensor):
        found.append(x)
    elif isinstance(x, (list, tuple)):
        for y in x:
            _tensors(y, found)
    elif isinstance(x, dict):
        for y in x.values():
            _tensors(y, found)
    return found


class PretendCuda(TorchFunctionMode):
    """The mode described in the module docstring; :attr:`mixes` counts ``(what, function,
    file:line)`` of each place where devices met."""

    def __init__(self) -> None:
        super().__init__()
        self.mixes: collections.Counter[tuple[str, str, str]] = collections.Counter()

    def _record(self, what: str, func: Any) -> None:
        stack = traceback.extract_stack()[:-2]
        ours = [(f, _in_project(f.filename)) for f in stack]
        ours = [(f, rel) for f, rel in ours if rel is not None]
        innermost = stack[-1].filename
        if not ours or any(part in innermost.replace("\\", "/") for part in TORCH_OWN):
            return  # an optimiser's step or autograd: the gradients are the CPU's here, not the project's doing
        frame, rel = ours[-1]
        where = f"{rel}:{frame.lineno}"
        self.mixes[(what, getattr(func, "__name__", str(func)), where)] += 1

    def _to(self, func: Any, args: tuple, kwargs: dict[str, Any]) -> Any:
        target, flags = kwargs.pop("device", None), []
        for a in args[1:]:
            if isinstance(a, (str, torch.device, torch.Tensor)):
                target = a
            elif isinstance(a, torch.dtype):
                kwargs["dtype"] = a
            elif isinstance(a, bool):
                flags.append(a)
        kwargs.update(zip(("non_blocking", "copy"), flags))
        if isinstance(target, torch.Tensor):
            kwargs.setdefault("dtype", target.dtype)
        if kwargs.get("dtype", torch.float32) is None:
            kwargs.pop("dtype")
        if target is None:
            return func(args[0], **kwargs)
        out = func(_plain(args[0]), **kwargs)
        return _mark(out) if _names_cuda(target) else _plain(out)

    def __torch_function__(self, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        kwargs = dict(kwargs or {})
        name = getattr(func, "__name__", "")
        if func in FACTORIES or name in ("new_zeros", "new_empty", "new_ones", "new_full", "new_tensor"):
            like = args[0] if name.endswith("_like") or name.startswith("new_") else None
            on_device = _names_cuda(kwargs.get("device", like))
            generator = kwargs.get("generator")
            if on_device and generator is not None and generator.device.type != "cuda":
                self._record("a CPU generator drawing on the device", func)
            if "device" in kwargs and _names_cuda(kwargs["device"]):
                kwargs["device"] = "cpu"
                return _mark(func(*args, **kwargs))
            return func(*args, **kwargs)
        if name == "to":
            return self._to(func, args, kwargs)
        if name == "cuda":
            return _mark(_plain(args[0]))
        if name == "cpu":
            return _plain(args[0])
        if name in ("numpy", "__array__"):
            if isinstance(args[0], OnDevice):
                self._record("numpy of a CUDA tensor", func)
            return func(_plain(args[0]), *args[1:], **kwargs)
        if name == "__deepcopy__":
            out = _mark(copy.deepcopy(_plain(args[0]).detach(), args[1] if len(args) > 1 else {}))
            if getattr(args[0], "_is_param", False):
                out.requires_grad_(args[0].requires_grad)
                out._is_param = True
            return out
        if name in (
            "__repr__",
            "__format__",
            "__str__",
            "copy_",
            "__reduce_ex__",
            "_has_compatible_shallow_copy_type",
            "__set__",
        ):
            return func(*args, **kwargs)
        tensors = _tensors(args, []) + _tensors(kwargs, [])
        if any(isinstance(t, OnDevice) for t in tensors):
            if name == "__getitem__":
                tensors = [args[0]]
            elif name == "__setitem__":
                tensors = [args[0], *_tensors(args[2:], [])]
            if any(not isinstance(t, OnDevice) and t.dim() > 0 for t in tensors):
                self._record("CUDA and CPU tensors in one call", func)
        return func(*args, **kwargs)


@contextmanager
def pretend_cuda() -> Iterator[PretendCuda]:
    """Within the block, ``torch.cuda`` says one device is there and ``cuda`` tensors are
    marked CPU tensors (modules' parameters too: ``.to()`` replaces them rather than their data);
    everything is as before once it ends. The universal detector's runners, cached per process
    and device, are dropped on entry and exit: a pretend ``cuda`` runner (CPU weights) must not
    serve a real CUDA device later in the same process, nor a real one serve the pretence.

    ONNX export (:func:`deepmorph_core.graphs.make_graph`, as the model and the detector call it) runs outside
    the mode, which its tracer does not follow; a network or example handed to it on the device
    is recorded and refused (the export traces CPU examples, so CUDA weights would fail it)."""
    import deepmorph_core.model as model_module
    import deepmorph_detect.centrenet as detector_module
    from deepmorph_core.graphs import GraphError
    from deepmorph_detect.universal import shared_runner

    pretend = {"is_available": lambda: True, "device_count": lambda: 1, "current_device": lambda: 0,
               "set_device": lambda *a, **k: None, "synchronize": lambda *a, **k: None}  # fmt: skip
    real = {name: getattr(torch.cuda, name) for name in pretend}
    real_make_graph = model_module.make_graph
    mode = PretendCuda()

    def make_graph_on_the_cpu(net: torch.nn.Module, examples: list[torch.Tensor], *args: Any, **kwargs: Any) -> Any:
        if any(isinstance(t, OnDevice) for t in [*net.parameters(), *net.buffers(), *examples]):
            mode._record("ONNX export of a CUDA network", real_make_graph)
            raise GraphError("pretend CUDA: the network or its examples are on the device")
        with torch.overrides._pop_mode_temporarily(), pytest.MonkeyPatch.context() as outside:
            for name, function in real.items():  # the exporter asks torch.cuda too
                outside.setattr(torch.cuda, name, function)
            return real_make_graph(net, examples, *args, **kwargs)

    overwrite = torch.__future__.get_overwrite_module_params_on_conversion()
    with pytest.MonkeyPatch.context() as patch:
        for module in (model_module, detector_module):
            patch.setattr(module, "make_graph", make_graph_on_the_cpu)
        for name, function in pretend.items():
            patch.setattr(torch.cuda, name, function)
        torch.__future__.set_overwrite_module_params_on_conversion(True)
        shared_runner.cache_clear()
        try:
            with mode:
                yield mode
        finally:
            shared_runner.cache_clear()
            torch.__future__.set_overwrite_module_params_on_conversion(overwrite)
