"""The two networks of the paper: a linear encoder (A, sigmoid, then the map T) and a small
CNN decoder (a few strided convolutions and a two-layer head).

Both are plain ``nn.Module``s over batched tensors; the morph space, rasterizer and
augmentations in between live in their own modules (:mod:`deepmorph.training.codec` wires them).
"""

from __future__ import annotations

import copy
import math
from typing import Annotated

import torch
from pydantic import BaseModel, ConfigDict, Field
from torch import Tensor, nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

from deepmorph_core.spatial import SpatialTransformer


class Encoder(nn.Module):
    """Bits to encoder outputs in ``(0, 1)``: ``sigmoid(A (2b - 1))``.

    Bits enter as ``+-1`` so that no bias is needed: flipping a bit flips its contribution.
    ``A`` starts as the paper's dense random matrix, scaled so that the pre-activations have a
    standard deviation of about 1.5. Training replaces that start by :func:`spread_weights`
    unless told otherwise (``TrainConfig.encoder_init``): stage 1 of the paper's schedule
    trains the decoder against whichever start is chosen.

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


def spread_weights(
    effects: Tensor, code_bits: int, generator: torch.Generator, strength: float = 4.0, same: float = 0.95
) -> Tensor:
    """A sparse start for the encoder matrix ``A``: each code bit drives its own variables.

    Why: a dense random ``A`` mixes all ``N_b`` bits into every variable, so one bit moves each
    variable by a tenth of its range and the decoder must undo a nonlinear mixture, which it
    does poorly even on clean renders. Giving each bit whole variables, pushed to the ends of
    their bounds (``sigmoid(+-strength)``, 98 % of the way for 4.0), makes every bit a
    full-range move.

    How:

    * Variables whose effects on the picture are the same (correlation ``>= same`` in absolute
      value: the two ends of the ghost's half-circle head, which both turn the half circle
      about the same centre) always go to the same bit, signed so that they add up. Two bits
      on twins would be told apart by nothing.
    * These groups are dealt out most visible first to the bit with the least visibility so
      far, so the bits end up about equally visible.
    * With fewer groups than bits, each group carries several bits at weights ``c, c/2, c/4 ...``
      (``c`` chosen so that all of them agreeing reach ``strength``): several distinguishable
      levels per variable.

    Signs and which bit goes where are drawn from ``generator``, so seeded runs stay reproducible.

    Args:
        effects: ``(N_v, N_v)`` Gram matrix of the variables' full-range picture changes
            (:meth:`~deepmorph_core.morphable.MorphableDrawing.effects`).
        code_bits: ``N_b``.
        generator: randomness for bit order and signs.
        strength: pre-activation of a variable driven by all of its bits agreeing.
        same: correlation from which two variables count as one.

    Returns:
        ``(N_v, N_b)``, the layout of ``Encoder.linear.weight``.
    """
    groups = twin_groups(effects, same)
    visibility = [float(signs @ effects[members][:, members] @ signs) for members, signs in groups]
    strongest_first = sorted(range(len(groups)), key=lambda g: -visibility[g])
    bit_order = torch.randperm(code_bits, generator=generator).tolist()
    flips = (torch.randint(0, 2, (len(groups), code_bits), generator=generator) * 2 - 1).float()
    weights = torch.zeros(effects.shape[0], code_bits)

    def drive(group: int, bit: int, weight: float) -> None:
        members, signs = groups[group]
        weights[members, bit] = weight * flips[group, bit] * signs.float()

    if len(groups) >= code_bits:
        load = {bit: 0.0 for bit in bit_order}
        for group in strongest_first:
            bit = min(bit_order, key=lambda b: load[b])  # first in bit_order among the least loaded
            load[bit] += visibility[group]
            drive(group, bit, strength)
    else:
        hosted: dict[int, list[int]] = {}
        for k, bit in enumerate(bit_order):
            hosted.setdefault(strongest_first[k % len(groups)], []).append(bit)
        for group, bits in hosted.items():
            top = strength / (2.0 - 2.0 ** (1 - len(bits)))
            for level, bit in enumerate(bits):
                drive(group, bit, top * 2.0**-level)
    return weights


def twin_groups(effects: Tensor, same: float = 0.95) -> list[tuple[list[int], Tensor]]:
    """Groups of variables with (nearly) the same effect (correlation ``>= same`` in absolute
    value), each with signs relative to its first: a decoder tells the members of a group apart
    by nothing, so a group carries what one variable does."""
    energy = effects.diagonal().clamp_min(1e-12)
    corr = effects / torch.sqrt(energy[:, None] * energy[None, :])
    groups: list[tuple[list[int], list[float]]] = []
    for var in range(effects.shape[0]):
        for members, signs in groups:
            c = float(corr[members[0], var])
            if abs(c) >= same:
                members.append(var)
                signs.append(1.0 if c > 0 else -1.0)
                break
        else:
            groups.append(([var], [1.0]))
    return [(members, torch.tensor(signs, dtype=effects.dtype)) for members, signs in groups]


class DecoderConfig(BaseModel):
    """Architecture of the decoder CNN (stored in model bundles).

    Attributes:
        stem: channels of a first, full-resolution convolution (0: none). Morphs move strokes by
            a pixel or two; a stride-2 first layer sees that only half as well.
        channels: output channels of each stride-2 convolution.
        hidden: width of the first fully connected layer.
        spatial_transformer: resample each image through a learned homography before reading
            it (:class:`~deepmorph_core.spatial.SpatialTransformer`). Off by default, so a
            bundle without this field loads without one.
        readout: a linear readout of the image's pixels added to the CNN's logits (a matched
            filter per bit). Training fits it by least squares where the CNN alone stalls
            (:func:`~deepmorph.training.codec.fit_readout`) and leaves it out where it does not.
            Off by default, so a bundle without this field loads without one.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    stem: int = Field(default=16, ge=0, le=256)
    channels: tuple[Annotated[int, Field(ge=1, le=512)], ...] = Field(
        default=(32, 48, 64, 64), min_length=2, max_length=6
    )
    hidden: int = Field(default=128, ge=8, le=2048)
    spatial_transformer: bool = False
    readout: bool = False


