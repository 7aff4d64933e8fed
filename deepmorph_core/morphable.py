"""A drawing with its morph space: the object pipelines are composed from.

Example::

    from deepmorph_core.morphable import MorphableDrawing

    drawing = MorphableDrawing.load("ghost.svg", move=0.5)
    unit = drawing.random_unit(4, seed=3)                 # (4, N_v) in [0, 1]
    values = drawing.values_from_unit(unit)               # mapped onto the bounds (T)
    ink = drawing.render_soft(values, width=128)          # (4, 1, H, W), differentiable
    svg_text = drawing.to_svg(values[0])                  # a morphed SVG document
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from lxml import etree
from pydantic import ValidationError
from torch import Tensor

from deepmorph_core.bounds import BoundSpec, format_validation_error
from deepmorph_core.drawing import Drawing, load_drawing
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.framing import render_moments
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, stretch_ink
from deepmorph_core.morph import MorphSpace, Variable
from deepmorph_core.plugins import Registry, default_registry
from deepmorph_core.raster import RasterSettings, SoftRasterizer
from deepmorph_core.reading_channel import choose_channel
from deepmorph_core.render import render_svg, render_svg_ink, render_svg_rgb
from deepmorph_core.svg.policy import GEOMETRY
from deepmorph_core.svg.reader import GEOMETRY_VERSION

# a variable changing the picture by at most this share of the median variable is invisible: it
# lies in the wide gap between variables a renderer does not show and the weakest ones it does
INVISIBLE = 0.1


def bound_defaults(
    move: float | None = None,
    shift: tuple[float, float] | float | None = None,
    scale: tuple[float, float] | None = None,
    rotate: tuple[float, float] | None = None,
) -> BoundSpec:
    """Default bounds for primitives that have none (validated like ``dm:`` attributes)."""
    try:
        return BoundSpec(move=move, shift=shift, scale=scale, rotate=rotate)
    except ValidationError as exc:
        raise DeepMorphError(f"default bounds: {format_validation_error(exc)}") from None


@dataclass
class MorphableDrawing:
    """A drawing with its morph space: the object pipelines are composed from.

    Attributes:
        drawing: the parsed drawing.
        space: its variables and bounds.
        channel: the gray its renders are read in (luminance unless a model chose another:
            :mod:`deepmorph_core.reading_channel`); the SVG keeps the artist's colours.
    """

    drawing: Drawing
    space: MorphSpace
    channel: Channel = LUMA_WEIGHTS

    @classmethod
    def load(
        cls,
        source: str | Path | bytes,
        *,
        move: float | None = None,
        shift: tuple[float, float] | float | None = None,
        scale: tuple[float, float] | None = None,
        rotate: tuple[float, float] | None = None,
        registry: Registry | None = None,
        label: str | None = None,
        drop_unsupported: bool = False,
        geometry: int = GEOMETRY_VERSION,
    ) -> MorphableDrawing:
        """Parse an SVG file or document; keyword bounds apply where the SVG says nothing.

        ``label`` names a bytes source in error messages (a path names itself);
        ``drop_unsupported`` leaves out what DeepMorph cannot model instead of refusing it
        (:func:`~deepmorph_core.drawing.load_drawing`; what was left out is in ``drawing.dropped``);
        ``geometry`` is the morph geometry version (the newest unless a bundle names an older one).
        """
        defaults = bound_defaults(move, shift, scale, rotate)
        drawing = load_drawing(
            source,
            defaults=defaults,
            registry=registry or default_registry(),
            label=label,
            drop_unsupported=drop_unsupported,
            geometry=geometry,
        )
        return cls(drawing, MorphSpace(drawing))

    @property
    def n_variables(self) -> int:
        """``N_v``."""
        return self.space.n_variables

    @property
    def variables(self) -> list[Variable]:
        """Every variable with its owner, role and bounds."""
        return self.space.variables

    def random_unit(self, batch: int = 1, seed: int | None = None) -> Tensor:
        """Uniform random encoder outputs ``(batch, N_v)`` in ``[0, 1]`` (seeded if asked)."""
        gen = torch.Generator().manual_seed(seed) if seed is not None else None
        return torch.rand(batch, self.n_variables, generator=gen)

    def values_from_unit(self, unit: Tensor) -> Tensor:
        """Map ``(B, N_v)`` in ``[0, 1]`` onto the bounds (differentiable)."""
        return self.space.values_from_unit(unit)

    def neutral_values(self, batch: int = 1) -> Tensor:
        """Values of the unmorphed drawing ``(batch, N_v)``."""
        return self.space.values_from_unit(self.space.neutral_unit(batch))

    def neutral_moments(self, width: int) -> Tensor:
        """Ink moments ``(4,)`` (cx, cy, sx, sy) of the unmorphed drawing's resvg render at
        ``width`` pixels: where framing puts every morph's ink."""
        return render_moments(stretch_ink(self.render_real(self.neutral_values(), width), self.ink_level))[0]

    def rasterizer(self, width: int, **settings: Any) -> SoftRasterizer:
        """A soft rasterizer module for this drawing (see :class:`RasterSettings`)."""
        return SoftRasterizer(self.space, RasterSettings(width=width, **settings), channel=self.channel)

    def render_soft(self, values: Tensor, width: int = 96, **settings: Any) -> Tensor:
        """Soft-rasterize ``(B, N_v)`` values to ``(B, 1, H, W)`` ink (differentiable)."""
        return self.rasterizer(width, **settings)(values)

    def to_svg(self, values: Tensor) -> str:
        """One morph ``(N_v,)`` written back as an SVG document."""
        return self.space.write_svg(values)

    def to_svgs(self, values: Tensor) -> list[str]:
        """:meth:`to_svg` of each of ``(B, N_v)`` morphs, written together (quicker)."""
        return self.space.write_svgs(values)

    @property
    def ink_level(self) -> float:
        """The luminance (or :attr:`channel`) of the darkest paint as printed on white (0 for black ink): what a
        photo's contrast stretch maps to black (:func:`~deepmorph_core.luminance.stretch_ink`)."""
        paints = self.drawing.palette
        if all(p.black_or_white for p in paints):
            return 0.0
        return max(0.0, min(1.0 - p.alpha * (1.0 - p.in_channel(self.channel)) for p in paints))

    def read_in(self, channel: Channel | None = None) -> MorphableDrawing:
        """Set :attr:`channel` to ``channel``, or (``None``) to the one a new model of this
        drawing reads (:func:`~deepmorph_core.reading_channel.choose_channel`; luminance for
        black and white); returns the drawing."""
        if channel is not None:
            self.channel = tuple(channel)
        else:
            self.channel = choose_channel(self.to_svg(self.neutral_values()[0]))[1] if self.colour else LUMA_WEIGHTS
        return self

    @property
    def colour(self) -> bool:
        """Whether any paint is other than opaque black or white: renders then come in colour."""
        return not self.drawing.black_and_white

    def render_real(self, values: Tensor, width: int, rgb: bool = False) -> Tensor:
        """resvg renders ``(B, 1, H, W)`` luminance (paper white = 1), or ``(B, 3, H, W)``
        colour with ``rgb``, of ``(B, N_v)`` values at ``width`` pixels, on the CPU."""
        h, w = self.drawing.pixel_size(width)
        out = np.empty((values.shape[0], 3 if rgb else 1, h, w), dtype=np.float32)
        for i, svg in enumerate(self.to_svgs(values.detach().cpu())):
            if rgb:
                out[i] = render_svg_rgb(svg, w).transpose(2, 0, 1)
            else:
                out[i, 0] = render_svg(svg, w, self.channel)
        return torch.from_numpy(out)

    def render_hard(self, values: Tensor | None, width: int = 96) -> np.ndarray:
        """Render one morph (or the base drawing, for ``None``) with the real renderer, as ink."""
        svg = self.to_svg(values) if values is not None else self.to_svg(self.neutral_values()[0])
        return render_svg_ink(svg, width, self.channel)

    def effects(self, raster: SoftRasterizer | None = None, chunk: int = 64) -> Tensor:
        """What each variable does to the picture, as a Gram matrix ``(N_v, N_v)``.

        Each variable sweeps its whole range with every other variable neutral (soft raster,
        ``raster`` or one at 96 px); entry ``(i, k)`` is the dot product of the pixel changes of
        ``i`` and ``k``. The diagonal is how visible a variable is; the correlations show
        variables that look alike (:func:`~deepmorph_core.networks.twin_groups`).
        """
        raster = raster or self.rasterizer(96)
        space = self.space
        neutral = space.neutral_unit(1)[0]
        changes = []
        with torch.no_grad():
            for start in range(0, space.n_variables, chunk):
                idx = torch.arange(start, min(start + chunk, space.n_variables))
                unit = neutral.repeat(2 * len(idx), 1)
                rows = torch.arange(len(idx))
                unit[2 * rows, idx] = 0.0
                unit[2 * rows + 1, idx] = 1.0
                images = raster(space.values_from_unit(unit))
                changes.append((images[1::2] - images[0::2]).flatten(1).double())
        change = torch.cat(changes)
        return change @ change.T

    def visibility(self, width: int = 96) -> np.ndarray:
        """``(N_v,)`` how much each variable changes the picture, relative to the median
        variable: the pixel change, squared and summed, between the two ends of its range (all
        others neutral), in renders by the real renderer at ``width``.

        Near 0 means a renderer does not show the variable: a point moving along a straight
        line through it, or under another stroke. Such a variable cannot carry a bit.
        """
        unit = self.space.neutral_unit(1)[0]
        energy = np.zeros(self.n_variables)
        for i in range(self.n_variables):
            ends = unit.repeat(2, 1)
            ends[0, i], ends[1, i] = 0.0, 1.0
            low, high = (self.render_hard(v, width) for v in self.values_from_unit(ends))
            energy[i] = float(((high - low) ** 2).sum())
        median = float(np.median(energy)) if self.n_variables else 0.0
        return energy / median if median > 0 else energy

    def contrast(self, width: int = 96) -> np.ndarray:
        """``(n_primitives,)`` how strongly each shape shows: the largest change of luminance
        (or of the channel the drawing is read in; ``[0, 1]``) that leaving the shape out makes
        to the unmorphed drawing's render at ``width``. Black on white is 1; a shape in a colour
        close to what lies under it is near 0, and its moves are as faint as its edges."""
        base = self.to_svg(self.neutral_values()[0])
        full = render_svg(base, width, self.channel)
        root = etree.fromstring(base.encode("utf-8"))
        shapes = [el for el in root.iter() if isinstance(el.tag, str) and etree.QName(el).localname in GEOMETRY]
        out = np.zeros(len(self.drawing.primitives))
        for k, element in enumerate(shapes[: len(out)]):
            element.set("display", "none")
            without = render_svg(etree.tostring(root, encoding="unicode"), width, self.channel)
            element.attrib.pop("display")
            out[k] = float(np.abs(full - without).max())
        return out

    def palette(self) -> list[dict[str, Any]]:
        """The paints the drawing lays down: ``paint`` (``#rrggbb``, with alpha as ``#rrggbbaa``,
        or ``url(#id) ~ mean``), its ``luminance`` and the ``shapes`` (indices) that use it."""
        return [
            {
                "paint": paint.describe(),
                "luminance": round(paint.luminance, 3),
                "alpha": round(paint.alpha, 3),
                "shapes": [prim.index for prim in self.drawing.primitives if paint in prim.style.palette],
            }
            for paint in self.drawing.palette
        ]

    def describe(self) -> dict[str, Any]:
        """A JSON-ready summary: primitives, variables, bounds, what is fixed or skipped."""
        per_prim: dict[int, list[Variable]] = {}
        per_group: dict[int, list[Variable]] = {}
        for v in self.space.variables:
            (per_prim if v.owner == "primitive" else per_group).setdefault(v.index, []).append(v)
        prims = []
        for p in self.drawing.primitives:
            vs = per_prim.get(p.index, [])
            prims.append(
                {
                    "index": p.index,
                    "kind": p.primitive.kind,
                    "line": p.line,
                    "control_points": int(p.primitive.control_points().shape[0]),
                    "variables": len(vs),
                    "fixed": p.fixed,
                    "bounds": p.bounds.model_dump(exclude_none=True),
                    "paints": [f"{mode}:{paint.describe()}" for mode, paint in p.style.paints],
                }
            )
        groups = [
            {
                "index": g.index,
                "line": g.line,
                "variables": len(per_group.get(g.index, [])),
                "bounds": g.bounds.model_dump(exclude_none=True),
            }
            for g in self.drawing.groups
        ]
        physical = lambda v: (v.lo, v.hi)  # noqa: E731
        return {
            "source": self.drawing.source,
            "viewbox": list(self.drawing.viewbox),
            "n_variables": self.n_variables,
            "primitives": prims,
            "groups": groups,
            "variables": [
                {
                    "owner": v.owner,
                    "index": v.index,
                    "role": v.role,
                    "point": v.point,
                    "lo": physical(v)[0],
                    "hi": physical(v)[1],
                    "line": v.line,
                }
                for v in self.space.variables
            ],
            "skipped": [{"line": line, "reason": why} for line, why in self.drawing.skipped],
            "palette": self.palette(),
        }
