"""How large a print is in a photo, and how far its variables move there: the pixels a user
plans a print with.

A camera sees a print ``print_mm`` wide, held square to it at ``distance_cm``, across
``frame_px * print_mm / (2 * distance * tan(fov / 2))`` pixels (a pinhole camera). The
defaults are a phone filming 1080p: the frame's long side, :data:`PHONE_FRAME_PX` pixels, spans
:data:`PHONE_FOV_DEG` degrees, so a 50 mm print at 30 cm spans about 250 px and at 20 cm about
375 px. A variable carries its bit by moving the drawing's outline; how far its control points
travel across its range, in the photo's pixels, is what blur, noise and the decoder's frame
have to resolve (:func:`movement`, :func:`plan`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from deepmorph_core.capacity import CapacityReport, payload_for_width
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.morphable import MorphableDrawing

#: The long side of a 1080p phone frame, in pixels.
PHONE_FRAME_PX = 1920
#: A phone's main camera across that side, in degrees (65-75 is common; 65 is the narrower).
PHONE_FOV_DEG = 65.0
#: The print widths in photo pixels a plan always shows.
PLAN_PIXELS = (96, 150, 200, 300)
#: A move shorter than this many photo pixels is under the capture's blur at every severity.
SUB_PIXEL = 1.0
#: What a plan's predicted payload means for prints of other sizes (``capacity`` and the studio).
READING_NOTE = (
    "a model trained the default way reads every print at least 96 px wide in its decoder's 96-px frame; one "
    "trained with `train --pixels 200` reads prints 200 px wide or more at their own resolution and carries "
    "the payload the table gives there"
)


def pixels_across(
    print_mm: float, distance_cm: float, frame_px: int = PHONE_FRAME_PX, fov_deg: float = PHONE_FOV_DEG
) -> float:
    """A print's width in photo pixels, held square to a pinhole camera at ``distance_cm``.

    Raises:
        DeepMorphError: a size or distance that is not positive, or a field of view outside
            1-179 degrees.
    """
    if not (print_mm > 0 and distance_cm > 0 and frame_px > 0):
        raise DeepMorphError(
            f"print size, distance and frame width must be positive (got {print_mm} mm, {distance_cm} cm, "
            f"{frame_px} px)"
        )
    if not 1.0 <= fov_deg <= 179.0:
        raise DeepMorphError(f"field of view must be 1-179 degrees, got {fov_deg}")
    seen_mm = 2.0 * distance_cm * 10.0 * math.tan(math.radians(fov_deg) / 2.0)
    return frame_px * print_mm / seen_mm


def farthest_cm(
    print_mm: float, needs_px: float, frame_px: int = PHONE_FRAME_PX, fov_deg: float = PHONE_FOV_DEG
) -> float:
    """The distance in cm at which a ``print_mm`` print spans ``needs_px`` photo pixels: the
    farthest a camera may be for the print to read (:func:`pixels_across` solved for the distance).

    Raises:
        DeepMorphError: as :func:`pixels_across`, or ``needs_px`` not positive.
    """
    if not needs_px > 0:
        raise DeepMorphError(f"the pixels a print needs must be positive (got {needs_px})")
    return pixels_across(print_mm, 1.0, frame_px, fov_deg) / needs_px


@dataclass(frozen=True)
class Legibility:
    """Whether a print is wide enough in a photo for a model to read it.

    Attributes:
        pixels: the print's width in the photo.
        needs_px: the narrowest print the model reads: its decoder's frame (a narrower one
            loses the detail its bits are in, and ``decode`` calls it too small).
        farthest_cm: with a camera and a print size, the farthest distance at which the print
            still spans ``needs_px``; ``None`` when only pixels were given.
    """

    pixels: float
    needs_px: float
    farthest_cm: float | None = None

    @property
    def reads(self) -> bool:
        """Whether the print is at least :attr:`needs_px` wide."""
        return self.pixels >= self.needs_px

    def sentence(self) -> str:
        """The verdict in a user's words."""
        where = ""
        if self.farthest_cm is not None:
            reach = f"{self.farthest_cm:.0f} cm" if self.farthest_cm < 100 else f"{self.farthest_cm / 100:.1f} m"
            where = f"; it reads up to {reach} away" if self.reads else f"; hold the camera within {reach}"
        if self.reads:
            return f"wide enough to read: {self.pixels:.0f} px across, {self.needs_px:.0f} needed{where}"
        return f"too small to read: {self.pixels:.0f} px across, needs {self.needs_px:.0f}{where}, or print it wider"

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "reads": self.reads}


