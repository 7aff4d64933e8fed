"""Translation: the drawing is off-centre after rough rectification."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from deepmorph_augment.base import Params
from deepmorph_augment.geometric import GeometricAugmentation, about_centre
from deepmorph_augment.sampling import Sampler, value_range


class Translation(GeometricAugmentation):
    """Shift by a fraction of the image size, drawn per sample and per axis.

    Args:
        fraction: range of the shift as a fraction of width (x) and height (y); a number ``m``
            means ``[-m, m]``.
        p: probability per sample.
    """

    name = "translation"

    def __init__(self, *, fraction: float | Sequence[float] = 0.04, p: float = 1.0):
        super().__init__(p=p)
        self.fraction = value_range(fraction, "fraction", symmetric=True, low=-0.5, high=0.5)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {"shift": sampler.uniform(self.fraction, images.shape[0], 2)}

    def matrix(self, params: Params, height: int, width: int) -> Tensor:
        shift = params["shift"]
        eye = torch.eye(2, device=shift.device, dtype=shift.dtype).expand(shift.shape[0], 2, 2)
        return about_centre(eye, shift * shift.new_tensor([width - 1.0, height - 1.0]), height, width)
