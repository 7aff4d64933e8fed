"""The contracts plugins implement: primitives, path segments, augmentations and detectors.

Built-in kinds implement exactly these and register through the same entry-point group as
third-party plugins (see :mod:`deepmorph_core.hookspecs`). This module imports no torch, so
that loading plugins stays cheap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from lxml import etree
    from torch import Tensor

    from deepmorph_core.outline import Frame, Outline, OutlineBuilder
    from deepmorph_core.svg.reader import ElementReader


@dataclass(frozen=True)
class ElementMorph:
    """An element- or group-level morph, for writing back: shift, uniform scale and rotation
    about ``centre`` (all in the element's own user units; degrees).
    """

    centre: tuple[float, float]
    shift: tuple[float, float] = (0.0, 0.0)
    scale: float = 1.0
    rotate: float = 0.0

    def matrix(self) -> np.ndarray:
        """The 3x3 matrix ``T(centre + shift) R S T(-centre)``."""
        cx, cy = self.centre
        a = math.radians(self.rotate)  # Python's math: numpy's scalar functions cost ten times more
        c, s = math.cos(a) * self.scale, math.sin(a) * self.scale
        tx = cx + self.shift[0] - (c * cx - s * cy)
        ty = cy + self.shift[1] - (s * cx + c * cy)
        return np.array([[c, -s, tx], [s, c, ty], [0.0, 0.0, 1.0]])

    @property
    def is_identity(self) -> bool:
        return self.shift == (0.0, 0.0) and self.scale == 1.0 and self.rotate == 0.0


@runtime_checkable
class Primitive(Protocol):
    """One drawable SVG element that DeepMorph can morph.

    Class attributes:
        kind: unique registry key, e.g. ``"circle"``.
        tags: SVG element names (local names) this kind reads.
        priority: when several kinds read one tag, higher priority is asked first; a kind
            declines an element by returning ``None`` from :meth:`from_element`.
        morphable: one line for ``list-primitives`` saying what may move.

    Instance attributes, set by the drawing parser from the element's style:
        evenodd: the fill rule is ``evenodd`` (the rasterizer's inside test).
        filled: the element paints a fill (an outline may then leave out its rings).
    """

    kind: ClassVar[str]
    tags: ClassVar[tuple[str, ...]]
    priority: ClassVar[int]
    morphable: ClassVar[str]
    evenodd: bool
    filled: bool

    @classmethod
    def from_element(cls, element: etree._Element, reader: ElementReader) -> Primitive | None:
        """Read the element's geometry (local user units), or return ``None`` to decline it.

        Raise :class:`~deepmorph_core.errors.SvgError` (via ``reader.error``) on bad values.
        """
        ...

    def control_points(self) -> Tensor:
        """``(n, 2)`` float64 control points in local user units: what per-point moves act on."""
        ...

    def outline(self, frame: Frame) -> Outline:
        """What the element draws, in pixels, for a batch of morphed control points: the only
        geometry the rasterizer asks a primitive for. Distances, caps, fills, culling,
        paints and compositing are the core's, from this outline."""
        ...

    def write(self, element: etree._Element, points: np.ndarray, morph: ElementMorph) -> None:
        """Write morphed geometry back into ``element``.

        Args:
            element: the element this primitive was read from (in the output tree).
            points: ``(n, 2)`` control points after per-point moves (before ``morph``).
            morph: the element-level morph to bake in (about the element's centre).
        """
        ...


@runtime_checkable
class PathSegment(Protocol):
    """One kind of ``<path>`` segment (e.g. arcs, cubic Béziers), registered like a primitive.

    Class attributes:
        kind: registry key, e.g. ``"cubic-bezier"``.
        commands: the path command letters it reads, e.g. ``"CcSs"``.
        svgpath_types: the ``svg.path`` segment classes it converts.
        morphable: one line for ``list-primitives``.
    """

    kind: ClassVar[str]
    commands: ClassVar[str]
    svgpath_types: ClassVar[tuple[type, ...]]
    morphable: ClassVar[str]

    @classmethod
    def from_svgpath(cls, segment: Any, reader: ElementReader) -> tuple[PathSegment, list[complex]]:
        """Convert a parsed ``svg.path`` segment.

        Returns:
            The segment object and the control points it adds after its start point
            (the last one is its end point), as complex numbers ``x + yj``.
        """
        ...

    def add_pieces(self, builder: OutlineBuilder, frame: Frame, points: Tensor, caps: tuple[int, int]) -> None:
        """Add this segment to ``builder``.

        Args:
            builder: the path's outline builder.
            frame: the path's frame (use ``frame.to_pixels`` for points, ``frame.affine`` for shape).
            points: ``(B, k + 1, 2)`` local points: the start point then the points it added.
            caps: cap codes for its start and end (round unless it ends an open subpath).
        """
        ...

    def flatten(self, frame: Frame, points: Tensor) -> Tensor:
        """``(B, m, 2)`` pixel points along the segment, excluding its start (for fill rings)."""
        ...

    def to_d(self, points: np.ndarray, morph: ElementMorph) -> str:
        """Path data for the segment (absolute commands), given its ``(k + 1, 2)`` local points
        already mapped through ``morph``; ``morph`` is passed for shape parameters (arc radii)."""
        ...


#: Pipeline order of the capture corruptions' stages (:mod:`deepmorph_core.corruption`); an
#: augmentation without a ``stage`` (or with an unknown one) runs as ``"custom"``. ``"colour"``
#: steps act on RGB images (ink, paper, white balance and JPEG's chroma loss change colours
#: only) and only when the images are RGB; every later stage acts on their luminance.
STAGES = ("colour", "geometry", "optics", "lighting", "intensity", "noise", "impulse", "custom", "compression")


@runtime_checkable
class Augmentation(Protocol):
    """A differentiable capture corruption applied between rasterizer and decoder.

    Class attributes:
        name: registry key used in configs, e.g. ``"gaussian_noise"``.
        stage: where in the physical order it runs (one of :data:`STAGES`; optional).

    Constructed with its parameters as keywords plus ``p``, the probability per sample. A
    geometric corruption may also define ``draw_matrices(images, generator)`` returning the
    chosen samples ``(B,)`` and their ``(B, 3, 3)`` pixel-space warps: the pipeline then fuses
    consecutive geometric steps into one resampling.
    """

    name: ClassVar[str]

    def __call__(self, images: Tensor, generator: Any | None = None) -> Tensor:
        """Corrupt ``(B, 1, H, W)`` images in ``[0, 1]`` (``(B, 3, H, W)`` RGB for a ``"colour"``
        stage step); differentiable w.r.t. ``images``."""
        ...


@dataclass(frozen=True, eq=False)
class Candidate:
    """Where a drawing may be in a photo: what a detector proposes, before alignment checks it.

    Attributes:
        corners: ``(4, 2)`` image pixels of the drawing's frame (its viewBox), in the order
            top-left, top-right, bottom-right, bottom-left as far as the proposer can tell
            (alignment also tries the other cyclic orders).
        score: the proposer's confidence in ``[0, 1]``.
        bbox: ``(x0, y0, x1, y1)`` pixel box around ``corners``, clipped to the image.
        homography: ``(3, 3)`` SVG units -> pixels, when the proposer already fixes the
            drawing's frame exactly (the whole image framed by its ink); ``None`` otherwise.
        source: what proposed it (``"detector"``, ``"whole-frame"``, a detector's name ...).
        sized: the outline's size comes from the print's own ink (the universal detector's):
            alignment tries its other corner orders and starts from the print's ink, not other
            turns or sizes of the outline.
        blind: the proposer does not know the drawing: it proposes every printed drawing (the
            universal detector). Each other drawing it proposes is one more chance at a CRC
            collision, so its readings always take the per-bit check, and one whose payload is
            not read is never reported.
    """

    corners: np.ndarray
    score: float
    bbox: tuple[int, int, int, int]
    homography: np.ndarray | None = None
    source: str = "detector"
    sized: bool = False
    blind: bool = False


@runtime_checkable
class Detector(Protocol):
    """Finds where instances of a trained drawing may be in a photo.

    Class attributes:
        name: registry key, e.g. ``"centrenet"``.
    """

    name: ClassVar[str]

    @classmethod
    def from_model(cls, model: Any) -> Detector | None:
        """This detector for a model (:class:`~deepmorph_core.model.DeepMorphModel`), from
        the weights its bundle stores; ``None`` when the bundle holds none for it."""
        ...

    def detect(self, image: np.ndarray) -> list[Candidate]:
        """Candidates for an ``(H, W)`` float32 gray image in ``[0, 1]``, best first; an empty
        list when there is none."""
        ...
