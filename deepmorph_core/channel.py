"""How well photos of a print show each readable group of a drawing's variables, and the payload
that allows: the physics a ``--pixels`` plan starts from.

A print ``print_px`` pixels wide in the photo: random one-bit codes on the readable groups (the
encoder's start, :func:`~deepmorph_core.networks.spread_weights`), rendered by resvg at that width
and framed by their ink, then the photometric steps of the ``medium`` capture in the camera's
pixels (blur, motion, light, contrast, noise, JPEG; alignment perfect), each image at zero mean and
unit variance. A ridge map from the pixels to each group's position, fitted on most renders and
measured on the rest, gives the rms error ``sigma`` of reading the group, in units of its range.
Each group is then a Gaussian channel with its input held to its range. Its capacity and
dispersion (Blahut-Arimoto), summed over the groups, give the information a code carries with
99 % of its words right (the normal approximation of Polyanskiy, Poor and Verdu 2010); less the
default CRC, that is the payload a perfect decoder of such a reading carries
(:attr:`ChannelReading.payload_bits`).

The reading sees what a count of groups cannot: how far each variable moves in the photo's
pixels, the contrast of the edge it moves, and how groups crowd each other. It is a linear reading
at perfect alignment, so trained models read a share of it
(:data:`~deepmorph_core.capacity.CHANNEL_SHARE`). A linear map reads a move well while the
picture changes about in proportion to it, up to about a stroke's width; far wider moves (a
2.5-unit stroke moved 1.5 units each way) change it otherwise, and read worse here than smaller
ones (a payload of 21 bits against 32 for moves of 0.4): such bounds are planned low.
"""

from __future__ import annotations

import functools
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from deepmorph_core.corruption import AugmentPipeline
from deepmorph_core.morphable import INVISIBLE, MorphableDrawing

#: The width at which look-alike variables and visibility are judged (the decoder's frame).
GROUPS_WIDTH = 96
#: Renders the ridge map is fitted on, and renders it is measured on.
SAMPLES, TEST_SAMPLES = 2500, 1000
#: The ridge at :data:`GROUPS_WIDTH` px; it grows with the frame's area.
RIDGE = 10.0
#: Pixels per block of the Gram matrix (bounds its memory).
GRAM_BLOCK = 8192
#: Share of words that must come back right.
WORD_RATE = 0.99
#: The rms errors the channel table is computed at (interpolated between).
SIGMA_GRID = np.linspace(0.02, 0.6, 59)
#: The steps of a capture that move the picture (left out: the alignment counts as perfect).
GEOMETRIC_STEPS = frozenset({"perspective", "scale", "rotation", "translation"})


# -- the channel of one group ------------------------------------------------------------------


def gaussian_channel(levels: np.ndarray, sigma: float, outputs: int) -> np.ndarray:
    """``P(y | x)`` of ``y = x + N(0, sigma^2)`` for inputs ``levels`` in ``[0, 1]``, ``y`` on a
    grid of ``outputs`` points reaching five ``sigma`` beyond the range: ``(len(levels), outputs)``."""
    y = np.linspace(-5 * sigma, 1 + 5 * sigma, outputs)
    channel = np.exp(-((y[None] - levels[:, None]) ** 2) / (2 * sigma**2))
    return channel / channel.sum(1, keepdims=True)


def information_density(p: np.ndarray, channel: np.ndarray) -> np.ndarray:
    """``log2 P(y | x) / P(y)`` (bits) for the input distribution ``p``."""
    return np.log2(channel / (p @ channel)[None] + 1e-300)


def amplitude_limited(sigma: float, inputs: int = 41, outputs: int = 801, iters: int = 600) -> tuple[float, float]:
    """Capacity (bits) and dispersion (bits^2) of the Gaussian channel with its input held to
    ``[0, 1]``: Blahut-Arimoto over ``inputs`` evenly spaced levels."""
    channel = gaussian_channel(np.linspace(0.0, 1.0, inputs), sigma, outputs)
    p = np.full(inputs, 1.0 / inputs)
    for _ in range(iters):
        p *= np.exp2((channel * information_density(p, channel)).sum(1))
        p /= p.sum()
    info = information_density(p, channel)
    capacity = float((p[:, None] * channel * info).sum())
    dispersion = float((p[:, None] * channel * (info - capacity) ** 2).sum())
    return capacity, dispersion


def binary_input(sigma: float, outputs: int = 2001) -> float:
    """Capacity (bits) of the same channel with the input at one end or the other (one bit per group)."""
    p = np.array([0.5, 0.5])
    channel = gaussian_channel(np.array([0.0, 1.0]), sigma, outputs)
    return float((p[:, None] * channel * information_density(p, channel)).sum())


