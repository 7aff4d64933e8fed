"""Where the networks run: ``--device auto|cpu|cuda`` resolved to a torch device name.

Training, validation and the photo chain's networks (detector and decoder) all take the same
names; ``auto`` is CUDA where a CUDA device is present, else the CPU.
"""

from __future__ import annotations

import torch

from deepmorph_core.errors import DeepMorphError

#: What ``--device`` takes: ``auto`` is CUDA where a CUDA device is present, else the CPU.
DEVICES = ("auto", "cpu", "cuda")


def resolve_device(name: str) -> str:
    """``auto`` -> ``cuda`` when CUDA is available, else ``cpu``; ``cpu`` and ``cuda`` as they are.

    Raises:
        DeepMorphError: an unknown name, or ``cuda`` where no CUDA device is available.
    """
    if name not in DEVICES:
        raise DeepMorphError(f"--device {name}: expected one of {', '.join(DEVICES)}")
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise DeepMorphError("--device cuda was asked for but no CUDA device is available (use --device cpu)")
    return name


def torch_device(name: str) -> torch.device:
    """The torch device ``name`` resolves to (:func:`resolve_device`): CUDA's current device
    (``cuda:<index>``, which ``torch.cuda.set_device`` chose for a torchrun process), or the CPU."""
    if resolve_device(name) == "cuda":
        return torch.device("cuda", torch.cuda.current_device())
    return torch.device("cpu")


__all__ = ["DEVICES", "resolve_device", "torch_device"]
