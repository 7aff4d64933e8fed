"""Bringing a drawing into the decoder's frame by its ink's moments, as training frames renders.

Training frames its renders and decoding frames its photos the same way: the ink's centre and
spread (its first and second moments) land where the unmorphed drawing's do in the decoder's
image. Moments average over every ink pixel, so one moved control point shifts them only a
little. What framing leaves (a turn, a perspective) is what the decoder's spatial transformer
and the training corruption cover.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from deepmorph_core.kernels import area_resize
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, to_channel
from deepmorph_core.photo import ink_mask, normalise_contrast


def mask_moments(mask: Tensor) -> Tensor:
    """Centre and spread of ink masks: ``(B, H, W)`` bool -> ``(B, 4)`` = cx, cy, sx, sy (pixels).

    Moments average over every ink pixel, so one moved control point shifts them only a
    little: a far steadier frame than a bounding box, which any extreme point drags along.
    An empty mask gives the frame's own centre and spread.
    """
    B, H, W = mask.shape
    w = mask.to(torch.float64)
    total = w.sum((1, 2)).clamp_min(1.0)
    xs = torch.arange(W, dtype=torch.float64, device=mask.device) + 0.5
    ys = torch.arange(H, dtype=torch.float64, device=mask.device) + 0.5
    cx = (w.sum(1) * xs).sum(1) / total
    cy = (w.sum(2) * ys).sum(1) / total
    sx = torch.sqrt((w.sum(1) * (xs - cx[:, None]) ** 2).sum(1) / total).clamp_min(1.0)
    sy = torch.sqrt((w.sum(2) * (ys - cy[:, None]) ** 2).sum(1) / total).clamp_min(1.0)
    empty = mask.flatten(1).sum(1) == 0
    frame = torch.tensor([W / 2, H / 2, W / 4, H / 4], dtype=torch.float64, device=mask.device)
    return torch.where(empty[:, None], frame, torch.stack([cx, cy, sx, sy], 1))


def mask_moments_one(mask: np.ndarray) -> np.ndarray:
    """:func:`mask_moments` of one ``(H, W)`` mask, by OpenCV: ``(4,)`` float64 cx, cy, sx, sy.
    The same numbers (to float rounding) about six times faster, for decoding one photo."""
    H, W = mask.shape
    m = cv2.moments(np.asarray(mask, dtype=np.uint8), binaryImage=True)
    if m["m00"] == 0:
        return np.array([W / 2, H / 2, W / 4, H / 4], dtype=np.float64)
    spread = np.sqrt(np.array([m["mu20"], m["mu02"]]) / m["m00"])
    return np.array([m["m10"] / m["m00"] + 0.5, m["m01"] / m["m00"] + 0.5, *np.maximum(spread, 1.0)])


def canonicalize(images: Tensor, moments: Tensor, target: Tensor, size: tuple[int, int]) -> Tensor:
    """Resample so that each image's ink moments land on ``target`` in a white ``size`` frame.

    Used identically in training (on renders) and in decoding (on photos), so the decoder
    always sees drawings framed the same way. Differentiable w.r.t. ``images`` (bilinear).

    Shape:
        images ``(B, 1, h, w)``, moments ``(B, 4)`` (cx, cy, sx, sy in input pixels),
        target ``(4,)`` in output pixels -> ``(B, 1, H, W)``.
    """
    H, W = size
    h_in, w_in = images.shape[-2:]
    dtype, device = images.dtype, images.device
    m = moments.to(dtype=dtype, device=device)
    t = target.to(dtype=dtype, device=device)
    u = torch.arange(W, dtype=dtype, device=device) + 0.5
    v = torch.arange(H, dtype=dtype, device=device) + 0.5
    x = m[:, 0:1] + (u[None] - t[0]) * (m[:, 2:3] / t[2])  # (B, W) input coordinates
    y = m[:, 1:2] + (v[None] - t[1]) * (m[:, 3:4] / t[3])  # (B, H)
    gx = (x / w_in * 2 - 1)[:, None, :].expand(-1, H, -1)
    gy = (y / h_in * 2 - 1)[:, :, None].expand(-1, -1, W)
    grid = torch.stack([gx, gy], -1)
    # sample (image - 1) with zero padding so that everything outside the photo reads as white paper
    out = F.grid_sample(images - 1.0, grid, mode="bilinear", padding_mode="zeros", align_corners=False) + 1.0
    return out.clamp(0.0, 1.0)


def frame_renders(images: Tensor, target: Tensor, size: tuple[int, int], channel: Channel = LUMA_WEIGHTS) -> Tensor:
    """Clean renders framed by their own ink, as training and validation frame theirs.

    Shape:
        images ``(B, C, h, w)`` (gray, or colour framed by its gray in the reading
        ``channel``), target ``(4,)`` -> ``(B, C, H, W)`` with ``(H, W) = size``.
    """
    return canonicalize(images, render_moments(to_channel(images, channel)), target, size)


def render_moments(images: Tensor) -> Tensor:
    """Ink moments of clean renders ``(B, 1, H, W)`` (ink = darker than 0.5): ``(B, 4)``."""
    with torch.no_grad():
        return mask_moments(images[:, 0] < 0.5)


def align_to_frame(
    gray: np.ndarray, size: tuple[int, int], target: Tensor, moments: np.ndarray | None = None
) -> tuple[np.ndarray, tuple[int, int, int, int]] | None:
    """Bring a photo or scan into the decoder's frame, as training frames its renders.

    Args:
        gray: ``(h, w)`` float image, 1 = white.
        size: ``(H, W)`` of the decoder's frame.
        target: ``(4,)`` ink moments of the unmorphed drawing in that frame.
        moments: ``(4,)`` where the drawing's ink is in ``gray`` (cx, cy, sx, sy), when that is
            known better than the photo's ink shows it: a rectified view, where the unmorphed
            drawing's ink lies wherever the alignment put it. A shadow's edge or a fill as dark
            as the photo's ink threshold moves the measured moments, not these. Measured from
            the ink mask when ``None``.

    Returns:
        The ``(H, W)`` float32 frame and the ink's bounding box in the input, or ``None`` when
        the image holds no drawing (blank, or no ink).
    """
    norm = normalise_contrast(gray)
    if norm is None:
        return None
    found = ink_mask(norm)
    if found is None:
        return None
    mask, box = found
    moments = mask_moments_one(mask) if moments is None else np.asarray(moments, dtype=np.float64)
    goal = target.detach().cpu().numpy() if isinstance(target, Tensor) else np.asarray(target)
    src, moments = shrink_to_frame(norm, moments, float(goal[2]))
    return canonicalize_one(np.ascontiguousarray(src, dtype=np.float32), moments, goal, size), box


#: how far a source's scale may be from a whole multiple of the frame's and still be averaged by
#: that multiple (:func:`shrink_to_frame`)
WHOLE_MULTIPLE_SLACK = 0.1


def shrink_to_frame(gray: np.ndarray, moments: np.ndarray, target_spread: float) -> tuple[np.ndarray, np.ndarray]:
    """Area-average a source larger than the decoder's frame down to about the frame's scale.

    A render at the decoder's width is an area average of the drawing over each pixel; sampling
    a larger image bilinearly instead skips pixels, and the edges it leaves sit up to a fraction
    of a pixel off, which is what the morphs are made of. A source about a whole multiple larger
    (a rectified view is two decoder widths wide) is averaged over blocks of that many pixels,
    any other by its exact ratio, which reads less well (``docs/design-notes.md``).

    Args:
        gray: ``(h, w)`` float32 image.
        moments: ``(4,)`` cx, cy, sx, sy of its ink in its pixels.
        target_spread: the ink's ``sx`` in the decoder's frame.

    Returns:
        The image at about the frame's scale (``gray`` itself when it is not larger) and its
        ink's moments in its pixels.
    """
    ratio = float(moments[2]) / target_spread
    whole = round(ratio)
    if whole >= 2 and abs(ratio - whole) <= WHOLE_MULTIPLE_SLACK:
        size = (gray.shape[1] // whole, gray.shape[0] // whole)
    elif ratio > 1 + WHOLE_MULTIPLE_SLACK:
        size = (max(1, round(gray.shape[1] / ratio)), max(1, round(gray.shape[0] / ratio)))
    else:
        return gray, moments
    small = area_resize(gray, size)
    scale = np.array([small.shape[1] / gray.shape[1], small.shape[0] / gray.shape[0]] * 2)
    return small, moments * scale


def canonicalize_one(
    gray: np.ndarray, moments: np.ndarray, target: Tensor | np.ndarray, size: tuple[int, int]
) -> np.ndarray:
    """:func:`canonicalize` of one ``(h, w)`` float32 image by OpenCV: the same map (a scale
    and a shift) and the same bilinear sampling with white beyond the edges, in a quarter of the
    time. It differs by about 1e-4 in intensity on average and by up to 0.02 on the steepest
    edges (OpenCV rounds sample positions to 1/32 pixel).

    Args:
        moments: ``(4,)`` cx, cy, sx, sy of the ink in ``gray``'s pixels.
        target: ``(4,)`` where they go in the ``size`` = ``(H, W)`` output.
    """
    H, W = size
    cx, cy, sx, sy = (float(v) for v in moments)
    tx, ty, tsx, tsy = (float(v) for v in target)
    ax, ay = sx / tsx, sy / tsy
    # output pixel u (centre u + 0.5) samples input position cx + (u + 0.5 - tx) * ax, whose
    # pixel-centre coordinate (OpenCV's) is half a pixel less
    M = np.array([[ax, 0.0, cx + (0.5 - tx) * ax - 0.5], [0.0, ay, cy + (0.5 - ty) * ay - 0.5]])
    out = cv2.warpAffine(
        gray, M, (W, H), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0
    )
    return np.clip(out, 0.0, 1.0, out=out)
