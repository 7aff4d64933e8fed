"""The detector network: a small anchor-free (CenterNet-style) CNN.

For a grayscale photo resized to :data:`INPUT_SIZE`, it predicts on a stride-8 grid

* a centre heatmap: the probability that a drawing's centre lies in each cell, and
* for each cell, the offsets from the cell centre to the four corners of the drawing's frame
  (in cells), so one peak gives a full quadrilateral: a homography, with any in-plane
  rotation and strong perspective.

Every peak is one drawing, so several drawings in one photo come out as several peaks. The
quadrilateral is then refined to sub-pixel accuracy on the full-resolution photo
(:mod:`deepmorph_detect.refine`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from deepmorph_core.networks import fused_for_inference

INPUT_SIZE = (256, 192)  # (width, height) the photo is resized to (keeping its aspect by padding)
STRIDE = 8


def _block(cin: int, cout: int, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride, padding=dilation, dilation=dilation, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class DetectorNet(nn.Module):
    """``(B, 1, H, W)`` normalised gray -> heatmap logits ``(B, 1, H/8, W/8)`` and corner
    offsets ``(B, 8, H/8, W/8)`` (x, y of TL, TR, BR, BL relative to the cell centre, in cells).

    The trunk reaches stride 16 with dilated convolutions (a receptive field wider than the
    largest drawing at the input size), and is upsampled back to stride 8 with a skip.
    """

    def __init__(self, width: int = 32) -> None:
        super().__init__()
        w = width
        self.stem = nn.Sequential(_block(1, w // 2, 2), _block(w // 2, w, 2), _block(w, w))  # /4
        self.down8 = nn.Sequential(_block(w, w + w // 2, 2), _block(w + w // 2, w + w // 2))  # /8
        self.down16 = nn.Sequential(
            _block(w + w // 2, 2 * w, 2), _block(2 * w, 2 * w, dilation=2), _block(2 * w, 2 * w, dilation=4)
        )  # /16
        self.fuse = _block(2 * w + w + w // 2, 2 * w)
        self.heat = nn.Sequential(_block(2 * w, w), nn.Conv2d(w, 1, 1))
        self.corners = nn.Sequential(_block(2 * w, w), nn.Conv2d(w, 8, 1))
        nn.init.constant_(self.heat[-1].bias, -2.19)  # prior 0.1: stable focal-loss start

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor]:
        f8 = self.down8(self.stem(x))
        f16 = self.down16(f8)
        up = F.interpolate(f16, size=f8.shape[-2:], mode="bilinear", align_corners=False)
        f = self.fuse(torch.cat([up, f8], 1))
        return self.heat(f), self.corners(f)


def detector_tensors(net: nn.Module) -> dict[str, Tensor]:
    """The network's state dict as a bundle files it: ``detector.*``, on the CPU (where a
    network trained on CUDA is saved and fingerprinted). The inverse of :func:`stored_weights`."""
    return {f"detector.{k}": v.detach().cpu() for k, v in net.state_dict().items()}


def stored_weights(detector_state: dict[str, Tensor]) -> dict[str, Tensor]:
    """A bundle's ``detector.*`` tensors (``DeepMorphModel.detector_state``) as the network's
    own state dict: the prefix the bundle files them under dropped."""
    return {k.removeprefix("detector."): v for k, v in detector_state.items()}


def normalise_input(gray: Tensor) -> Tensor:
    """Per-image standardisation of ``(B, 1, H, W)`` gray in ``[0, 1]`` (exposure-invariant)."""
    mean = gray.mean((1, 2, 3), keepdim=True)
    std = gray.std((1, 2, 3), keepdim=True).clamp_min(0.02)
    return (gray - mean) / std


def standardise(gray: np.ndarray) -> np.ndarray:
    """:func:`normalise_input` for one ``(H, W)`` float32 image, in numpy: the same numbers
    (to float rounding) without a torch operation per statistic, which costs four times as much
    on the 256x192 frame the detector reads."""
    mean, std = cv2.meanStdDev(gray)
    n = gray.size
    spread = max(float(std[0, 0]) * math.sqrt(n / max(n - 1, 1)), 0.02)  # torch's std: n - 1
    return ((gray - np.float32(mean[0, 0])) / np.float32(spread)).astype(np.float32, copy=False)


class DetectorGraph(nn.Module):
    """What the detector's ONNX graph computes: ``(1, 1, H, W)`` gray in ``[0, 1]`` (the photo
    area-resized and edge-padded to :data:`INPUT_SIZE`) -> heatmap logits and corner offsets,
    with the standardisation (:func:`normalise_input`) inside, so that a program running the
    graph has one step less to get right."""

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net

    def forward(self, gray: Tensor) -> tuple[Tensor, Tensor]:
        return self.net(normalise_input(gray))


def focal_loss(logits: Tensor, target: Tensor, alpha: float = 2.0, beta: float = 4.0) -> Tensor:
    """CenterNet's penalty-reduced focal loss over Gaussian-splatted centre heatmaps."""
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    pos = target.ge(0.999).float()
    neg = 1 - pos
    pos_loss = -torch.log(p) * (1 - p) ** alpha * pos
    neg_loss = -torch.log(1 - p) * p**alpha * (1 - target) ** beta * neg
    n = pos.sum().clamp_min(1.0)
    return (pos_loss.sum() + neg_loss.sum()) / n


__all__ = [
    "INPUT_SIZE",
    "STRIDE",
    "DetectorGraph",
    "DetectorNet",
    "detector_tensors",
    "focal_loss",
    "fused_for_inference",
    "normalise_input",
    "standardise",
    "stored_weights",
]
