"""Perspective: each image corner moves independently (a photo not taken square-on, roughly
rectified); the homography mapping the corners is found with kornia."""

from __future__ import annotations

from collections.abc import Sequence

from kornia.geometry.transform import get_perspective_transform
from torch import Tensor

from deepmorph_augment.base import Params
from deepmorph_augment.geometric import GeometricAugmentation
from deepmorph_augment.sampling import Sampler, value_range


def corner_homography(offsets: Tensor, height: int, width: int) -> Tensor:
    """Homographies moving the image corners by ``offsets`` (fractions of the image size).

    Shape:
        offsets: ``(B, 4, 2)`` for corners top-left, top-right, bottom-right, bottom-left, as
        ``(dx, dy)``; returns ``(B, 3, 3)`` pixel-space matrices.
    """
    if offsets.dim() != 3 or offsets.shape[1:] != (4, 2):
        raise ValueError(f"corner_homography: expected offsets of shape (B, 4, 2), got {tuple(offsets.shape)}")
    w, h = width - 1.0, height - 1.0
    src = offsets.new_tensor([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]).expand_as(offsets)
    dst = src + offsets * offsets.new_tensor([w, h])
    return get_perspective_transform(src, dst)


class Perspective(GeometricAugmentation):
    """Random corner jitter -> homography -> warp (white border).

    Args:
        jitter: each corner coordinate moves by a uniform fraction of the image size in this
            range (a number ``m`` means ``[-m, m]``).
        p: probability per sample.
    """

    name = "perspective"

    def __init__(self, *, jitter: float | Sequence[float] = 0.04, p: float = 1.0):
        super().__init__(p=p)
        self.jitter = value_range(jitter, "jitter", symmetric=True, low=-0.25, high=0.25)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {"offsets": sampler.uniform(self.jitter, images.shape[0], 4, 2)}

    def matrix(self, params: Params, height: int, width: int) -> Tensor:
        return corner_homography(params["offsets"], height, width)