def decoder_parameters(code_bits: int, image_size: tuple[int, int], config: DecoderConfig) -> int:
    """How many weights a :class:`Decoder` of this shape has, without making one (so that a
    bundle asking for an absurd network is refused before anything is allocated)."""
    total, c_in = 0, 1
    if config.stem:
        total += 9 * c_in * config.stem + 3 * config.stem
        c_in = config.stem
    h, w = image_size
    for c_out in config.channels:
        total += 9 * c_in * c_out + 3 * c_out
        c_in, h, w = c_out, (h + 1) // 2, (w + 1) // 2
    total += c_in * h * w * config.hidden + config.hidden + config.hidden * code_bits + code_bits
    if config.readout:
        total += image_size[0] * image_size[1] * code_bits + code_bits
    if config.spatial_transformer:  # its localisation network, at half resolution
        c_in, h, w = 1, image_size[0] // 2, image_size[1] // 2
        for c_out in SpatialTransformer.CHANNELS:
            total += 9 * c_in * c_out + 3 * c_out
            c_in, h, w = c_out, (h + 1) // 2, (w + 1) // 2
        total += (
            c_in * h * w * SpatialTransformer.HIDDEN + SpatialTransformer.HIDDEN + SpatialTransformer.HIDDEN * 8 + 8
        )
    return total


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
        self.align = SpatialTransformer(image_size) if cfg.spatial_transformer else None
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
        self.readout = nn.Linear(image_size[0] * image_size[1], code_bits) if cfg.readout else None
        if self.readout is not None:  # contributes nothing until fitted (fit_readout) or trained
            nn.init.zeros_(self.readout.weight)
            nn.init.zeros_(self.readout.bias)
        self.image_size = image_size

    def forward(self, images: Tensor) -> Tensor:
        """Shape: ``(B, 1, H, W)`` -> ``(B, N_b)`` logits."""
        if images.dim() != 4 or images.shape[1] != 1 or tuple(images.shape[2:]) != tuple(self.image_size):
            raise ValueError(
                f"decoder expects (B, 1, {self.image_size[0]}, {self.image_size[1]}), got {tuple(images.shape)}"
            )
        if self.align is not None:
            images = self.align(images)
        # centre intensities so that white paper is +0.5 and black ink -0.5
        centred = images - 0.5
        logits = self.head(self.features(centred))
        if self.readout is not None:
            logits = logits + self.readout(centred.flatten(1))
        return logits


def fused_for_inference(net: nn.Module) -> nn.Module:
    """A copy of ``net`` in eval mode on the CPU with every batch norm folded into the
    convolution before it: the same outputs (to float rounding) with one pass less over each
    feature map. What the photo chain runs, and what is exported to ONNX."""
    fused = copy.deepcopy(net).cpu().eval()
    for module in fused.modules():
        if not isinstance(module, nn.Sequential):
            continue
        for i in range(len(module) - 1):
            conv, norm = module[i], module[i + 1]
            if isinstance(conv, nn.Conv2d) and isinstance(norm, nn.BatchNorm2d):
                module[i] = fuse_conv_bn_eval(conv, norm)
                module[i + 1] = nn.Identity()
    return fused