def legibility(
    pixels: float,
    needs_px: float,
    print_mm: float | None = None,
    frame_px: int = PHONE_FRAME_PX,
    fov_deg: float = PHONE_FOV_DEG,
) -> Legibility:
    """The :class:`Legibility` of a print ``pixels`` wide in a photo, for a model that needs
    ``needs_px``; with ``print_mm``, also how far away the camera may be."""
    far = farthest_cm(print_mm, needs_px, frame_px, fov_deg) if print_mm is not None else None
    return Legibility(float(pixels), float(needs_px), far)


def movement(drawing: MorphableDrawing) -> np.ndarray:
    """``(N_v,)`` how far each variable moves the drawing: the largest distance any control
    point travels as the variable sweeps its whole range (every other one neutral), as a share
    of the drawing's width. Times a print's width in pixels, its travel in those pixels."""
    space = drawing.space
    n = space.n_variables
    if n == 0:
        return np.zeros(0)
    width = 1000
    neutral = space.neutral_unit(1)[0]
    unit = neutral.repeat(2 * n, 1).double()
    rows = torch.arange(n)
    unit[2 * rows, rows] = 0.0
    unit[2 * rows + 1, rows] = 1.0
    with torch.no_grad():
        frames = space.frames(space.values_from_unit(unit), width)
        travel = torch.zeros(n, dtype=torch.float64)
        for frame in frames:
            points = frame.to_pixels(frame.local)  # (2n, k, 2)
            step = (points[1::2] - points[0::2]).norm(dim=-1).amax(-1)
            travel = torch.maximum(travel, step)
    return travel.numpy() / width


@dataclass(frozen=True)
class SizeRow:
    """What one print width gives the variables a reader sees.

    Attributes:
        pixels: the print's width in the photo.
        median_move: the median visible variable's travel across its range, in those pixels.
        smallest_move: the least-moving visible variable's travel.
        sub_pixel: visible variables that travel less than :data:`SUB_PIXEL` pixel.
        payload_bits: the payload predicted to read at this width
            (:func:`~deepmorph_core.capacity.payload_for_width`); ``None``: too small to read,
            or no prediction asked for.
        train_pixels: the ``train --pixels`` of the model that carries it (``None``: the
            default training).
        measuring: its payload waits for the drawing's channel, which is being measured
            (:func:`~deepmorph_core.capacity.with_channel`; the studio measures it in the background).
    """

    pixels: float
    median_move: float
    smallest_move: float
    sub_pixel: int
    payload_bits: int | None = None
    train_pixels: int | None = None
    measuring: bool = False

    @property
    def payload_text(self) -> str:
        """The payload cell of ``capacity``'s table (and the studio's)."""
        if self.measuring:
            return f"measuring ... (--pixels {self.train_pixels})"
        if self.payload_bits is None:
            return "too small"
        how = "" if self.train_pixels is None else f" (--pixels {self.train_pixels})"
        return f"{self.payload_bits}{how}"


def plan(
    drawing: MorphableDrawing,
    visible: np.ndarray | list[bool],
    sizes: list[float],
    report: CapacityReport | None = None,
    needs_px: float = 96,
    crc_bits: int | None = None,
) -> list[SizeRow]:
    """Each print width of ``sizes`` (photo pixels) with the travel of the ``visible``
    variables (a ``(N_v,)`` bool) there; with ``report`` (the drawing's
    :func:`~deepmorph_core.capacity.predict`), also the payload each width carries, for a model
    whose default frame is ``needs_px`` wide and codes with ``crc_bits``. From
    :data:`~deepmorph_core.capacity.PIXELS_MEASURED` px up that needs the report's channel; a
    report without it gives those rows as still measuring."""
    share = movement(drawing)[np.asarray(visible, dtype=bool)]
    rows = []
    for px in sizes:
        moves = share * px
        payload, train_px = (None, None) if report is None else payload_for_width(report, px, needs_px, crc_bits)
        measuring = payload is None and train_px is not None  # a --pixels model's, its channel not measured yet
        rows.append(
            SizeRow(
                float(px),
                round(float(np.median(moves)), 2) if moves.size else 0.0,
                round(float(moves.min()), 2) if moves.size else 0.0,
                int((moves < SUB_PIXEL).sum()),
                payload,
                train_px,
                measuring,
            )
        )
    return rows


def plan_sizes(pixels: float | None) -> list[float]:
    """:data:`PLAN_PIXELS`, with ``pixels`` among them in order when given."""
    sizes = [float(p) for p in PLAN_PIXELS]
    if pixels is not None and all(abs(pixels - s) > 0.5 for s in sizes):
        sizes.append(float(pixels))
    return sorted(sizes)


def rows_to_json(rows: list[SizeRow]) -> list[dict[str, Any]]:
    """The rows as ``capacity --json`` gives them (``print_size.sizes``)."""
    return [{**asdict(row), "payload_text": row.payload_text} for row in rows]
