"""Colour corruptions of a print and its capture: duller inks, tinted paper, a white-balance
error and JPEG's chroma subsampling.

They act on RGB images ``(B, 3, H, W)`` (paper white = 1) in the pipeline's ``"colour"`` stage,
before it converts to luminance (:func:`deepmorph_core.luminance.to_luminance`) for every later
stage. Gray images ``(B, 1, H, W)`` pass through them untouched, and without a random draw:
a seeded gray pipeline replays exactly as it did without colour steps.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from kornia.color import rgb_to_ycbcr, ycbcr_to_rgb
from torch import Tensor

from deepmorph_augment.base import Params, RandomAugmentation
from deepmorph_augment.sampling import Sampler, value_range
from deepmorph_core.corruption import check_images
from deepmorph_core.luminance import LUMA_WEIGHTS, to_luminance


def _per_sample(values: Tensor) -> Tensor:
    """``(B,)`` -> ``(B, 1, 1, 1)``, or ``(B, 3)`` -> ``(B, 3, 1, 1)``."""
    return values.reshape(values.shape[0], -1, 1, 1)


class ColourAugmentation(RandomAugmentation):
    """Base of the colour corruptions: RGB in, RGB out; gray input is returned as it is,
    drawing nothing from the generator."""

    stage = "colour"

    def __call__(self, images: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Corrupt a random subset (probability ``p`` each) of RGB ``images``.

        Shape:
            images: ``(B, 3, H, W)`` RGB, or ``(B, 1, H, W)`` gray (returned unchanged); returns
            the same shape, device and dtype.
        """
        check_images(images, self.name)
        if images.shape[1] == 1:
            return images
        if images.shape[1] != 3:
            raise ValueError(
                f"{self.name}: expected RGB (B, 3, H, W) or gray (B, 1, H, W) images, got {tuple(images.shape)}"
            )
        return super().__call__(images, generator)


def fade_ink(images: Tensor, desaturation: Tensor, black_lift: Tensor) -> Tensor:
    """Duller inks: each pixel's colour moved toward its own luminance by ``desaturation``
    (0 keeps it, 1 makes it gray), then the range of ink density shrunk by lifting black to
    ``black_lift`` (``lift + (1 - lift) x``: paper stays white). Not clamped.

    Shape:
        images: ``(B, 3, H, W)``; desaturation, black_lift: ``(B,)``; returns ``(B, 3, H, W)``.
    """
    d, k = _per_sample(desaturation), _per_sample(black_lift)
    dull = images - d * (images - to_luminance(images))
    return k + (1.0 - k) * dull


class InkFade(ColourAugmentation):
    """Faded or cheap inks: less saturated colours and greyer blacks (see :func:`fade_ink`).

    Desaturation blends toward BT.601 luminance, as Pillow's ``ImageEnhance.Color`` and
    kornia's ``adjust_saturation_with_gray_subtraction`` do (kornia's ``adjust_saturation``
    scales HSV saturation instead, which moves colours toward their brightest channel, not
    toward their luminance); written out here because kornia's version clamps to ``[0, 1]``.

    Args:
        desaturation: range of the share of saturation lost (a number ``m`` means ``[0, m]``).
        black_lift: range of the level black ink is lifted to (a number ``m`` means ``[0, m]``).
        p: probability per sample.
    """

    name = "ink_fade"

    def __init__(
        self,
        *,
        desaturation: float | Sequence[float] = 0.2,
        black_lift: float | Sequence[float] = 0.05,
        p: float = 1.0,
    ):
        super().__init__(p=p)
        self.desaturation = value_range(desaturation, "desaturation", low=0.0, high=1.0)
        self.black_lift = value_range(black_lift, "black_lift", low=0.0, high=0.9)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        return {
            "desaturation": sampler.uniform(self.desaturation, b),
            "black_lift": sampler.uniform(self.black_lift, b),
        }

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return fade_ink(images, params["desaturation"], params["black_lift"])


