"""The photo chain's validation of a trained model: close-up photos of its codes.

Each fresh payload's code is rendered at :data:`PRINT_PX`, printed and photographed close
(:func:`~deepmorph_detect.scenes.close_up_photo`: a scan, or a phone held close, at ``medium``;
a colour code is printed in colour, through the colour plugins, :func:`printed`; the print
spans 144-192 of the photo's 240 camera pixels, or about ``print_px``) and decoded
by the whole photo chain (:class:`~deepmorph_detect.locate.Locator`). A model without a
trained detector is read from whole frames, as such photos need no detector.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np
import torch

from deepmorph_core.bundle import PayloadTally, ValidationRecord
from deepmorph_core.corruption import AugmentPipeline, build_pipeline
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import random_payloads
from deepmorph_core.render import render_svg, render_svg_rgb
from deepmorph_core.severity import VALIDATION_SEVERITY
from deepmorph_detect.close_up_pool import read_close_ups
from deepmorph_detect.locate import Locator
from deepmorph_detect.refine import pixels_to_svg_units
from deepmorph_detect.results import across_px
from deepmorph_detect.scenes import CLOSE_UP_SIZE, Art, close_up_placed, colour_print, model_added_steps

PRINT_PX = 400  # the code's render, before it is printed and photographed
#: The close-up photo's width: its drawing spans 60-80 % of it, 144-192 camera pixels.
PHOTO_PX = 240


def photo_for_print(print_px: float) -> int:
    """The width of a close-up photo whose drawing spans about ``print_px`` camera pixels (the
    middle of :data:`~deepmorph_detect.scenes.CLOSE_UP_SIZE`)."""
    return max(16, round(print_px / (sum(CLOSE_UP_SIZE) / 2)))


def printed(
    model: DeepMorphModel, svg: str, colours: AugmentPipeline | None, rng: np.random.Generator, width: int = PRINT_PX
) -> Art:
    """A code's print as the photo simulator takes it, ``(H, W)`` float, 1 = white, and its
    paper: a colour drawing rendered in colour and put through the colour corruptions of the
    capture (ink, paper, white balance, chroma: the registered ``colour`` plugins) before it
    becomes the luminance the camera simulation works on (``(H, W, 3)`` RGB for a model read in
    another channel, photographed in colour: :func:`~deepmorph_detect.scenes.colour_print`); a
    black-and-white one rendered as it is, on white paper."""
    if colours is None:
        return render_svg(svg, width), 1.0
    return colour_print(render_svg_rgb(svg, width), colours, rng)


@dataclass(frozen=True)
class CloseUp:
    """One close-up of :func:`close_ups`: the photo, the payload and code bits it shows, the
    print's width in it (:func:`~deepmorph_detect.results.across_px`), and the pose the simulator
    photographed it at (``homography``: SVG units -> photo pixels, what a perfect alignment
    finds)."""

    photo: np.ndarray
    payload: np.ndarray
    code: np.ndarray
    width_px: float
    homography: np.ndarray

    def narrower_than_read(self, model: DeepMorphModel) -> bool:
        """Whether the print is narrower than ``model`` was trained to read (``print_px``), so
        that its right answer is "too small": the simulator makes a few close-ups narrower than
        asked, where no pose of the asked size fits the frame and it tries smaller ones."""
        return model.print_px is not None and self.width_px < model.print_px


def close_up_width(model: DeepMorphModel, print_px: float | None = None) -> int:
    """The close-up photo's width for ``model``: :data:`PHOTO_PX`, or wide enough that the print
    spans the width the model was trained for (``model.print_px``), or about ``print_px``."""
    if print_px is not None:
        return photo_for_print(print_px)
    if model.print_px is not None:  # its prints span at least the width it was trained for
        return math.ceil(model.print_px / CLOSE_UP_SIZE[0])
    return PHOTO_PX


def close_ups(
    model: DeepMorphModel,
    samples: int,
    seed: int = 0,
    severity: str = VALIDATION_SEVERITY,
    print_px: float | None = None,
) -> Iterator[CloseUp]:
    """``samples`` close-ups of fresh payloads' codes (:func:`validate_close_ups`'s, by ``seed``):
    each code rendered, printed (:func:`printed`) and photographed close at ``severity``, in a
    photo :func:`close_up_width` wide."""
    model.eval()
    codec = model.codec
    rng = np.random.default_rng(seed + 7)
    payloads = random_payloads(samples, codec.spec.payload_bits, rng)
    codes = codec.encode(payloads)
    md = model.drawing
    colours = build_pipeline(severity, PRINT_PX, colour=True, channel=md.channel) if md.colour else None
    added = model_added_steps(model)
    photo_px = close_up_width(model, print_px)
    high = round(CLOSE_UP_SIZE[1] * photo_px)
    for code, payload in zip(codes, payloads):
        values = model.morph_values(torch.from_numpy(code.astype(np.float32))[None])[0]
        art, paper = printed(model, model.drawing.to_svg(values), colours, rng, max(PRINT_PX, 2 * high))
        photo, art_to_photo = close_up_placed(art, severity, rng, size=photo_px, extra=added, paper=paper)
        height, width = art.shape[:2]
        frame = np.array([[0, 0], [width, 0], [width, height], [0, height]], np.float64)  # the art's pixels
        svg_to_art = np.linalg.inv(pixels_to_svg_units(md.drawing.viewbox, width))  # the viewBox rendered
        yield CloseUp(photo, payload, code, across_px(art_to_photo, frame), art_to_photo @ svg_to_art)


def validate_close_ups(  # noqa: PLR0913
    model: DeepMorphModel,
    samples: int,
    seed: int = 0,
    severity: str = VALIDATION_SEVERITY,
    print_px: float | None = None,
    detector: str | None = None,
    workers: int = 1,
) -> ValidationRecord:
    """Read ``samples`` fresh payloads from close-up photos through the photo chain: photos
    :data:`PHOTO_PX` wide (a model trained for prints ``model.print_px`` wide: photos whose
    prints span that width or more), or with the drawing about ``print_px`` camera pixels wide; with the
    model's detector, or the one named by ``detector`` (``"none"``: whole images only), by
    ``workers`` processes (:mod:`deepmorph_detect.close_up_pool`: the same record as one).

    A model trained for prints at least ``print_px`` wide refuses a narrower one as too small.
    The simulator makes a few close-ups narrower than asked (where no pose of the asked size fits
    the frame, it tries smaller ones): those are not counted, unless they give a wrong payload,
    and the description says how many there were."""
    start = time.perf_counter()
    photo_px = close_up_width(model, print_px)
    low, high = (round(share * photo_px) for share in CLOSE_UP_SIZE)
    tally = PayloadTally()
    right_bits = missed = unread = narrower = 0
    shots = close_ups(model, samples, seed, severity, print_px)
    for seen in read_close_ups(model, shots, _close_up_seen, workers, detector=detector):
        if seen.narrower:
            narrower += 1
            tally.wrong += any(not np.array_equal(payload, seen.payload) for payload in seen.vouched)
            continue
        if seen.right_bits is None:
            # found but not read (a blind detector reports only what it reads), or not found
            missed += not seen.aligns
            unread += 1
            continue
        right_bits += seen.right_bits
        tally.add(seen.vouched, seen.payload)
    counted = samples - narrower
    description = f"photos {photo_px} px wide of prints {low}-{high} px wide in them, through the photo chain"
    if narrower:
        description += f"; {narrower} narrower than {model.print_px} px not counted"
    return ValidationRecord(
        name="close-ups",
        description=description,
        severity=severity,
        samples=max(counted, 1),
        read=tally.read,
        wrong=tally.wrong,
        bit_accuracy=right_bits / ((counted - unread) * model.codec.spec.code_bits) if unread < counted else None,
        missed=missed,
        seconds=round(time.perf_counter() - start, 2),
    )


@dataclass(frozen=True)
class CloseUpSeen:
    """What the photo chain made of one validation close-up (:func:`_close_up_seen`).

    Attributes:
        payload: the payload printed.
        narrower: the print is narrower than the model reads (not counted).
        vouched: the payloads reported read.
        right_bits: the first drawing found's code bits read right; ``None`` where none was found.
        aligns: where none was found and the print is not narrower, whether the detector's
            proposals aligned at all; else ``None``.
    """

    payload: np.ndarray
    narrower: bool
    vouched: list[np.ndarray]
    right_bits: int | None
    aligns: bool | None


def _close_up_seen(locator: Locator, shot: CloseUp) -> CloseUpSeen:
    """One validation close-up through ``locator``: run in a worker, so a small result."""
    found = locator.locate(shot.photo)
    vouched = [f.result.payload for f in found if f.result.ok]
    if shot.narrower_than_read(locator.model):
        return CloseUpSeen(shot.payload, True, vouched, None, None)
    if not found:
        return CloseUpSeen(shot.payload, False, vouched, None, locator.aligns(shot.photo))
    right = int(((found[0].probabilities > 0.5) == (shot.code == 1)).sum())
    return CloseUpSeen(shot.payload, False, vouched, right, None)


@dataclass(frozen=True)
class WrongPayloadCount:
    """What :func:`count_wrong_payloads` read: close-ups that gave the payload printed, and those
    that gave another one (any other payload reported counts, beside the right one or not)."""

    samples: int
    read: int
    wrong: int
    seconds: float


def count_wrong_payloads(  # noqa: PLR0913
    model: DeepMorphModel,
    samples: int,
    seed: int,
    crc_checked: int,
    severity: str = "hard",
    print_px: float | None = None,
    workers: int = 1,
) -> WrongPayloadCount:
    """Read ``samples`` fresh payloads' close-ups (:func:`close_ups`) through the photo chain,
    the model's CRC checked on only its first ``crc_checked`` bits
    (:meth:`PayloadCodec.narrowed <deepmorph_core.codec.PayloadCodec.narrowed>`), and count the
    wrong payloads. A wrong code word passes such a CRC ``2**(crc_bits - crc_checked)`` times as
    often as the whole one, at every look the chain takes, and the rest of the chain (the morph's
    fit, the bits' evidence, the print's size) judges it as it would a real collision, the code
    word reached: each wrong payload counted stands for that many fewer with the whole CRC. A little fewer are
    counted than that, as a wrong word passed early can end a search that would have passed
    another later. ``workers`` processes read the close-ups (:mod:`deepmorph_detect.close_up_pool`),
    with the same count as one. The model is not changed."""
    start = time.perf_counter()
    narrow = replace(model, codec=model.codec.narrowed(crc_checked))
    read = wrong = 0
    shots = close_ups(model, samples, seed, severity, print_px)
    for right, other in read_close_ups(narrow, shots, payloads_reported, workers):
        read += right
        wrong += other
    return WrongPayloadCount(samples, read, wrong, round(time.perf_counter() - start, 2))


def payloads_reported(locator: Locator, shot: CloseUp) -> tuple[bool, bool]:
    """Whether the photo chain reported ``shot``'s payload, and whether it reported another,
    its narrowed codec's collision forgotten first."""
    locator.model.codec.forget()
    vouched = [f.result.payload for f in locator.locate(shot.photo) if f.result.ok]
    right = any(np.array_equal(payload, shot.payload) for payload in vouched)
    return right, any(not np.array_equal(payload, shot.payload) for payload in vouched)


__all__ = [
    "PHOTO_PX",
    "PRINT_PX",
    "CloseUp",
    "close_up_width",
    "WrongPayloadCount",
    "close_ups",
    "count_wrong_payloads",
    "payloads_reported",
    "photo_for_print",
    "printed",
    "validate_close_ups",
]
