"""The shape every built-in augmentation shares: draw per-sample parameters, then apply a pure
function to the samples chosen with probability ``p`` (kornia's generate-then-apply split).

A subclass defines ``name``, ``stage``, :meth:`RandomAugmentation.sample` and
:meth:`RandomAugmentation.apply`; its constructor takes the ranges it samples from, plus ``p``.
"""

from __future__ import annotations

from typing import ClassVar

import torch
from torch import Tensor

from deepmorph_augment.sampling import Sampler, probability
from deepmorph_core.corruption import apply_to, check_images

Params = dict[str, Tensor]


class RandomAugmentation:
    """Base of the built-in augmentations (a convenience: the protocol needs only ``name`` and
    ``__call__``).

    Args:
        p: probability that a sample is corrupted (drawn per sample).
    """

    name: ClassVar[str]
    stage: ClassVar[str] = "custom"

    def __init__(self, *, p: float = 1.0):
        self.p = probability(p)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        """Per-sample parameters for the whole batch, each with leading dimension ``B``."""
        raise NotImplementedError

    def apply(self, images: Tensor, params: Params) -> Tensor:
        """Corrupt every sample of ``images`` with ``params`` (a pure function of both)."""
        raise NotImplementedError

    def draw(self, images: Tensor, generator: torch.Generator | None = None) -> tuple[Tensor, Params]:
        """Which samples are corrupted ``(B,)`` bool, and the parameters of all ``B``.

        The draws are always made for the whole batch in the same order, so a seeded generator
        replays them whatever ``p`` selects.
        """
        sampler = Sampler(images, generator)
        chosen = sampler.chance(self.p, images.shape[0])
        return chosen, self.sample(sampler, images)

    def __call__(self, images: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Corrupt a random subset (probability ``p`` each) of ``images``.

        Shape:
            images: ``(B, C, H, W)``; returns the same shape, device and dtype.
        """
        check_images(images, self.name)
        if self.p == 0.0:
            return images
        chosen, params = self.draw(images, generator)
        return apply_to(images, chosen, lambda x, idx: self.apply(x, {k: v[idx] for k, v in params.items()}))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in vars(self).items() if not k.startswith("_"))
        return f"{type(self).__name__}({args})"
