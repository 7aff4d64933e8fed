"""Motion blur: camera shake during the exposure smears along a line."""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.kernels import filter_per_sample, kernel_size, line_kernels
from deepmorph_augment.sampling import Sampler, value_range


class MotionBlur(RandomAugmentation):
    """Line-kernel blur with a length and direction drawn per sample.

    Args:
        length: range of the smear length in pixels (a number ``m`` means ``[0, m]``).
        angle: range of its direction in degrees.
        p: probability per sample.
    """

    name = "motion_blur"
    stage = "optics"

    def __init__(
        self,
        *,
        length: float | Sequence[float] = 3.0,
        angle: Sequence[float] = (0.0, 180.0),
        p: float = 1.0,
    ):
        super().__init__(p=p)
        self.length = value_range(length, "length", low=0.0, high=40.0)
        self.angle = value_range(angle, "angle", low=-360.0, high=360.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        return {"length": sampler.uniform(self.length, b), "angle": sampler.uniform(self.angle, b)}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        size = kernel_size(0.5 * self.length[1] + 1.0)
        return filter_per_sample(images, line_kernels(params["length"], params["angle"], size))
