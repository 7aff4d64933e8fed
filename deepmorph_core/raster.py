"""The soft rasterizer: batched, differentiable, and culled to each primitive's bounding box.

Per the paper, each paint (a primitive's fill or stroke) is ``sigmoid(s * sdf)`` with ``sdf``
in pixels; black paints add, white paints subtract, and the sum is squashed with
``sigmoid(t * (x - 0.5))``. Runs of same-coloured paints are summed and a squash is applied
between runs of different colour, so that a white stroke over black strokes shows white
(bottom-up layering).

Colour drawings go beyond the paper, which drew black and white only: each run of one paint
is composited over what lies below it (``over``, bottom-up in paint order) with its colour and
alpha, its coverage squashed exactly as a black run's is, so a single black run draws the same
either way. Drawings whose every paint is opaque black or white keep the paper's blend, so the
models trained on them render as they were trained.

Three departures from a literal reading (benchmarked in ``bench/``):

* **Culling.** The paper names the rasterizer's memory as its bottleneck. A paint is evaluated
  only over the pixel rectangle its batch can reach (its outline's bounding box, padded by the
  stroke half-width and the sigmoid's reach). Strokes go further: every piece of every stroke in
  a run is paired with just the pixels within reach of it and evaluated in one vectorised pass
  (:mod:`deepmorph_core.flat`), and so are fills near their outlines, their pixels farther in
  taken as wholly inside. Beyond the reach ``sigmoid(s * sdf)`` is below ``3.4e-4``, so the
  result matches the dense reference to within ``2e-3`` (``2.5e-3`` with fills near their
  outlines, whose rounding inside the squash between runs can amplify). The colour reading
  panel's drawings in black and white (the five that show ink) rasterize 1.6-34 times as fast
  this way as with each fill over its whole box (``bench/bw_fills.py``).
* **Soft union within a run.** Same-coloured paints are combined as ``1 - prod(1 - c_i)``
  (accumulated additively as ``sum log(1 - c_i)``) instead of ``sum c_i``: where the soft edges
  of two strokes overlap, a plain sum reads as solid ink beyond both edges (visible bulges at
  every joint), the union does not. ``blend="sum"`` keeps the paper's sum.
* **Normalised squash.** ``sigmoid(t (x - 0.5))`` is rescaled so that 0 ink maps to exactly 0
  and 1 to exactly 1; otherwise blank paper would read as faint grey everywhere.

Output is *ink* in ``[0, 1]`` (1 = black; for colour, one minus the BT.601 luminance that the
photo chain reads); :func:`ink_to_image` gives paper-white images and
:meth:`SoftRasterizer.render_rgb` the colours.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from deepmorph_core.flat import flat_fill_sdf, flat_stroke_sdf
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel
from deepmorph_core.morph import MorphSpace
from deepmorph_core.outline import Frame, Outline, pixel_bbox, pixel_grid
from deepmorph_core.primitive import outline_paint_sdf
from deepmorph_core.svg.style import Paint

#: Reach of the sigmoid beyond which a pixel's contribution is treated as zero: sigmoid(-8) ~ 3e-4.
_SIGMOID_REACH = 8.0


@dataclass(frozen=True)
class RasterSettings:
    """Soft rasterizer settings.

    Attributes:
        width: raster width in pixels (height follows the viewBox aspect).
        sharpness: ``s``, per pixel. With ``t = 12``, ``s = 1.85`` minimises the mean
            difference of an edge to a real renderer's one-pixel box-filtered edge.
        squash: ``t``, the squash sharpness.
        cull: evaluate each paint only inside its padded bounding box.
        blend: ``"union"`` (soft union of same-coloured paints) or ``"sum"`` (the paper's).
        flat_fills: evaluate fills only near their outlines (:func:`~deepmorph_core.flat.flat_fill_sdf`)
            instead of over their whole box: the same picture to within the sigmoid's reach, and
            a large fill as cheap as its outline. ``None``: for colour drawings alone, as bundles
            written before black-and-white fills went flat render
            (:meth:`~deepmorph_core.model.DeepMorphModel.raster_settings`), so that their models
            render exactly as they were trained.
    """

    width: int = 96
    sharpness: float = 1.85
    squash: float = 12.0
    cull: bool = True
    blend: str = "union"
    flat_fills: bool | None = True


def normalised_squash(x: Tensor, t: float) -> Tensor:
    """``sigmoid(t (x - 0.5))`` rescaled so that 0 -> 0 and 1 -> 1, clamped to ``[0, 1]``."""
    lo = 1.0 / (1.0 + math.exp(t / 2))
    hi = 1.0 - lo
    return ((torch.sigmoid(t * (x - 0.5)) - lo) / (hi - lo)).clamp(0.0, 1.0)


def ink_to_image(ink: Tensor) -> Tensor:
    """Ink (1 = black) to image intensity (1 = white paper)."""
    return 1.0 - ink


class SoftRasterizer(nn.Module):
    """Renders a batch of morphs of one drawing.

    Args:
        space: the drawing's morph space.
        settings: raster settings.
        channel: the gray a colour drawing is rendered in (:mod:`deepmorph_core.reading_channel`).
    """

    def __init__(self, space: MorphSpace, settings: RasterSettings | None = None, channel: Channel = LUMA_WEIGHTS):
        super().__init__()
        self.space = space
        self.channel = channel
        self.settings = settings or RasterSettings()
        self.height, self.width = space.drawing.pixel_size(self.settings.width)
        self._runs = _paint_runs(space)
        self.black_and_white = space.drawing.black_and_white
        flat = self.settings.flat_fills
        self._flat_fills = (not self.black_and_white) if flat is None else flat

    def forward(self, values: Tensor) -> Tensor:
        """Render morph values.

        Args:
            values: ``(B, N_v)`` morph values (:meth:`MorphSpace.values_from_unit`).

        Returns:
            ``(B, 1, H, W)`` ink in ``[0, 1]``: for a colour drawing, one minus the luminance
            (BT.601; or the gray of :attr:`channel`) of its composited colours, what the photo
            chain reads from a photo.
        """
        if self.black_and_white:
            return self._squashed(values)
        return 1.0 - self._composited(values, [[paint.in_channel(self.channel)] for paint, _ in self._runs])

    def render_rgb(self, values: Tensor) -> Tensor:
        """Render morph values in colour: ``(B, 3, H, W)`` sRGB on white paper, in ``[0, 1]``."""
        if self.black_and_white:
            return (1.0 - self._squashed(values)).expand(-1, 3, -1, -1)
        return self._composited(values, [list(paint.rgb) for paint, _ in self._runs])

    def _squashed(self, values: Tensor) -> Tensor:
        """The paper's black-and-white blend: black runs add ink, white runs take it away, with
        the normalised squash between runs and at the end."""
        acc: Tensor | None = None
        for (paint, _), cover in zip(self._runs, self._run_covers(values)):
            contribution = paint.ink_sign * cover
            acc = contribution if acc is None else normalised_squash(acc, self.settings.squash) + contribution
        if acc is None:
            B, H, W = values.shape[0], self.height, self.width
            return torch.zeros(B, 1, H, W, dtype=values.dtype, device=values.device)
        return normalised_squash(acc, self.settings.squash)[:, None]

    def _composited(self, values: Tensor, colours: list[list[float]]) -> Tensor:
        """Colour runs composited bottom-up over white paper (``over``): each run's coverage,
        squashed as a black run is, times its paint's alpha, lays its colour down.

        Args:
            colours: per run, its colour in the output's ``C`` channels.

        Returns:
            ``(B, C, H, W)``.
        """
        B, H, W = values.shape[0], self.height, self.width
        image = torch.ones(B, len(colours[0]) if colours else 1, H, W, dtype=values.dtype, device=values.device)
        for (paint, _), colour, cover in zip(self._runs, colours, self._run_covers(values)):
            alpha = (normalised_squash(cover, self.settings.squash) * paint.alpha)[:, None]
            tint = torch.tensor(colour, dtype=values.dtype, device=values.device)[None, :, None, None]
            # image (1 - alpha) + tint alpha as one fused op: the broadcast products took 3.1 ms a
            # run for 43 colour renders at 96 px on a CPU thread, lerp 0.4 (equal to 6e-8)
            image = torch.lerp(image, tint.expand_as(image), alpha)
        return image

    def _run_covers(self, values: Tensor) -> Iterator[Tensor]:
        """Each paint run's coverage ``(B, H, W)`` in ``[0, 1]``, bottom run first."""
        st = self.settings
        B, dtype, device = values.shape[0], values.dtype, values.device
        H, W = self.height, self.width
        frames = self.space.frames(values, W)
        outlines: dict[int, object] = {}
        if st.blend not in ("union", "sum"):
            raise ValueError(f"blend must be 'union' or 'sum', got {st.blend!r}")
        union = st.blend == "union"
        reach = _SIGMOID_REACH / st.sharpness
        for _, paints in self._runs:
            # Covers are gathered with the canvas positions they land on and added with a single
            # index_add: in-place slice additions would make autograd copy the whole canvas once
            # per paint in the backward pass.
            positions: list[Tensor] = []
            sdfs: list[Tensor] = []
            strokes: list[tuple[Outline, Tensor]] = []
            fills: list[tuple[Outline, bool]] = []
            for index, mode in paints:
                prim = self.space.drawing.primitives[index]
                frame = frames[index]
                if index not in outlines:
                    outlines[index] = prim.primitive.outline(frame)
                outline = outlines[index]
                half_width = stroke_half_width(frame, prim.style.stroke_width, mode)
                if st.cull and mode == "stroke":
                    strokes.append((outline, half_width))  # evaluated together below
                    continue
                if st.cull and self._flat_fills:
                    fills.append((outline, prim.primitive.evenodd))
                    continue
                if st.cull:
                    box = pixel_bbox(outline, float(half_width.detach().max()) + reach)
                    x0 = max(0, int(math.floor(float(box[0]))))
                    y0 = max(0, int(math.floor(float(box[1]))))
                    x1 = min(W, int(math.ceil(float(box[2]))) + 1)
                    y1 = min(H, int(math.ceil(float(box[3]))) + 1)
                    if x1 <= x0 or y1 <= y0:
                        continue
                else:
                    x0, y0, x1, y1 = 0, 0, W, H
                grid = pixel_grid(x0, y0, x1, y1, dtype, device)
                sdfs.append(outline_paint_sdf(outline, grid, mode, half_width, prim.primitive.evenodd).t())
                rows = torch.arange(y0, y1, device=device)[:, None] * W
                positions.append((rows + torch.arange(x0, x1, device=device)[None]).reshape(-1))
            for flat in (flat_stroke_sdf(strokes, H, W, reach) if strokes else None,
                         flat_fill_sdf(fills, H, W, reach) if fills else None):  # fmt: skip
                if flat is not None:
                    positions.append(flat[0])
                    sdfs.append(flat[1])
            # pixels-first (H*W, B): index_add then moves contiguous rows of B values
            canvas = torch.zeros(H * W, B, dtype=dtype, device=device)
            if sdfs:
                sdf = torch.cat(sdfs, 0)
                # union: log(1 - sigmoid(z)) = logsigmoid(-z), summed; sum: the paper's sigmoids
                cover = (
                    torch.nn.functional.logsigmoid(-st.sharpness * sdf) if union else torch.sigmoid(st.sharpness * sdf)
                )
                canvas = canvas.index_add(0, torch.cat(positions), cover)
            canvas = canvas.t().reshape(B, H, W)
            yield -torch.expm1(canvas) if union else canvas


def stroke_half_width(frame: Frame, stroke_width: float, mode: str) -> Tensor:
    """``(B,)`` half the stroke width in pixels (zero for fills)."""
    scale = frame.stroke_scale if frame.stroke_scale is not None else frame.scale
    return scale * (stroke_width / 2) if mode == "stroke" else torch.zeros_like(scale)


def _paint_runs(space: MorphSpace) -> list[tuple[Paint, list[tuple[int, str]]]]:
    """Group paints in paint order into runs of one paint: ``[(paint, [(prim, mode)])]``."""
    runs: list[tuple[Paint, list[tuple[int, str]]]] = []
    for prim in space.drawing.primitives:
        for mode, colour in prim.style.paints:
            if runs and runs[-1][0] == colour:
                runs[-1][1].append((prim.index, mode))
            else:
                runs.append((colour, [(prim.index, mode)]))
    return runs
