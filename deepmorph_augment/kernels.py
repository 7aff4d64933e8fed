"""Per-sample blur kernels and the grouped convolution that applies them (kornia's
``filter2d`` with a ``(B, k, k)`` kernel: one convolution call for the whole batch).

Borders replicate the edge pixels (paper stays paper). A kernel's size is fixed by the largest
value its augmentation can draw, so one size serves the whole batch.

Where no gradient is wanted on the CPU (photographing a scene, validation), OpenCV's filters
apply the same kernels with the same borders: on a 1280x720 photo torch's convolution took
80-270 ms a blur against OpenCV's 5-50 ms, outputs within 4e-7 (``tests/augment``). Training
batches that carry gradients keep kornia's differentiable path.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import torch
from kornia.filters import filter2d, filter2d_separable
from torch import Tensor


def kernel_size(reach: float) -> int:
    """The smallest odd size holding every integer offset ``|x| < reach`` (at least 1)."""
    return max(1, 2 * math.ceil(reach) - 1)


def _offsets(values: Tensor, size: int) -> Tensor:
    """``(size,)`` integer offsets ``-r..r`` on ``values``' device and dtype."""
    r = size // 2
    return torch.arange(-r, r + 1, device=values.device, dtype=values.dtype)


def gaussian_kernels(sigma: Tensor, size: int) -> Tensor:
    """Normalised 1-D Gaussians, one per sample; ``sigma = 0`` gives the identity kernel.

    Shape:
        sigma: ``(B,)`` pixels; returns ``(B, size)``.
    """
    x = _offsets(sigma, size)
    s = sigma.clamp_min(1e-3)[:, None]
    k = torch.exp(-0.5 * (x / s) ** 2)
    return k / k.sum(-1, keepdim=True)


def disk_kernels(radius: Tensor, size: int) -> Tensor:
    """Normalised anti-aliased disks (defocus), one per sample; ``radius = 0`` is the identity.

    A pixel's weight is its coverage estimate ``clamp(radius + 0.5 - distance, 0, 1)``.

    Shape:
        radius: ``(B,)`` pixels; returns ``(B, size, size)``.
    """
    x = _offsets(radius, size)
    dist = torch.sqrt(x[:, None] ** 2 + x[None, :] ** 2)
    k = (radius[:, None, None] + 0.5 - dist).clamp(0.0, 1.0)
    return k / k.sum((-2, -1), keepdim=True)


def line_kernels(length: Tensor, angle_deg: Tensor, size: int) -> Tensor:
    """Normalised anti-aliased line segments through the centre (motion blur), one per sample.

    A pixel's weight is ``clamp(1 - d, 0, 1)``, ``d`` its distance to the segment of ``length``
    pixels at ``angle_deg``; ``length = 0`` is the identity.

    Shape:
        length, angle_deg: ``(B,)``; returns ``(B, size, size)``.
    """
    x = _offsets(length, size)
    a = torch.deg2rad(angle_deg)[:, None, None]
    px, py = x[None, None, :], x[None, :, None]  # kernel column is x, row is y
    along = px * torch.cos(a) + py * torch.sin(a)
    across = -px * torch.sin(a) + py * torch.cos(a)
    beyond = (along.abs() - 0.5 * length[:, None, None]).clamp_min(0.0)
    k = (1.0 - torch.sqrt(beyond**2 + across**2)).clamp(0.0, 1.0)
    return k / k.sum((-2, -1), keepdim=True)


def _without_gradient(images: Tensor, kernels: Tensor) -> bool:
    """Whether OpenCV may filter: CPU tensors of 32- or 64-bit floats that need no gradient."""
    wanted = torch.is_grad_enabled() and (images.requires_grad or kernels.requires_grad)
    return not wanted and images.device.type == "cpu" and images.dtype in (torch.float32, torch.float64)


def _opencv_filtered(images: Tensor, kernels: Tensor, separable: bool) -> Tensor:
    """Each plane of ``images`` correlated with its sample's kernel by OpenCV, borders
    replicated: ``kernels`` ``(B, k)`` applied along both axes when ``separable``, else
    ``(B, k, k)``."""
    x = images.detach().contiguous().numpy()
    k = kernels.detach().cpu().numpy().astype(x.dtype)
    out = np.empty_like(x)
    for b in range(x.shape[0]):
        for c in range(x.shape[1]):
            if separable:
                out[b, c] = cv2.sepFilter2D(x[b, c], -1, k[b], k[b], borderType=cv2.BORDER_REPLICATE)
            else:
                out[b, c] = cv2.filter2D(x[b, c], -1, k[b], borderType=cv2.BORDER_REPLICATE)
    return torch.from_numpy(out)


def filter_per_sample(images: Tensor, kernels: Tensor) -> Tensor:
    """Correlate each sample with its own 2-D kernel (replicated borders).

    Shape:
        images: ``(B, C, H, W)``; kernels: ``(B, k, k)``; returns ``(B, C, H, W)``.
    """
    if kernels.dim() != 3 or kernels.shape[0] != images.shape[0]:
        raise ValueError(f"filter_per_sample: expected kernels ({images.shape[0]}, k, k), got {tuple(kernels.shape)}")
    if kernels.shape[-1] == 1:
        return images * kernels[:, None]
    if _without_gradient(images, kernels):
        return _opencv_filtered(images, kernels, separable=False)
    return filter2d(images, kernels, border_type="replicate")


def filter_separable_per_sample(images: Tensor, kernels: Tensor) -> Tensor:
    """Correlate each sample with its own separable kernel ``k k^T`` (replicated borders).

    Shape:
        images: ``(B, C, H, W)``; kernels: ``(B, k)``; returns ``(B, C, H, W)``.
    """
    if kernels.dim() != 2 or kernels.shape[0] != images.shape[0]:
        raise ValueError(
            f"filter_separable_per_sample: expected kernels ({images.shape[0]}, k), got {tuple(kernels.shape)}"
        )
    if kernels.shape[-1] == 1:
        return images * kernels[:, None, None] ** 2
    if _without_gradient(images, kernels):
        return _opencv_filtered(images, kernels, separable=True)
    return filter2d_separable(images, kernels, kernels, border_type="replicate")
