"""Impulse noise: dust, paper fibres and dead pixels set single pixels white or black."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.sampling import Sampler, probability, value_range


def impulse(images: Tensor, mask: Tensor, values: Tensor) -> Tensor:
    """``values`` where ``mask`` is set, ``images`` elsewhere: differentiable in ``images``
    (zero gradient where a pixel was replaced).

    Shape:
        images: ``(B, C, H, W)``; mask (bool), values: the same or broadcastable.
    """
    return torch.where(mask, values, images)


class SaltPepper(RandomAugmentation):
    """Replace a random fraction of pixels (drawn per sample) by white or black.

    Args:
        amount: range of the fraction of pixels replaced (a number ``m`` means ``[0, m]``).
        salt: probability that a replaced pixel is white rather than black.
        p: probability per sample.
    """

    name = "salt_pepper"
    stage = "impulse"

    def __init__(self, *, amount: float | Sequence[float] = 0.01, salt: float = 0.5, p: float = 1.0):
        super().__init__(p=p)
        self.amount = value_range(amount, "amount", low=0.0, high=1.0)
        try:
            self.salt = probability(salt)
        except ValueError:
            raise ValueError(f"salt: must lie in [0, 1], got {salt!r}") from None

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        # One draw u per pixel: replaced when u < amount, white when u < amount * salt.
        amount = sampler.uniform(self.amount, images.shape[0])[:, None, None, None]
        u = sampler.unit(*images.shape)
        return {"mask": u < amount, "values": (u < amount * self.salt).to(images.dtype)}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return impulse(images, params["mask"], params["values"])
