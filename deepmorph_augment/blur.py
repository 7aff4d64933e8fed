"""Gaussian blur (slight focus error, lens softness) with a sigma drawn per sample."""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.kernels import filter_separable_per_sample, gaussian_kernels, kernel_size
from deepmorph_augment.sampling import Sampler, value_range


class Blur(RandomAugmentation):
    """Separable Gaussian blur, one sigma per sample, all samples in one grouped convolution.

    Args:
        sigma: range of the standard deviation in pixels (a number ``m`` means ``[0, m]``);
            the kernel reaches ``3 * max sigma``.
        p: probability per sample.
    """

    name = "blur"
    stage = "optics"

    def __init__(self, *, sigma: float | Sequence[float] = 1.0, p: float = 1.0):
        super().__init__(p=p)
        self.sigma = value_range(sigma, "sigma", low=0.0, high=20.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {"sigma": sampler.uniform(self.sigma, images.shape[0])}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        size = kernel_size(3.0 * self.sigma[1] + 1.0)
        return filter_separable_per_sample(images, gaussian_kernels(params["sigma"], size))
