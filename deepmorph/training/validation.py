"""Validation: how a trained model reads payloads it has never seen.

Training reports accuracies on its own batches; a user needs to know what the finished model
reads. After training (and tuning) every model is validated on fresh random payloads:

* **renders** (here): each payload's morph rendered by the real renderer (resvg) at the
  decoder's width, framed by its ink as photos are, through the training corruption at
  ``medium``, read by the decoder and the codec;
* further validations from plugins (the ``deepmorph_validate_model`` hook): the photo chain adds
  **close-ups**, simulated photos of prints that fill the frame.

The records are stored in the bundle (``meta.validation``) and shown by ``deepmorph info``. A
payload counts as read only when the codec vouches for it (its CRC matches) *and* it is the one
sent; one the codec vouches for that is not the one sent is counted as wrong.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
import torch

from deepmorph.training.settings import PHOTO_SAMPLES, RENDER_SAMPLES
from deepmorph_core.bundle import PayloadTally, ValidationRecord
from deepmorph_core.corruption import build_pipeline
from deepmorph_core.payload import random_payloads
from deepmorph_core.severity import VALIDATION_SEVERITY

if TYPE_CHECKING:
    from deepmorph_core.codec import PayloadCodec
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.plugins import Registry

TARGET_RATE = 0.99  # below this share of payloads read, training ends with a warning


def default_samples() -> tuple[int, int]:
    """``(renders, photos)``: the payloads training validates on when not told otherwise."""
    return RENDER_SAMPLES, PHOTO_SAMPLES


def validate_renders(
    model: DeepMorphModel,
    samples: int = RENDER_SAMPLES,
    seed: int = 0,
    severity: str = VALIDATION_SEVERITY,
    batch: int = 100,
    device: str = "cpu",
) -> ValidationRecord:
    """Read ``samples`` fresh payloads from real renders under the training corruption.

    Args:
        model: a trained model.
        samples: how many payloads (each drawn at random from ``seed``).
        severity: the corruption (``easy``, ``medium``, ``hard``).
        batch: renders per decoder call.
        device: where the networks and corruptions run (``cpu`` or ``cuda``; the renders are resvg's).
    """
    if samples < 1:
        raise ValueError(f"samples must be at least 1, got {samples}")
    start = time.perf_counter()
    codec = model.codec
    payloads = random_payloads(samples, codec.spec.payload_bits, np.random.default_rng(seed))
    codes = codec.encode(payloads)
    probs = read_renders(model, codes, severity, seed, batch, device)
    right_bits = int(((probs > 0.5) == (codes == 1)).sum())
    tally = tally_decoded(codec, probs, payloads)
    return ValidationRecord(
        name="renders",
        description=f"resvg renders at {model.width} px under the training corruption",
        severity=severity,
        samples=samples,
        read=tally.read,
        wrong=tally.wrong,
        bit_accuracy=right_bits / (samples * codec.spec.code_bits),
        seconds=round(time.perf_counter() - start, 2),
    )


def tally_decoded(codec: PayloadCodec, probs: np.ndarray, payloads: np.ndarray) -> PayloadTally:
    """The payloads ``codec`` reads from ``probs`` (``(B, N_b)``, each capture's ``P(bit = 1)``),
    counted against the ``payloads`` sent (``(B, payload_bits)``): read where the codec vouches for
    the one sent, wrong where it vouches for another."""
    tally = PayloadTally()
    for result, payload in zip(codec.decode_batch(probs), payloads):
        tally.add([result.payload] if result.ok else [], payload)
    return tally


def read_renders(
    model: DeepMorphModel,
    codes: np.ndarray,
    severity: str = VALIDATION_SEVERITY,
    seed: int = 0,
    batch: int = 100,
    device: str = "cpu",
) -> np.ndarray:
    """The decoder's ``P(bit = 1)``, ``(B, N_b)`` float64, on resvg renders of ``codes``
    (``(B, N_b)`` code words) framed by their ink and put through the ``severity`` corruption,
    whose random draws come from ``seed + 1``, ``batch`` renders per decoder call; the networks
    and the corruption on ``device`` (the model's networks are back on the CPU afterwards)."""
    model.eval()
    colour = model.drawing.colour
    on = torch.device(device)
    channel = model.drawing.channel
    augment = build_pipeline(
        severity, model.width, colour=colour, print_px=model.print_px, channel=channel, registered=model.registered
    ).to(on)
    generator = torch.Generator().manual_seed(seed + 1)  # on the CPU, so that every device draws the same
    probs = []
    model.encoder.to(on)
    model.decoder.to(on)
    try:
        for lo in range(0, len(codes), batch):
            values = model.morph_values(torch.from_numpy(codes[lo : lo + batch].astype(np.float32)).to(on))
            real = model.real_renders(values, rgb=colour)
            with torch.no_grad():
                framed = augment(model.framed(real), generator=generator)
            probs.append(model.probabilities(framed).cpu().numpy().astype(np.float64))
    finally:
        model.encoder.cpu()
        model.decoder.cpu()
    return np.concatenate(probs)


def validate(
    model: DeepMorphModel,
    registry: Registry,
    render_samples: int = RENDER_SAMPLES,
    photo_samples: int = PHOTO_SAMPLES,
    seed: int = 0,
    device: str = "cpu",
) -> list[ValidationRecord]:
    """Every validation: renders (networks on ``device``), then what plugins add (``photo_samples``
    payloads each; the photo chain runs on the CPU)."""
    records = [validate_renders(model, render_samples, seed, device=device)]
    if photo_samples > 0:
        records.extend(registry.validate_model(model, photo_samples, seed))
    return records


def validation_warning(records: list[ValidationRecord], label: str, own_detector: bool = False) -> str | None:
    """Why the model should not be trusted yet, when a validation read fewer than
    :data:`TARGET_RATE` of its payloads (or any wrong one); ``None`` when all is well.
    ``own_detector``: the model holds a detector of its drawing's own (``train-detector``), so
    prints not found are not met by advice to train one."""
    weak = [r for r in records if r.rate < TARGET_RATE or r.wrong]
    if not weak:
        return None
    parts = [f"{r.name} {r.read}/{r.samples} read, {r.wrong} wrong" + (f", {r.missed} not found" if r.missed else "")
             for r in weak]  # fmt: skip
    missed = sum(r.missed or 0 for r in weak)
    misread = sum(r.samples - r.read - r.wrong - (r.missed or 0) for r in weak)
    # the code reads its renders: photos' misses are their captures'
    renders_read = any(r.name == "renders" for r in records) and all(r.name != "renders" for r in weak)
    advice = []
    if any(r.wrong for r in weak) or (misread >= missed and not renders_read):
        advice.append("train with fewer --payload-bits (see `deepmorph capacity`), more --steps, or wider bounds")
    elif misread >= missed:
        advice.append(
            "its renders read, so the photos' misses are their capture's (shadows, blur, the narrowest prints), "
            "not the code's: a smaller code reads about as many"
        )
    if missed and missed >= misread:
        advice.append(
            "most captures not read were not found by the drawing's own detector: the bundle it was tuned"
            " from uses the universal detector, which may find more (compare both with `deepmorph validate`)"
            if own_detector
            else "most captures not read were not found: a detector of the drawing's own"
            " (`deepmorph train-detector`, about 2 minutes) may find them"
        )
    return (
        f"{label}: validation read fewer than {TARGET_RATE:.0%} of fresh payloads ({'; '.join(parts)}); "
        + "; ".join(advice)
    )


__all__ = [
    "PHOTO_SAMPLES",
    "RENDER_SAMPLES",
    "TARGET_RATE",
    "default_samples",
    "tally_decoded",
    "validate",
    "validate_renders",
    "validation_warning",
]
