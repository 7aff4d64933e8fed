"""Rotation: the print was not square to the camera (in-plane), about the image centre."""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor

from deepmorph_augment.base import Params
from deepmorph_augment.geometric import GeometricAugmentation, about_centre, rotation_scale
from deepmorph_augment.sampling import Sampler, value_range


class Rotation(GeometricAugmentation):
    """Rotation about the centre by an angle drawn per sample.

    Args:
        degrees: range of angles in degrees (a number ``m`` means ``[-m, m]``).
        p: probability per sample.
    """

    name = "rotation"

    def __init__(self, *, degrees: float | Sequence[float] = 5.0, p: float = 1.0):
        super().__init__(p=p)
        self.degrees = value_range(degrees, "degrees", symmetric=True, low=-180.0, high=180.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {"angle": sampler.uniform(self.degrees, images.shape[0])}

    def matrix(self, params: Params, height: int, width: int) -> Tensor:
        angle = params["angle"]
        linear = rotation_scale(angle, angle.new_ones(angle.shape))
        return about_centre(linear, angle.new_zeros(angle.shape[0], 2), height, width)
