"""How often the photo chain finds a drawing's prints, simulated before any model is trained.

A print is read only where it is found: the universal detector proposes a square around its ink
and the unmorphed drawing aligns from there, or, where nothing reads, the whole photo framed by
its ink aligns. Most drawings are found in nearly every photo, not all: ``bench/README.md``,
*Finding colour prints*, measures 20 colour drawings nobody chose. No single number of the
drawing (its gray's spread, its edges' contrast, its darkest ink) told the ones found least
apart, so it is simulated: :data:`SHOTS` hard close-ups, photographed as ``validate``
photographs prints, each aligned every way the photo chain aligns a print it cannot read
(:meth:`Locator.every_alignment <deepmorph_detect.locate.Locator.every_alignment>`; no decoder).
The morphs are those of an untrained model's encoder: each within the drawing's bounds, as a
trained model's are.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from deepmorph_core.codec import CodecSpec
from deepmorph_core.errors import DeepMorphWarning
from deepmorph_core.luminance import Channel
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_detect.camera import project
from deepmorph_detect.locate import Aligned, Locator
from deepmorph_detect.metrics import corner_error
from deepmorph_detect.photo_validation import close_ups

#: hard close-ups simulated (about 0.1 s each): a drawing found in 93.8 % of photos (the median
#: measured) is found in fewer than :data:`~deepmorph_core.capacity.FOUND_ENOUGH` of 40 less than
#: once in 1000 runs, one found in 60 % in that many or more about once in 160
SHOTS = 40
#: the close-ups' seed (``bench/findable.py``'s)
SEED = 1
#: a print is found when an alignment's frame corners lie this close to the truth (mean distance,
#: a share of the frame's width): the reading refines from there
FOUND_WITHIN = 0.15
#: the decoder frame's width the untrained model is made with (the default training's)
WIDTH = 96


@dataclass(frozen=True)
class Findability:
    """How many of ``shots`` hard close-ups of a drawing the photo chain found it in
    (:meth:`CapacityReport.limits <deepmorph_core.capacity.CapacityReport.limits>` calls out a
    drawing found in fewer than :data:`~deepmorph_core.capacity.FOUND_ENOUGH` of them)."""

    found: int
    shots: int


def frame_error(frame_corners: np.ndarray, aligned: list[Aligned], truth: np.ndarray) -> float | None:
    """The smallest mean distance of ``aligned``'s frame corners from ``truth`` (``(4, 2)``
    pixels), in any corner order, as a share of the frame's width; ``None``: nothing aligned. A
    drawing that looks the same turned is read at each of its turns, so any order is found."""
    width = float(np.linalg.norm(truth[1] - truth[0]))
    quads = [project(a.alignment.homography, frame_corners) for a in aligned]
    return min((corner_error(np.roll(q, k, axis=0), truth) / width for q in quads for k in range(4)), default=None)


def untrained_model(
    svg_text: str, label: str, bounds: dict[str, Any], channel: Channel | None, print_px: int | None = None
) -> DeepMorphModel:
    """A model of the drawing as training starts one (seeded), with a small code, for prints at
    least ``print_px`` wide (``train --pixels``; ``None``: the default): what the photo chain
    needs to photograph and align its prints."""
    torch.manual_seed(0)
    spec = CodecSpec(payload_bits=4, crc_bits=8, bch_t=0)
    train = {} if print_px is None else {"print_px": print_px}
    return DeepMorphModel.create(
        svg_text, label, bounds, spec, WIDTH, {}, {}, train, label=label, reading_channel=channel
    )


def findability(
    drawing: MorphableDrawing,
    bounds: dict[str, Any],
    print_px: int | None = None,
    shots: int = SHOTS,
    seed: int = SEED,
) -> Findability:
    """How many of ``shots`` hard close-ups of ``drawing`` (loaded with the default ``bounds``,
    read in its channel) the universal detector and the alignment find, photographed as the
    validation of a model trained for prints ``print_px`` wide photographs them (``None``: the
    default model's)."""
    model = untrained_model(drawing.to_svg(drawing.neutral_values()[0]), "drawing", bounds, drawing.channel, print_px)
    with warnings.catch_warnings():  # no decoder reads here: its graph is not worth a warning
        warnings.simplefilter("ignore", DeepMorphWarning)
        locator = Locator(model, "universal", use_verifier=False)
    found = 0
    for shot in close_ups(locator.model, shots, seed, "hard"):
        truth = project(shot.homography, locator.frame_corners)
        error = frame_error(locator.frame_corners, locator.every_alignment(shot.photo), truth)
        found += error is not None and error < FOUND_WITHIN
    return Findability(found, shots)


__all__ = ["FOUND_WITHIN", "SHOTS", "Findability", "findability", "frame_error", "untrained_model"]
