"""Checks and random draws shared by every augmentation.

Parameters are drawn on the generator's device (or the images' device when no generator is
given) in float32, then moved to the images' device and dtype: the same seed gives the same
parameters whatever the images' dtype, and a CPU generator can drive augmentations on a GPU.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor


def probability(p: float) -> float:
    """``p`` as a float in ``[0, 1]``, or ``ValueError``."""
    p = float(p)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"p must lie in [0, 1], got {p:g}")
    return p


def value_range(
    value: float | Sequence[float],
    name: str,
    *,
    symmetric: bool = False,
    low: float = float("-inf"),
    high: float = float("inf"),
) -> tuple[float, float]:
    """Read a sampling range: a pair ``(lo, hi)``, or one number ``m`` meaning ``(-m, m)`` when
    ``symmetric`` else ``(0, m)``.

    Raises:
        ValueError: not one or two numbers, ``lo > hi``, or outside ``[low, high]``; the message
            names the parameter.
    """
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        m = float(value)
        lo, hi = (-abs(m), abs(m)) if symmetric else (0.0, m)
    else:
        try:
            lo, hi = (float(v) for v in value)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected a number or a pair [lo, hi], got {value!r}") from None
    if lo > hi:
        raise ValueError(f"{name}: lower bound {lo:g} is above upper bound {hi:g}")
    if lo < low or hi > high:
        raise ValueError(f"{name}: bounds must lie in [{low:g}, {high:g}], got [{lo:g}, {hi:g}]")
    return lo, hi


class Sampler:
    """Per-sample random draws for one batch of images.

    Args:
        images: the batch the draws are for (their device and dtype are the draws').
        generator: an optional ``torch.Generator``; the same seed replays the same draws.
    """

    def __init__(self, images: Tensor, generator: torch.Generator | None = None):
        self.generator = generator
        self.source = generator.device if generator is not None else images.device
        self.device, self.dtype = images.device, images.dtype

    def _out(self, t: Tensor) -> Tensor:
        return t.to(device=self.device, dtype=self.dtype)

    def rand(self, *shape: int) -> Tensor:
        """Uniform ``[0, 1)`` draws of ``shape``, on the generator's device in float32."""
        return torch.rand(shape, generator=self.generator, device=self.source)

    def unit(self, *shape: int) -> Tensor:
        """Uniform ``[0, 1)`` draws of ``shape``, on the images' device and dtype."""
        return self._out(self.rand(*shape))

    def uniform(self, bounds: tuple[float, float], *shape: int) -> Tensor:
        """Uniform draws in ``[lo, hi)`` of ``shape``, on the images' device and dtype."""
        lo, hi = bounds
        return self._out(lo + (hi - lo) * self.rand(*shape))

    def normal(self, *shape: int) -> Tensor:
        """Standard normal draws of ``shape``, on the images' device and dtype."""
        return self._out(torch.randn(shape, generator=self.generator, device=self.source))

    def chance(self, p: float, n: int) -> Tensor:
        """``(n,)`` bool: which samples an augmentation of probability ``p`` applies to."""
        return (self.rand(n) < p).to(self.device)
