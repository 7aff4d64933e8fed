"""A soft shadow across the page: a random polygon (a hand, a phone, a lamp's edge) darkening
what lies under it, its edge blurred as a shadow's penumbra is."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.kernels import filter_separable_per_sample, gaussian_kernels, kernel_size
from deepmorph_augment.sampling import Sampler, value_range
from deepmorph_core.geometry import winding_numbers

#: Most corners a shadow polygon has (it has 3 to this many).
MAX_CORNERS = 5
#: How far a corner may lie outside the image, as a share of its size (shadows enter from the side).
OVERHANG = 0.2


def polygon_masks(corners: Tensor, height: int, width: int) -> Tensor:
    """``1`` inside each sample's polygon (non-zero winding), ``0`` outside, at pixel centres.

    Shape:
        corners: ``(B, M, 2)`` in shares of the image's width and height (a polygon with fewer
        corners repeats its last one); returns ``(B, 1, H, W)`` on its device and dtype.
    """
    ys = (torch.arange(height, device=corners.device, dtype=corners.dtype) + 0.5) / height
    xs = (torch.arange(width, device=corners.device, dtype=corners.dtype) + 0.5) / width
    grid = torch.stack(torch.meshgrid(xs, ys, indexing="xy"), -1).reshape(-1, 2)
    inside = winding_numbers(grid, [corners]) != 0
    return inside.to(corners.dtype).reshape(-1, 1, height, width)


class Shadow(RandomAugmentation):
    """Darken a random soft-edged polygon of the image.

    Args:
        strength: range of the darkening (0.3: the shadow passes 70 % of the light).
        softness: range of the penumbra's Gaussian sigma in pixels.
        p: probability per sample.
    """

    name = "shadow"
    stage = "lighting"

    def __init__(
        self,
        *,
        strength: float | Sequence[float] = (0.2, 0.5),
        softness: float | Sequence[float] = (2.0, 12.0),
        p: float = 1.0,
    ):
        super().__init__(p=p)
        self.strength = value_range(strength, "strength", low=0.0, high=1.0)
        self.softness = value_range(softness, "softness", low=0.0, high=64.0)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        corners = sampler.uniform((-OVERHANG, 1.0 + OVERHANG), b, MAX_CORNERS, 2)
        count = 3 + (sampler.unit(b) * (MAX_CORNERS - 2)).floor()
        # a polygon of k corners repeats its k-th for the rest (zero-length edges wind nothing)
        keep = torch.arange(MAX_CORNERS, device=images.device)[None, :] < count[:, None]
        last = corners.gather(1, (count.long() - 1)[:, None, None].expand(b, 1, 2))
        corners = torch.where(keep[..., None], corners, last)
        return {
            "corners": corners,
            "strength": sampler.uniform(self.strength, b),
            "softness": sampler.uniform(self.softness, b),
        }

    def apply(self, images: Tensor, params: Params) -> Tensor:
        h, w = images.shape[-2:]
        # the inside test in float32 whatever the images' dtype: float64 replays the same shadow
        mask = polygon_masks(params["corners"].float(), h, w).to(images.dtype)
        size = kernel_size(3.0 * self.softness[1] + 1.0)
        mask = filter_separable_per_sample(mask, gaussian_kernels(params["softness"].to(images.dtype), size))
        return images * (1.0 - params["strength"][:, None, None, None] * mask)
