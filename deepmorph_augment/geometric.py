"""Geometric corruptions as 3x3 pixel-space matrices and one white-bordered warp.

Each geometric augmentation only builds per-sample matrices; the warp is shared, and the
pipeline composes consecutive geometric steps into a single warp (one resampling, as a real
rectified photo has).
"""

from __future__ import annotations

import torch
from kornia.geometry.transform import warp_perspective
from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation, apply_to


def warp_white(images: Tensor, matrix: Tensor) -> Tensor:
    """Warp ``images`` by ``matrix`` (source pixel -> destination pixel), bilinear, with
    everything outside the source filled white (paper).

    White fill is done as ``1 - warp(1 - images)`` with zero padding: exact, and one grid
    sample where kornia's ``padding_mode="fill"`` takes two (it warps a mask of ones too).

    Shape:
        images: ``(B, C, H, W)``; matrix: ``(B, 3, 3)`` in pixel coordinates (``x`` right,
        ``y`` down, pixel centres at integers); returns ``(B, C, H, W)``.
    """
    if matrix.shape != (images.shape[0], 3, 3):
        raise ValueError(f"warp_white: expected matrix of shape ({images.shape[0]}, 3, 3), got {tuple(matrix.shape)}")
    size = (images.shape[-2], images.shape[-1])
    return 1.0 - warp_perspective(1.0 - images, matrix.to(images.dtype), size, align_corners=True)


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


def warp_chosen(images: Tensor, chosen: Tensor, matrix: Tensor) -> Tensor:
    """:func:`warp_white` on the chosen samples only.

    Shape:
        images: ``(B, C, H, W)``; chosen: ``(B,)`` bool; matrix: ``(B, 3, 3)``.
    """
    return apply_to(images, chosen, lambda x, idx: warp_white(x, matrix[idx]))
