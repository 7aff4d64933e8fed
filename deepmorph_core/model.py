"""The two networks of the paper: a linear encoder (A, sigmoid, then the map T) and a small
CNN decoder (a few strided convolutions and a two-layer head).

Both are plain ``nn.Module``s over batched tensors; the morph space, rasterizer and
augmentations in between live in their own modules (:mod:`deepmorph_core.pipeline` wires them).
"""

from __future__ import annotations

import math

import torch
from pydantic import BaseModel, ConfigDict, Field
from torch import Tensor, nn


class Encoder(nn.Module):
    """Bits to encoder outputs in ``(0, 1)``: ``sigmoid(A (2b - 1))``.

    Bits enter as ``+-1`` so that no bias is needed: flipping a bit flips its contribution.
    ``A`` is initialised so that the pre-activations have a standard deviation of about 1.5,
    spreading a random encoder's morphs over most of each variable's range (stage 1 of the
    paper's schedule trains the decoder against exactly this random encoder).

    Args:
        code_bits: ``N_b``.
        n_variables: ``N_v``.
    """

    def __init__(self, code_bits: int, n_variables: int):
        super().__init__()
        self.linear = nn.Linear(code_bits, n_variables, bias=False)
        nn.init.normal_(self.linear.weight, std=1.5 / math.sqrt(code_bits))

    def forward(self, bits: Tensor) -> Tensor:
        """Shape: ``(B, N_b)`` in {0, 1} -> ``(B, N_v)`` in ``(0, 1)``."""
        return torch.sigmoid(self.linear(2.0 * bits - 1.0))


class DecoderConfig(BaseModel):
    """Architecture of the decoder CNN (stored in model bundles).

    Attributes:
        stem: channels of a first, full-resolution convolution (0: none). Morphs move strokes by
            a pixel or two; a stride-2 first layer sees that only half as well.
        channels: output channels of each stride-2 convolution.
        hidden: width of the first fully connected layer.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    stem: int = Field(default=16, ge=0, le=256)
    channels: tuple[int, ...] = Field(default=(32, 48, 64, 64), min_length=2, max_length=6)
    hidden: int = Field(default=128, ge=8, le=2048)


class Decoder(nn.Module):
    """A small CNN from ``(B, 1, H, W)`` images (1 = white paper) to ``(B, N_b)`` logits.

    Args:
        code_bits: ``N_b``.
        image_size: ``(H, W)`` the decoder is trained at.
        config: channels and head width.
    """

    def __init__(self, code_bits: int, image_size: tuple[int, int], config: DecoderConfig | None = None):
        super().__init__()
        cfg = config or DecoderConfig()
        layers: list[nn.Module] = []
        c_in = 1
        if cfg.stem:
            layers += [nn.Conv2d(1, cfg.stem, 3, padding=1), nn.BatchNorm2d(cfg.stem), nn.ReLU(inplace=True)]
            c_in = cfg.stem
        for c_out in cfg.channels:
            layers += [nn.Conv2d(c_in, c_out, 3, stride=2, padding=1), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True)]
            c_in = c_out
        self.features = nn.Sequential(*layers)
        h, w = image_size
        for _ in cfg.channels:
            h, w = (h + 1) // 2, (w + 1) // 2
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Linear(c_in * h * w, cfg.hidden),
            nn.ReLU(inplace=True),
            nn.Linear(cfg.hidden, code_bits),
        )
        self.image_size = image_size

    def forward(self, images: Tensor) -> Tensor:
        """Shape: ``(B, 1, H, W)`` -> ``(B, N_b)`` logits."""
        if images.dim() != 4 or images.shape[1] != 1 or tuple(images.shape[2:]) != tuple(self.image_size):
            raise ValueError(
                f"decoder expects (B, 1, {self.image_size[0]}, {self.image_size[1]}), got {tuple(images.shape)}"
            )
        # centre intensities so that white paper is +0.5 and black ink -0.5
        return self.head(self.features(images - 0.5))
