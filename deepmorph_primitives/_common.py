"""Small pieces shared by the built-in kinds."""

from __future__ import annotations

import torch
from torch import Tensor

from deepmorph_core.geometry import CAP_CODES, CAP_ROUND
from deepmorph_core.outline import Frame, OutlineBuilder
from deepmorph_core.svg.reader import ElementReader


def builder_for(frame: Frame) -> OutlineBuilder:
    """An empty outline builder matching the frame's batch, dtype and device."""
    return OutlineBuilder(frame.local.shape[0], frame.local.dtype, frame.local.device)


def cap_of(reader: ElementReader) -> int:
    """The cap code of the element being read (from its computed style)."""
    return CAP_CODES.get(reader.style.linecap, CAP_ROUND)


def add_polyline(builder: OutlineBuilder, px: Tensor, closed: bool, cap: int) -> None:
    """Line pieces through ``px`` ``(B, n, 2)``; open ends get ``cap``, joins are round."""
    n = px.shape[1]
    count = n if closed else n - 1
    for k in range(count):
        a, b = px[:, k], px[:, (k + 1) % n]
        start = cap if (not closed and k == 0) else CAP_ROUND
        end = cap if (not closed and k == count - 1) else CAP_ROUND
        builder.line(a, b, start, end)
    builder.ring(px)


def circle_linear(frame: Frame, rx: Tensor | float, ry: Tensor | float) -> Tensor:
    """``(B, 2, 2)`` map from the unit circle to the pixel-space ellipse of radii rx, ry."""
    diag = torch.zeros(2, 2, dtype=frame.local.dtype, device=frame.local.device)
    diag[0, 0], diag[1, 1] = rx, ry
    return frame.linear @ diag