class ChannelTable:
    """Capacity, dispersion and binary capacity against sigma, computed once and interpolated."""

    def __init__(self) -> None:
        rows = [(*amplitude_limited(s), binary_input(s)) for s in SIGMA_GRID]
        self.capacity, self.dispersion, self.binary = (np.array(col) for col in zip(*rows))

    def __call__(self, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s = np.clip(sigma, SIGMA_GRID[0], SIGMA_GRID[-1])
        return tuple(np.interp(s, SIGMA_GRID, col) for col in (self.capacity, self.dispersion, self.binary))


@functools.cache
def channel_table() -> ChannelTable:
    """The one :class:`ChannelTable` (about a second to compute)."""
    return ChannelTable()


def information_at(capacity: float, dispersion: float, symbols: int, word_rate: float = WORD_RATE) -> float:
    """Normal approximation of the information bits a code of ``symbols`` uses of channels with
    summed ``capacity`` and ``dispersion`` carries with ``word_rate`` of its words right."""
    if symbols == 0:
        return 0.0
    q = statistics.NormalDist().inv_cdf(word_rate)
    return max(0.0, capacity - math.sqrt(dispersion) * q + 0.5 * math.log2(symbols))


def payload_within(information_bits: float) -> int:
    """The largest payload whose bits and default CRC fit in ``information_bits`` (0 if none)."""
    from deepmorph_core.codec import choose_codec

    for payload in range(int(information_bits), 0, -1):
        if payload + choose_codec(payload, bch_t=0).crc_bits <= information_bits:
            return payload
    return 0


# -- reading the groups ------------------------------------------------------------------------


def ridge_rms(pixels: np.ndarray, targets: np.ndarray, test: int, width: int = GROUPS_WIDTH) -> np.ndarray:
    """Rms error per target column of a ridge map fitted on all rows but the last ``test``.

    Solved in its dual form (the Gram matrix of the fitted rows, accumulated in float64 over
    blocks of pixels), which gives the primal's weights and needs no pixels-by-pixels matrix:
    a 300-px frame has 90,000. The ridge grows with the frame's area (:data:`RIDGE` at
    :data:`GROUPS_WIDTH` px, times ``(width / GROUPS_WIDTH)^2``), so that wider frames are
    regularised alike."""
    fit, held = slice(None, -test), slice(-test, None)
    mean_x, mean_t = pixels[fit].mean(0, dtype=np.float64), targets[fit].mean(0)
    rows = len(pixels)
    gram = np.zeros((rows, rows))
    for lo in range(0, pixels.shape[1], GRAM_BLOCK):
        block = pixels[:, lo : lo + GRAM_BLOCK].astype(np.float64) - mean_x[lo : lo + GRAM_BLOCK]
        gram += block @ block.T
    fitted = gram[fit, fit].copy()
    fitted[np.diag_indices_from(fitted)] += RIDGE * (width / GROUPS_WIDTH) ** 2
    dual = np.linalg.solve(fitted, targets[fit] - mean_t)
    return np.sqrt(((gram[held, fit] @ dual + mean_t - targets[held]) ** 2).mean(0))


def medium_steps(width: int, geometric: bool = False, print_px: int | None = None) -> AugmentPipeline:
    """The ``medium`` capture with only its geometric steps (``geometric``) or without them; with
    ``print_px``, its pixel parameters the camera's for a print that many pixels wide."""
    from deepmorph_core.severity import residual_steps

    steps = [
        {"name": name, "p": p, "params": params}
        for name, p, params in residual_steps("medium", width, print_px=print_px)
        if (name in GEOMETRIC_STEPS) == geometric
    ]
    return AugmentPipeline({"steps": steps})


def framed_renders(drawing: MorphableDrawing, unit: torch.Tensor, width: int) -> torch.Tensor:
    """resvg renders of the encoder outputs ``unit`` (B, N_v), framed by their ink: (B, 1, H, W)."""
    from deepmorph_core.framing import frame_renders

    real = drawing.render_real(drawing.values_from_unit(unit), width)
    return frame_renders(real, drawing.neutral_moments(width), tuple(real.shape[-2:]))


def corrupted(
    images: torch.Tensor,
    steps: Callable[[torch.Tensor, torch.Generator], torch.Tensor],
    seed: int,
    batch: int = 500,
    standardise: bool = True,
) -> np.ndarray:
    """``steps(images, generator)`` over ``images`` in batches, as float32 rows of pixels; with
    ``standardise``, each row at zero mean and unit variance (a reading that ignores contrast and
    brightness, as a CNN's normalisation does)."""
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        out = [steps(images[i : i + batch], generator) for i in range(0, len(images), batch)]
    flat = torch.cat(out).flatten(1)
    if standardise:
        flat = (flat - flat.mean(1, keepdim=True)) / flat.std(1, keepdim=True).clamp_min(1e-6)
    return flat.numpy()


@dataclass(frozen=True)
class GroupCodes:
    """Random codes on a drawing's groups of look-alike variables.

    Attributes:
        unit: ``(B, N_v)`` the encoder's outputs (each variable's place in its range).
        targets: ``(B, G)`` each readable group's place in its range (its first variable's).
        visible: the drawing's visible variables.
    """

    unit: torch.Tensor
    targets: np.ndarray
    visible: int


def group_codes(drawing: MorphableDrawing, samples: int, seed: int, continuous: bool = False) -> GroupCodes:
    """``samples`` codes of the encoder's start (:func:`~deepmorph_core.networks.spread_weights`,
    one code bit per group of look-alikes, groups and visibility judged at
    :data:`GROUPS_WIDTH` px): each group at one end of its range or the other, or with
    ``continuous`` anywhere between (a regression of binary positions measures how well a reader
    tells two apart, not how finely it places them)."""
    from deepmorph_core.networks import spread_weights, twin_groups

    effects = drawing.effects(drawing.rasterizer(GROUPS_WIDTH))
    groups = twin_groups(effects)
    shown = drawing.visibility(GROUPS_WIDTH) > INVISIBLE
    firsts = [members[0] for members, _ in groups if shown[members].any()]
    weights = spread_weights(effects, len(groups), torch.Generator().manual_seed(seed))
    rng = np.random.default_rng(seed + 1)
    shape = (samples, len(groups))
    levels = rng.uniform(-1.0, 1.0, shape) if continuous else 2 * rng.integers(0, 2, shape) - 1
    unit = torch.sigmoid(torch.from_numpy(levels.astype(np.float32)) @ weights.T)
    return GroupCodes(unit, unit[:, firsts].numpy().astype(np.float64), int(shown.sum()))


@dataclass(frozen=True)
class ChannelReading:
    """What a linear reading of photos of a print carries.

    Attributes:
        print_px: the print's width in the photo.
        sigma: ``(G,)`` each readable group's rms reading error (its range is 1).
        visible: the drawing's visible variables.
        capacity_bits: the groups' summed capacity.
        information_bits: what a code over the groups carries with 99 % of words right.
        payload_bits: that, less the default CRC: the payload of a perfect decoder of this reading.
        seconds: how long the measurement took.
    """

    print_px: int
    sigma: np.ndarray
    visible: int
    capacity_bits: float
    information_bits: float
    payload_bits: int
    seconds: float


def summarise(sigma: np.ndarray) -> tuple[float, float, int]:
    """The summed capacity, the information at :data:`WORD_RATE` and its payload of groups read
    with rms errors ``sigma``."""
    capacity, dispersion, _ = channel_table()(sigma)
    information = information_at(float(capacity.sum()), float(dispersion.sum()), len(sigma))
    return float(capacity.sum()), information, payload_within(information)


def read_channel(drawing: MorphableDrawing, print_px: int, samples: int = SAMPLES, seed: int = 0) -> ChannelReading:
    """Measure ``drawing``'s channel for prints ``print_px`` wide in the photo (see the module
    docstring): ``samples`` renders to fit the ridge map and :data:`TEST_SAMPLES` to measure it,
    by ``seed``. About half a minute at 200 px on one thread."""
    start = time.perf_counter()
    codes = group_codes(drawing, samples + TEST_SAMPLES, seed)
    renders = framed_renders(drawing, codes.unit, print_px)
    capture = medium_steps(print_px, print_px=print_px)
    seen = corrupted(renders, lambda images, generator: capture(images, generator=generator), seed + 2)
    sigma = ridge_rms(seen, codes.targets, TEST_SAMPLES, print_px)
    capacity, information, payload = summarise(sigma)
    seconds = round(time.perf_counter() - start, 1)
    return ChannelReading(print_px, sigma, codes.visible, capacity, information, payload, seconds)


__all__ = [
    "SAMPLES",
    "TEST_SAMPLES",
    "ChannelReading",
    "ChannelTable",
    "GroupCodes",
    "amplitude_limited",
    "binary_input",
    "channel_table",
    "corrupted",
    "framed_renders",
    "gaussian_channel",
    "group_codes",
    "information_at",
    "information_density",
    "medium_steps",
    "payload_within",
    "read_channel",
    "ridge_rms",
    "summarise",
]
