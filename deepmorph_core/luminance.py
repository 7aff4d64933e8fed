"""Luminance, or the channel a model reads: what the networks read of a colour print.

A colour image becomes one channel with a model's reading weights (:data:`Channel`): by default
the BT.601 weights :data:`LUMA_WEIGHTS`, the conversion OpenCV's ``COLOR_RGB2GRAY`` and Pillow's
``convert("L")`` make, so that training reads renders the way the photo chain reads photos. A
drawing whose colours differ far more in one of red, green or blue than in luminance (a yellow
face on white paper) is read in that channel instead (:mod:`deepmorph_core.reading_channel`).
"""

from __future__ import annotations

import numpy as np
from torch import Tensor

#: Weights of red, green and blue that make one gray channel (non-negative, adding up to 1).
Channel = tuple[float, float, float]

#: BT.601 luma weights of red, green and blue (JPEG's Y, OpenCV's and Pillow's gray).
LUMA_WEIGHTS: Channel = (0.299, 0.587, 0.114)


def is_luma(channel: Channel) -> bool:
    """Whether ``channel`` is BT.601 luminance: every conversion then takes its usual path."""
    return tuple(channel) == LUMA_WEIGHTS


def stretch_ink(images: Tensor | np.ndarray, level: float) -> Tensor | np.ndarray:
    """Renders with contrast stretched as a photo's is (``normalise_contrast``): ``level``, the
    luminance of the drawing's darkest paint, to 0; white paper stays 1. A drawing whose
    darkest paint is light (cyan on white: 0.53) then has ink darker than 0.5 in its renders,
    as in its photos, where framing, templates and the decoder look for it. Identity at
    ``level`` 0 (black ink)."""
    if level <= 0:
        return images
    scaled = (images - level) * (1.0 / (1.0 - level))
    return scaled.clamp(0.0, 1.0) if isinstance(images, Tensor) else np.clip(scaled, 0.0, 1.0)


def to_luminance(images: Tensor) -> Tensor:
    """The BT.601 luminance of RGB images; gray images are returned as they are
    (:func:`to_channel` with :data:`LUMA_WEIGHTS`)."""
    return to_channel(images, LUMA_WEIGHTS)


def to_channel(images: Tensor, channel: Channel) -> Tensor:
    """The gray that ``channel``'s weights make of RGB images; gray images are returned as
    they are.

    Linear (differentiable) and not clamped: RGB in ``[0, 1]`` gives gray in ``[0, 1]``.

    Shape:
        images: ``(B, 3, H, W)`` RGB or ``(B, 1, H, W)`` gray; returns ``(B, 1, H, W)``.

    Raises:
        ValueError: not a ``(B, C, H, W)`` batch with 1 or 3 channels.
    """
    if images.dim() != 4 or images.shape[1] not in (1, 3):
        raise ValueError(f"to_channel: expected (B, 3, H, W) or (B, 1, H, W) images, got {tuple(images.shape)}")
    if images.shape[1] == 1:
        return images
    r, g, b = images.unbind(1)
    wr, wg, wb = channel
    return (wr * r + wg * g + wb * b).unsqueeze(1)
