"""Scale: the drawing appears larger or smaller (camera distance), about the image centre."""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor

from deepmorph_augment.base import Params
from deepmorph_augment.geometric import GeometricAugmentation, about_centre, rotation_scale
from deepmorph_augment.sampling import Sampler, value_range


class Scale(GeometricAugmentation):
    """Uniform scaling about the centre by a factor drawn per sample.

    Args:
        factor: range of scale factors, e.g. ``[0.9, 1.1]``.
        p: probability per sample.
    """

    name = "scale"

    def __init__(self, *, factor: Sequence[float] = (0.9, 1.1), p: float = 1.0):
        super().__init__(p=p)
        self.factor = value_range(factor, "factor", low=0.1, high=10.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {"factor": sampler.uniform(self.factor, images.shape[0])}

    def matrix(self, params: Params, height: int, width: int) -> Tensor:
        factor = params["factor"]
        linear = rotation_scale(factor.new_zeros(factor.shape), factor)
        return about_centre(linear, factor.new_zeros(factor.shape[0], 2), height, width)
