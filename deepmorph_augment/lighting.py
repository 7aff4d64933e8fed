"""Uneven lighting: a smooth multiplicative gain over the page (a lamp to one side, a
darker rim from the lens: vignetting)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.sampling import Sampler, value_range


def lighting_gain(gradient: Tensor, angle_deg: Tensor, vignette: Tensor, height: int, width: int) -> Tensor:
    """Per-sample illumination ``(1 + g (cos a x + sin a y)) (1 - v (x^2 + y^2) / 2)`` with
    ``x, y`` in ``[-1, 1]`` across the image: the gain is ``1 +- g`` at the edge midpoints the
    gradient points to and from, and the vignette darkens the corners by ``v``.

    Shape:
        gradient, angle_deg, vignette: ``(B,)``; returns ``(B, 1, H, W)``.
    """
    y = torch.linspace(-1.0, 1.0, height, device=gradient.device, dtype=gradient.dtype)[:, None]
    x = torch.linspace(-1.0, 1.0, width, device=gradient.device, dtype=gradient.dtype)[None, :]
    a = torch.deg2rad(angle_deg)[:, None, None]
    ramp = 1.0 + gradient[:, None, None] * (torch.cos(a) * x + torch.sin(a) * y)
    rim = 1.0 - vignette[:, None, None] * (x**2 + y**2) / 2.0
    return (ramp * rim)[:, None]


class Lighting(RandomAugmentation):
    """Multiply by a random linear light gradient and a vignette.

    Args:
        gradient: range of the gradient strength ``g`` (a number ``m`` means ``[-m, m]``;
            its direction is uniform over the circle).
        vignette: range of the corner darkening ``v`` (a number ``m`` means ``[0, m]``).
        p: probability per sample.
    """

    name = "lighting"
    stage = "lighting"

    def __init__(
        self,
        *,
        gradient: float | Sequence[float] = 0.2,
        vignette: float | Sequence[float] = 0.0,
        p: float = 1.0,
    ):
        super().__init__(p=p)
        self.gradient = value_range(gradient, "gradient", symmetric=True, low=-0.9, high=0.9)
        self.vignette = value_range(vignette, "vignette", low=0.0, high=0.9)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        return {
            "gradient": sampler.uniform(self.gradient, b),
            "angle": sampler.uniform((0.0, 360.0), b),
            "vignette": sampler.uniform(self.vignette, b),
        }

    def apply(self, images: Tensor, params: Params) -> Tensor:
        h, w = images.shape[-2:]
        return images * lighting_gain(params["gradient"], params["angle"], params["vignette"], h, w)
