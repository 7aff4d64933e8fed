"""Intensity: exposure and the camera's tone curve (ink reads grey, paper reads off-white)."""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.sampling import Sampler, value_range


def adjust_intensity(images: Tensor, contrast: Tensor, brightness: Tensor) -> Tensor:
    """``0.5 + contrast * (images - 0.5) + brightness`` per sample (contrast about mid-grey,
    so a low contrast greys ink and paper alike). Not clamped.

    Shape:
        images: ``(B, C, H, W)``; contrast, brightness: ``(B,)``; returns ``(B, C, H, W)``.
    """
    c, b = contrast[:, None, None, None], brightness[:, None, None, None]
    return 0.5 + c * (images - 0.5) + b


class Intensity(RandomAugmentation):
    """Contrast scale and brightness offset drawn per sample.

    Args:
        contrast: range of the contrast factor.
        brightness: range of the offset (a number ``m`` means ``[-m, m]``).
        p: probability per sample.
    """

    name = "intensity"
    stage = "intensity"

    def __init__(
        self,
        *,
        contrast: Sequence[float] = (0.6, 1.1),
        brightness: float | Sequence[float] = 0.15,
        p: float = 1.0,
    ):
        super().__init__(p=p)
        self.contrast = value_range(contrast, "contrast", low=0.0, high=4.0)
        self.brightness = value_range(brightness, "brightness", symmetric=True, low=-1.0, high=1.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        return {"contrast": sampler.uniform(self.contrast, b), "brightness": sampler.uniform(self.brightness, b)}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return adjust_intensity(images, params["contrast"], params["brightness"])
