"""A spatial transformer in front of the decoder: it learns to undo what framing leaves.

Decoding frames every image by its ink's moments (:func:`deepmorph_core.framing.canonicalize`):
centre and spread land where the unmorphed drawing's do. Moments cannot undo a perspective, a
turn or a shear, and a morph moves points by about 2 % of the width, less than a residual
perspective of 3 % at the corners (the ``medium`` capture preset). A decoder that reads pixels
at fixed places then takes warp for morph: under ``medium`` corruption, the perspective step
alone costs it about one payload in fifty.

:class:`SpatialTransformer` (Jaderberg et al., 2015) is a small CNN that looks at the framed
image at half resolution and predicts a homography close to the identity; the image is
resampled through it before the decoder reads it. It is trained with the decoder, end to end
from the decoding loss (no alignment target), starting at the identity. It is the paper's own
suggestion of a spatial transformer, placed where the residual geometry is.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

REACH = 0.1  # scale of the predicted homography entries (normalised coordinates)
MIN_DEPTH = 0.25  # smallest projective denominator allowed (keeps the warp finite)


def normalised_grid(height: int, width: int) -> Tensor:
    """``(H, W, 3)`` homogeneous normalised coordinates of the pixel centres
    (``grid_sample``'s convention with ``align_corners=False``)."""
    ys = (torch.arange(height, dtype=torch.float32) * 2 + 1) / height - 1
    xs = (torch.arange(width, dtype=torch.float32) * 2 + 1) / width - 1
    gy, gx = torch.meshgrid(ys, xs, indexing="ij")
    return torch.stack([gx, gy, torch.ones_like(gx)], -1)


def warp_homography(images: Tensor, homography: Tensor, grid: Tensor) -> Tensor:
    """Resample white-paper images through homographies in normalised coordinates.

    Shape: images ``(B, 1, H, W)`` (1 = white), homography ``(B, 3, 3)`` mapping output to
    input coordinates, grid ``(H, W, 3)`` from :func:`normalised_grid` -> ``(B, 1, H, W)``.
    Everything the warp brings in from outside the image reads as paper.
    """
    pts = torch.einsum("hwk,bjk->bhwj", grid, homography)
    depth = pts[..., 2:3].clamp_min(MIN_DEPTH)
    source = pts[..., :2] / depth
    return F.grid_sample(images - 1.0, source, mode="bilinear", padding_mode="zeros", align_corners=False) + 1.0


class SpatialTransformer(nn.Module):
    """``(B, 1, H, W)`` framed images -> the same images resampled through a learned homography.

    Args:
        image_size: ``(H, W)`` of the images.
        channels: channels of the stride-2 convolutions of the localisation network (which
            sees the image average-pooled to half resolution).
        hidden: width of its hidden fully connected layer.

    The last layer starts at zero, so an untrained transformer is exactly the identity (a
    bilinear sample at the pixel centres returns the image unchanged).
    """

    CHANNELS = (8, 16, 32)
    HIDDEN = 64

    def __init__(self, image_size: tuple[int, int], channels: tuple[int, ...] = CHANNELS, hidden: int = HIDDEN):
        super().__init__()
        layers: list[nn.Module] = [nn.AvgPool2d(2)]
        h, w = image_size[0] // 2, image_size[1] // 2
        c_in = 1
        for c_out in channels:
            layers += [nn.Conv2d(c_in, c_out, 3, stride=2, padding=1), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True)]
            c_in, h, w = c_out, (h + 1) // 2, (w + 1) // 2
        self.features = nn.Sequential(*layers)
        self.head = nn.Sequential(
            nn.Flatten(), nn.Linear(c_in * h * w, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, 8)
        )
        nn.init.zeros_(self.head[-1].weight)
        nn.init.zeros_(self.head[-1].bias)
        self.register_buffer("grid", normalised_grid(*image_size), persistent=False)

    def homography(self, images: Tensor) -> Tensor:
        """``(B, 3, 3)`` output -> input homographies in normalised coordinates."""
        delta = self.head(self.features(images - 0.5)) * REACH
        full = torch.cat([delta, torch.zeros_like(delta[:, :1])], 1).view(-1, 3, 3)
        return torch.eye(3, dtype=images.dtype, device=images.device) + full

    def forward(self, images: Tensor) -> Tensor:
        return warp_homography(images, self.homography(images), self.grid.to(images.dtype))


__all__ = ["MIN_DEPTH", "REACH", "SpatialTransformer", "normalised_grid", "warp_homography"]
