"""Geometric corruptions as 3x3 pixel-space matrices and one white-bordered warp.

Each geometric augmentation only builds per-sample matrices; the warp is core's
(:func:`~deepmorph_core.corruption.warp_white`), and the pipeline composes consecutive geometric
steps into a single warp (one resampling, as a real rectified photo has).
"""

from __future__ import annotations

import torch
from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_core.corruption import warp_white


def about_centre(linear: Tensor, shift: Tensor, height: int, width: int) -> Tensor:
    """The matrices ``T(c + shift) @ L @ T(-c)``, ``c`` the image centre.

    Shape:
        linear: ``(B, 2, 2)``; shift: ``(B, 2)`` pixels; returns ``(B, 3, 3)``.
    """
    centre = linear.new_tensor([(width - 1) / 2.0, (height - 1) / 2.0])
    out = torch.zeros(linear.shape[0], 3, 3, device=linear.device, dtype=linear.dtype)
    out[:, :2, :2] = linear
    out[:, :2, 2] = centre + shift - (linear @ centre)
    out[:, 2, 2] = 1.0
    return out


def rotation_scale(angle_deg: Tensor, scale: Tensor) -> Tensor:
    """``(B, 2, 2)`` rotations by ``angle_deg`` (clockwise on screen, ``y`` down) times ``scale``.

    Shape:
        angle_deg, scale: ``(B,)``.
    """
    a = torch.deg2rad(angle_deg)
    c, s = torch.cos(a) * scale, torch.sin(a) * scale
    return torch.stack([torch.stack([c, -s], -1), torch.stack([s, c], -1)], -2)


class GeometricAugmentation(RandomAugmentation):
    """An augmentation that is a per-sample warp; subclasses define :meth:`matrix`."""

    stage = "geometry"

    def matrix(self, params: Params, height: int, width: int) -> Tensor:
        """``(B, 3, 3)`` pixel-space matrices for ``params``."""
        raise NotImplementedError

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return warp_white(images, self.matrix(params, images.shape[-2], images.shape[-1]))

    def draw_matrices(self, images: Tensor, generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
        """The chosen samples ``(B,)`` and their matrices ``(B, 3, 3)`` (identity where not chosen),
        drawing exactly what :meth:`__call__` draws (so a fused warp replays the same way)."""
        b, h, w = images.shape[0], images.shape[-2], images.shape[-1]
        eye = torch.eye(3, device=images.device, dtype=images.dtype).expand(b, 3, 3)
        if self.p == 0.0:
            return torch.zeros(b, dtype=torch.bool, device=images.device), eye
        chosen, params = self.draw(images, generator)
        return chosen, torch.where(chosen[:, None, None], self.matrix(params, h, w), eye)
