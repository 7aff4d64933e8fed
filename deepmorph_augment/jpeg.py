"""JPEG-like compression, differentiable: 8x8 block DCT as a matrix product, quantisation by
the IJG tables scaled for a quality, a differentiable rounding, and the inverse DCT.

It follows baseline JPEG (level shift by 128, orthonormal 8x8 DCT-II, the Annex K tables
scaled as libjpeg's ``jpeg_quality_scaling``): a grey image is one luminance plane; an RGB
image (three channels: the photo simulator's whole photos) is converted to YCbCr, its Y
compressed with the luminance table and its Cb and Cr subsampled 4:2:0 and compressed with
the chrominance table, as a phone's encoder does. Values stay continuous outside the rounding
(no 8-bit input or output rounding, no clamping: the pipeline clamps at the end).
Rounding follows Shin & Song, "JPEG-resistant Adversarial Images" (2017):
``"cubic"`` is ``round(x) + (x - round(x))^3``; ``"ste"`` (straight-through) rounds forward
and passes gradients unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import torch
import torch.nn.functional as F
from kornia.color import rgb_to_ycbcr, ycbcr_to_rgb
from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.colour import pool_chroma, unpool_chroma
from deepmorph_augment.sampling import Sampler, value_range

ROUNDINGS = ("ste", "cubic")

#: JPEG Annex K luminance quantisation table (row = vertical frequency).
LUMINANCE_TABLE = (
    (16, 11, 10, 16, 24, 40, 51, 61),
    (12, 12, 14, 19, 26, 58, 60, 55),
    (14, 13, 16, 24, 40, 57, 69, 56),
    (14, 17, 22, 29, 51, 87, 80, 62),
    (18, 22, 37, 56, 68, 109, 103, 77),
    (24, 35, 55, 64, 81, 104, 113, 92),
    (49, 64, 78, 87, 103, 121, 120, 101),
    (72, 92, 95, 98, 112, 100, 103, 99),
)

#: JPEG Annex K chrominance quantisation table.
CHROMINANCE_TABLE = (
    (17, 18, 24, 47, 99, 99, 99, 99),
    (18, 21, 26, 66, 99, 99, 99, 99),
    (24, 26, 56, 99, 99, 99, 99, 99),
    (47, 66, 99, 99, 99, 99, 99, 99),
    *((99,) * 8,) * 4,
)


def dct_matrix(like: Tensor) -> Tensor:
    """The orthonormal 8-point DCT-II matrix ``D`` (``D @ x`` transforms a column), on
    ``like``'s device and dtype.

    Shape:
        returns ``(8, 8)``.
    """
    k = torch.arange(8, device=like.device, dtype=torch.float64)
    d = torch.cos((2.0 * k[None, :] + 1.0) * k[:, None] * math.pi / 16.0) * math.sqrt(2.0 / 8.0)
    d[0] = math.sqrt(1.0 / 8.0)
    return d.to(like.dtype)


def quality_tables(quality: Tensor, base_table: tuple[tuple[int, ...], ...] = LUMINANCE_TABLE) -> Tensor:
    """Quantisation tables (luminance by default) for integer-rounded qualities in ``[1, 100]``
    (libjpeg's scaling: ``5000 / q`` below 50, ``200 - 2 q`` above, entries in ``[1, 255]``).

    Shape:
        quality: ``(B,)``; returns ``(B, 8, 8)`` on its device and dtype.
    """
    q = quality.detach().round().clamp(1.0, 100.0)[:, None, None]
    scale = torch.where(q < 50, 5000.0 / q, 200.0 - 2.0 * q)
    base = torch.tensor(base_table, device=quality.device, dtype=quality.dtype)
    return torch.floor((base * scale + 50.0) / 100.0).clamp(1.0, 255.0)


class _RoundStraightThrough(torch.autograd.Function):
    """``round`` forward, identity backward (one kernel each way)."""

    @staticmethod
    def forward(ctx: Any, x: Tensor) -> Tensor:
        return torch.round(x)

    @staticmethod
    def backward(ctx: Any, grad: Tensor) -> Tensor:
        return grad


def round_differentiable(x: Tensor, rounding: str = "ste") -> Tensor:
    """Round to integers with a useful gradient: ``"ste"`` (identity gradient) or ``"cubic"``
    (``round(x) + (x - round(x))^3``, gradient ``3 (x - round(x))^2``)."""
    if rounding == "ste":
        return _RoundStraightThrough.apply(x)
    if rounding == "cubic":
        r = torch.round(x).detach()
        return r + (x - r) ** 3
    raise ValueError(f"rounding: expected one of {', '.join(ROUNDINGS)}, got {rounding!r}")


def jpeg_compress(images: Tensor, quality: Tensor, rounding: str = "ste") -> Tensor:
    """Compress and decompress each sample at its quality.

    One channel is a luminance plane. Three channels are RGB: Y is compressed with the
    luminance table, Cb and Cr averaged over 2x2 blocks (4:2:0), compressed with the
    chrominance table and upsampled back bilinearly (as libjpeg decodes), then the result is converted back to RGB
    (kornia's conversions: Y has JPEG's weights exactly). Other channel counts are refused.

    Args:
        images: intensities in ``[0, 1]``.
        quality: JPEG quality per sample (rounded to an integer in ``[1, 100]``).
        rounding: ``"ste"`` or ``"cubic"`` (see :func:`round_differentiable`).

    Shape:
        images: ``(B, 1, H, W)`` or ``(B, 3, H, W)``; quality: ``(B,)``; returns the same shape.
    """
    if images.dim() != 4 or quality.shape != (images.shape[0],) or images.shape[1] not in (1, 3):
        raise ValueError(
            f"jpeg_compress: expected images (B, 1 or 3, H, W) and quality (B,), got {tuple(images.shape)} and "
            f"{tuple(quality.shape)}"
        )
    luma = quality_tables(quality.to(images.dtype))
    if images.shape[1] == 1:
        return compress_planes(images, luma, rounding)
    ycc = rgb_to_ycbcr(images)
    y = compress_planes(ycc[:, :1], luma, rounding)
    chroma_tables = quality_tables(quality.to(images.dtype), CHROMINANCE_TABLE)
    chroma = compress_planes(pool_chroma(ycc), chroma_tables, rounding)
    return ycbcr_to_rgb(torch.cat([y, unpool_chroma(chroma, images.shape[-2:])], 1))


def compress_planes(images: Tensor, tables: Tensor, rounding: str = "ste") -> Tensor:
    """Every channel compressed and decompressed as one JPEG plane with its sample's table.

    Every 8x8 block, flattened to 64 values, is transformed by ``kron(D, D)`` (the 2-D DCT as
    one 64x64 matrix). The level shift, the 0-255 scaling and each sample's quantisation
    table are folded into that matrix and a bias, so a whole batch is two ``baddbmm`` calls
    around the rounding, plus two block permutations. Sizes that are not multiples of 8 are
    padded by replicating the edge, then cropped back.

    Shape:
        images: ``(B, C, H, W)`` in ``[0, 1]``; tables: ``(B, 8, 8)``; returns ``(B, C, H, W)``.
    """
    b, c, h, w = images.shape
    ph, pw = -h % 8, -w % 8
    x = F.pad(images, (0, pw, 0, ph), mode="replicate") if ph or pw else images
    hb, wb = (h + ph) // 8, (w + pw) // 8
    d = dct_matrix(images)
    k = torch.kron(d, d)  # row-major block vectors: vec(D X D^T) = k @ vec(X)
    table = tables.reshape(b, 64)
    # Quantised coefficients: (255 x - 128) @ k^T / table. The level shift only reaches the DC
    # coefficient (8 * -128 for an orthonormal DCT).
    forward = 255.0 * k.T[None] / table[:, None, :]
    shift = torch.zeros(b, 1, 64, device=images.device, dtype=images.dtype)
    shift[:, 0, 0] = -1024.0 / table[:, 0]
    inverse = table[:, :, None] * k[None] / 255.0
    blocks = x.reshape(b, c, hb, 8, wb, 8).permute(0, 1, 2, 4, 3, 5).reshape(b, c * hb * wb, 64)
    levels = round_differentiable(torch.baddbmm(shift, blocks, forward), rounding)
    out = torch.baddbmm(torch.full_like(shift, 128.0 / 255.0), levels, inverse)
    out = out.reshape(b, c, hb, wb, 8, 8).permute(0, 1, 2, 4, 3, 5).reshape(b, c, hb * 8, wb * 8)
    return out[..., :h, :w]


class Jpeg(RandomAugmentation):
    """JPEG compression at a quality drawn per sample (see :func:`jpeg_compress`).

    Args:
        quality: range of JPEG qualities in ``[1, 100]``.
        rounding: ``"ste"`` (straight-through) or ``"cubic"``.
        p: probability per sample.
    """

    name = "jpeg"
    stage = "compression"

    def __init__(self, *, quality: Sequence[float] = (40.0, 90.0), rounding: str = "ste", p: float = 1.0):
        super().__init__(p=p)
        self.quality = value_range(quality, "quality", low=1.0, high=100.0)
        if rounding not in ROUNDINGS:
            raise ValueError(f"rounding: expected one of {', '.join(ROUNDINGS)}, got {rounding!r}")
        self.rounding = rounding

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {"quality": sampler.uniform(self.quality, images.shape[0])}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return jpeg_compress(images, params["quality"], self.rounding)
