"""The photo chain's validation of a trained model: close-up photos of its codes.

Each fresh payload's code is rendered at :data:`PRINT_PX`, printed and photographed close
(:func:`~deepmorph_detect.scenes.close_up_photo`: a scan, or a phone held close, at ``medium``;
a colour code is printed in colour, through the colour plugins, :func:`printed`) and decoded
by the whole photo chain (:class:`~deepmorph_detect.locate.Locator`). A model without a
trained detector is read from whole frames, as such photos need no detector.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from deepmorph_core.bundle import ValidationRecord
from deepmorph_core.corruption import AugmentPipeline, build_pipeline
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import random_payloads
from deepmorph_core.render import render_svg, render_svg_rgb
from deepmorph_core.validation import SEVERITY
from deepmorph_detect.locate import Locator
from deepmorph_detect.scenes import close_up_photo, colour_print, model_added_steps

PRINT_PX = 400  # the code's render, before it is printed and photographed


def printed(model: DeepMorphModel, svg: str, colours: AugmentPipeline | None, rng: np.random.Generator) -> np.ndarray:
    """A code's print as the photo simulator takes it, ``(H, W)`` float, 1 = white: a colour
    drawing rendered in colour and put through the colour corruptions of the capture (ink,
    paper, white balance, chroma: the registered ``colour`` plugins) before it becomes the
    luminance the camera simulation works on; a black-and-white one rendered as it is."""
    if colours is None:
        return render_svg(svg, PRINT_PX)
    return colour_print(render_svg_rgb(svg, PRINT_PX), colours, rng)


def validate_close_ups(
    model: DeepMorphModel, samples: int, seed: int = 0, severity: str = SEVERITY
) -> ValidationRecord:
    """Read ``samples`` fresh payloads from close-up photos through the photo chain."""
    start = time.perf_counter()
    model.eval()
    codec = model.codec
    rng = np.random.default_rng(seed + 7)
    payloads = random_payloads(samples, codec.spec.payload_bits, rng)
    codes = codec.encode(payloads)
    locator = Locator(model)
    colours = build_pipeline(severity, PRINT_PX, colour=True) if model.drawing.colour else None
    added = model_added_steps(model)
    read = wrong = right_bits = missed = 0
    for code, payload in zip(codes, payloads):
        values = model.morph_values(torch.from_numpy(code.astype(np.float32))[None])[0]
        photo = close_up_photo(printed(model, model.drawing.to_svg(values), colours, rng), severity, rng, extra=added)
        found = locator.locate(photo)
        if not found:
            missed += 1
            continue
        right_bits += int(((found[0].probabilities > 0.5) == (code == 1)).sum())
        vouched = [f for f in found if f.result.ok]
        if vouched:
            same = any(np.array_equal(f.result.payload, payload) for f in vouched)
            read += same
            wrong += not same
    return ValidationRecord(
        name="close-ups",
        description=f"photos of {PRINT_PX}-px prints filling the frame, through the photo chain",
        severity=severity,
        samples=samples,
        read=read,
        wrong=wrong,
        bit_accuracy=right_bits / ((samples - missed) * codec.spec.code_bits) if missed < samples else None,
        missed=missed,
        seconds=round(time.perf_counter() - start, 2),
    )


__all__ = ["PRINT_PX", "printed", "validate_close_ups"]