def paper_tint(grey: Tensor, warmth: Tensor) -> Tensor:
    """Per-sample RGB reflectance of the paper: ``(1 - grey)`` times ``(1, 1 - w/4, 1 - w)`` for
    a warm (cream, ``w > 0``) paper or ``(1 - |w|, 1 - |w|/4, 1)`` for a cool (bluish, ``w < 0``)
    one.

    Shape:
        grey, warmth: ``(B,)``; returns ``(B, 3)``.
    """
    warm, cool = warmth.clamp(min=0.0), (-warmth).clamp(min=0.0)
    tint = torch.stack([1.0 - cool, 1.0 - warmth.abs() / 4.0, 1.0 - warm], 1)
    return (1.0 - grey)[:, None] * tint


class PaperTint(ColourAugmentation):
    """Tinted paper: the image multiplied by the paper's RGB reflectance (see
    :func:`paper_tint`); ink is multiplicative over paper, so white takes the tint and black
    stays black.

    Args:
        grey: range of the paper's darkening, every channel alike (a number ``m`` means
            ``[0, m]``).
        warmth: range of its colour, cream (``> 0``) to bluish (``< 0``): the share of blue
            (or red) it absorbs (a number ``m`` means ``[-m, m]``).
        p: probability per sample.
    """

    name = "paper_tint"

    def __init__(
        self,
        *,
        grey: float | Sequence[float] = 0.04,
        warmth: float | Sequence[float] = 0.04,
        p: float = 1.0,
    ):
        super().__init__(p=p)
        self.grey = value_range(grey, "grey", low=0.0, high=0.5)
        self.warmth = value_range(warmth, "warmth", symmetric=True, low=-0.5, high=0.5)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        return {"grey": sampler.uniform(self.grey, b), "warmth": sampler.uniform(self.warmth, b)}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return images * _per_sample(paper_tint(params["grey"], params["warmth"]))


def white_balance_gains(temperature: Tensor, tint: Tensor) -> Tensor:
    """Per-channel gains ``(1 + t, 1 + g, 1 - t)`` divided by their BT.601 luminance, so that
    a neutral gray keeps its luminance: ``t > 0`` is a warm (amber) cast, ``t < 0`` a cool
    (blue) one, ``g > 0`` green and ``g < 0`` magenta.

    Shape:
        temperature, tint: ``(B,)``; returns ``(B, 3)``.
    """
    wr, wg, wb = LUMA_WEIGHTS
    gains = torch.stack([1.0 + temperature, 1.0 + tint, 1.0 - temperature], 1)
    return gains / (1.0 + (wr - wb) * temperature + wg * tint)[:, None]


class WhiteBalance(ColourAugmentation):
    """A white-balance error: per-channel gains (see :func:`white_balance_gains`), the
    luminance of grays kept, plus an optional additive colour cast per channel (coloured
    ambient light, black-level error), each channel then clipped to ``[0, 1]`` as a camera's
    8-bit output is (so a cast greys white paper a little, as it does in a photo).

    Args:
        temperature: range of the amber (``> 0``) / blue (``< 0``) gain error (a number ``m``
            means ``[-m, m]``).
        tint: range of the green (``> 0``) / magenta (``< 0``) gain error (same).
        cast: range of the offset added to each channel, drawn per channel (same).
        p: probability per sample.
    """

    name = "white_balance"

    def __init__(
        self,
        *,
        temperature: float | Sequence[float] = 0.08,
        tint: float | Sequence[float] = 0.03,
        cast: float | Sequence[float] = 0.0,
        p: float = 1.0,
    ):
        super().__init__(p=p)
        self.temperature = value_range(temperature, "temperature", symmetric=True, low=-0.5, high=0.5)
        self.tint = value_range(tint, "tint", symmetric=True, low=-0.5, high=0.5)
        self.cast = value_range(cast, "cast", symmetric=True, low=-0.2, high=0.2)

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        b = images.shape[0]
        return {
            "temperature": sampler.uniform(self.temperature, b),
            "tint": sampler.uniform(self.tint, b),
            "cast": sampler.uniform(self.cast, b, 3),
        }

    def apply(self, images: Tensor, params: Params) -> Tensor:
        gains = white_balance_gains(params["temperature"], params["tint"])
        return (images * _per_sample(gains) + _per_sample(params["cast"])).clamp(0.0, 1.0)


