"""Which gray a model reads a colour print in: luminance, or one of red, green and blue.

The networks, the alignment and the checks read one gray channel. Luminance suits most
drawings, but not one whose colours differ little in it: a yellow face (``#ffb02e``) on white
paper differs by 0.27 in luminance and by 0.82 in blue, and after the capture's duller inks,
white balance and lost saturation (the ``colour`` plugins, hard severity) still by 0.23 against
0.56 (medians of 200 draws). Such a drawing is read in that one channel: its moves then show
with twice the contrast or more. A single channel is noisier than luminance (luminance averages
three: its noise is about 0.67 of one channel's), hence the margin :data:`CHANNEL_GAIN`.
"""

from __future__ import annotations

import numpy as np

from deepmorph_core.luminance import LUMA_WEIGHTS, Channel
from deepmorph_core.render import render_svg_rgb

#: The single channels a model may read instead of luminance.
SINGLE_CHANNELS: dict[str, Channel] = {"red": (1.0, 0.0, 0.0), "green": (0.0, 1.0, 0.0), "blue": (0.0, 0.0, 1.0)}
#: Every channel a model may be read in, by name.
CHANNELS: dict[str, Channel] = {"luminance": LUMA_WEIGHTS, **SINGLE_CHANNELS}
#: A single channel is read only where the drawing's edges show at least this many times the
#: contrast they show in luminance: twice the noise ratio of one channel to luminance (1.5)
#: would be the break-even point of signal to noise; the rest is margin for cameras whose blue
#: is noisier still.
CHANNEL_GAIN = 2.0
#: the width the drawing is rendered at to weigh its edges
RENDER_WIDTH = 96
#: a pixel is on an edge where some channel changes by at least this much to its neighbours
EDGE_STEP = 0.05


def edge_contrast(rgb: np.ndarray, channel: Channel) -> float:
    """The mean change of ``channel``'s gray across the edges of an ``(H, W, 3)`` render: pixels
    where any of red, green and blue changes by :data:`EDGE_STEP` or more."""
    steps = [np.hypot(*np.gradient(rgb[..., i])) for i in range(3)]
    edges = np.max(steps, axis=0) >= EDGE_STEP
    if not edges.any():
        return 0.0
    gray = rgb @ np.asarray(channel, dtype=np.float32)
    return float(np.hypot(*np.gradient(gray))[edges].mean())


def choose_channel(svg_text: str) -> tuple[str, Channel]:
    """The channel a drawing is read in and its name: ``"luminance"``, or the single channel
    whose edge contrast (:func:`edge_contrast` of the unmorphed drawing) is at least
    :data:`CHANNEL_GAIN` times luminance's and the highest."""
    rgb = render_svg_rgb(svg_text, RENDER_WIDTH)
    luma = edge_contrast(rgb, LUMA_WEIGHTS)
    name, best = max(((n, edge_contrast(rgb, c)) for n, c in SINGLE_CHANNELS.items()), key=lambda nc: nc[1])
    if best >= CHANNEL_GAIN * luma and best > 0:
        return name, SINGLE_CHANNELS[name]
    return "luminance", LUMA_WEIGHTS


def channel_name(channel: Channel) -> str:
    """``"luminance"``, ``"red"``, ``"green"``, ``"blue"``, or the weights written out."""
    for name, weights in CHANNELS.items():
        if tuple(channel) == weights:
            return name
    return "rgb(" + ", ".join(f"{w:g}" for w in channel) + ")"


def channel_for(read_in: str) -> Channel | None:
    """The channel a ``--read-in`` choice names: ``None`` for ``"auto"`` (the drawing's
    :func:`choose_channel`), else :data:`CHANNELS`' entry."""
    return None if read_in == "auto" else CHANNELS[read_in]


__all__ = ["CHANNELS", "CHANNEL_GAIN", "EDGE_STEP", "RENDER_WIDTH", "SINGLE_CHANNELS", "channel_for", "channel_name",
           "choose_channel", "edge_contrast"]  # fmt: skip
