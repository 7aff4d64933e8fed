"""Defocus: an out-of-focus lens spreads each point into a disk (its circle of confusion)."""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.kernels import disk_kernels, filter_per_sample, kernel_size
from deepmorph_augment.sampling import Sampler, value_range


class Defocus(RandomAugmentation):
    """Disk blur, one radius per sample, all samples in one grouped convolution.

    Args:
        radius: range of the disk radius in pixels (a number ``m`` means ``[0, m]``).
        p: probability per sample.
    """

    name = "defocus"
    stage = "optics"

    def __init__(self, *, radius: float | Sequence[float] = 1.5, p: float = 1.0):
        super().__init__(p=p)
        self.radius = value_range(radius, "radius", low=0.0, high=20.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {"radius": sampler.uniform(self.radius, images.shape[0])}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        size = kernel_size(self.radius[1] + 0.5)
        return filter_per_sample(images, disk_kernels(params["radius"], size))
