"""Sensor noise: additive Gaussian noise with a level drawn per sample."""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.sampling import Sampler, value_range


class GaussianNoise(RandomAugmentation):
    """Add ``sigma * N(0, 1)`` per pixel, ``sigma`` drawn per sample.

    Args:
        sigma: range of the noise standard deviation (a number ``m`` means ``[0, m]``).
        p: probability per sample.
    """

    name = "gaussian_noise"
    stage = "noise"

    def __init__(self, *, sigma: float | Sequence[float] = 0.04, p: float = 1.0):
        super().__init__(p=p)
        self.sigma = value_range(sigma, "sigma", low=0.0, high=1.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        sigma = sampler.uniform(self.sigma, b)
        return {"noise": sigma[:, None, None, None] * sampler.normal(*images.shape)}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return images + params["noise"]