UPSAMPLING = ("bilinear", "nearest")


def subsample_chroma(images: Tensor, upsample: str = "bilinear") -> Tensor:
    """JPEG's 4:2:0 chroma: RGB to YCbCr, Cb and Cr averaged over 2x2 blocks (edges
    replicated, as libjpeg pads) and upsampled back, Y untouched, then back to RGB clamped to
    ``[0, 1]`` as a JPEG decoder clamps.

    kornia's conversions are used: Y has JPEG's weights exactly; Cb and Cr are scaled by 0.564
    and 0.713 where JFIF has 0.5/0.886 and 0.5/0.701 (0.5643, 0.7133), but the way back is
    their exact inverse and averaging commutes with a scale, so the result does not depend on
    them. ``"bilinear"`` upsampling (half-pixel centres) is libjpeg's default "fancy"
    upsampling, which Pillow and OpenCV decode with; ``"nearest"`` repeats each block.

    Shape:
        images: ``(B, 3, H, W)``; returns ``(B, 3, H, W)``.
    """
    if upsample not in UPSAMPLING:
        raise ValueError(f"upsample: expected one of {', '.join(UPSAMPLING)}, got {upsample!r}")
    ycc = rgb_to_ycbcr(images)
    chroma = unpool_chroma(pool_chroma(ycc), images.shape[-2:], upsample)
    return ycbcr_to_rgb(torch.cat([ycc[:, :1], chroma], 1))


def pool_chroma(ycc: Tensor) -> Tensor:
    """Cb and Cr of a YCbCr batch averaged over 2x2 blocks, odd edges replicated (as libjpeg pads).

    Shape:
        ycc: ``(B, 3, H, W)``; returns ``(B, 2, ceil(H / 2), ceil(W / 2))``.
    """
    h, w = ycc.shape[-2:]
    chroma = ycc[:, 1:]
    if h % 2 or w % 2:
        chroma = F.pad(chroma, (0, w % 2, 0, h % 2), mode="replicate")
    return F.avg_pool2d(chroma, 2)


def unpool_chroma(chroma: Tensor, size: tuple[int, int], upsample: str = "bilinear") -> Tensor:
    """Pooled chroma (:func:`pool_chroma`) back to ``size`` ``(H, W)``: bilinear with half-pixel
    centres (libjpeg's "fancy" upsampling), or each block repeated (``"nearest"``).

    Shape:
        chroma: ``(B, C, h, w)``; returns ``(B, C, H, W)``.
    """
    if upsample == "nearest":
        chroma = chroma.repeat_interleave(2, -2).repeat_interleave(2, -1)
    else:
        doubled = (2 * chroma.shape[-2], 2 * chroma.shape[-1])
        chroma = F.interpolate(chroma, size=doubled, mode="bilinear", align_corners=False)
    return chroma[..., : size[0], : size[1]]


class ChromaSubsampling(ColourAugmentation):
    """JPEG's 4:2:0 chroma subsampling (see :func:`subsample_chroma`).

    It belongs to the capture's compression, but it is colour-only, so it runs in the
    ``"colour"`` stage, before the conversion to luminance: Y is untouched, so luminance sees
    the lost chroma only where the decoded RGB clips (a saturated colour next to another),
    which is the point of reading luminance. So running it ahead of geometry and optics
    changes what luminance sees only through where it clips. Put it after the other colour
    steps (config order within a stage).

    Args:
        upsample: ``"bilinear"`` (libjpeg's default) or ``"nearest"``.
        p: probability per sample.
    """

    name = "chroma_subsampling"

    def __init__(self, *, upsample: str = "bilinear", p: float = 1.0):
        super().__init__(p=p)
        if upsample not in UPSAMPLING:
            raise ValueError(f"upsample: expected one of {', '.join(UPSAMPLING)}, got {upsample!r}")
        self.upsample = upsample

    def sample(self, sampler: Sampler, images: Tensor) -> Params:
        return {}

    def apply(self, images: Tensor, params: Params) -> Tensor:
        return subsample_chroma(images, self.upsample)
