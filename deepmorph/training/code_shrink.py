"""A smaller code, chosen by training, for a payload sized by ``--payload-bits auto``.

``auto`` starts from the largest payload :func:`deepmorph_core.capacity.predict` expects a drawing
to carry. The prediction counts readable variables; it does not see how faint they are in a
photo, so it can overshoot (colour drawings whose edges differ little in luminance). Training
sees what the drawing carries: once the curriculum has reached full corruption, it waits one
window of ``early_stop_window`` steps for the decoder to settle there, then watches the next.
A code that reads fewer than :data:`SHRINK_BELOW` of that window's code words is made smaller:

* its size is halfway between the code's and the information its bits carried over the window
  (each bit read with error rate ``p`` carries ``1 - H(p)`` bits, :func:`information`), which
  bounds it from below: the bits left then each get the variables the dropped ones drove, and
  read far better than they did in the crowded code (a colour drawing's 46 code bits read 1 %
  of words at step 2000; the 19 best of them, alone, 99 % 400 steps later);
* the new payload is the largest whose code fits that size (:func:`smaller_code`), with the CRC
  and BCH the user fixed, if any;
* the code bits the decoder read best over the window are kept, with their encoder columns and
  decoder outputs; the others are dropped (:func:`shrink_networks`).

Training goes on from there with the same networks, and watches again after another settling
window, so a code that still does not read is halved again towards its information. A
user-given size is never changed: its model reads what it reads, and validation says so.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from deepmorph_core.bundle import AutoPayload, CodeShrink
from deepmorph_core.capacity import ECC_CHOICES, payload_codes
from deepmorph_core.codec import CodecSpec, PayloadCodec
from deepmorph_core.model import DeepMorphModel

#: A code that reads fewer of its words than this over a window at full corruption is shrunk.
#: Codes that go on to read 99 % of photos read 98-99.6 % there (the time-to-print panel).
SHRINK_BELOW = 0.9
#: The same for a model trained with ``--pixels``: its corruption is the camera's at the
#: narrowest print it reads, with a share of hard captures, so its batches read fewer words than
#: its close-ups do. Codes that read 98.5-100 % of medium close-ups at 240 and 330 px read
#: 0.64-1.00 of their words over their last batches; codes that read 56-95 % of close-ups,
#: 0.13-0.58; one at 97.5 %, 0.78 (``bench/pixels_panel.py``, ``bench/README.md``).
SHRINK_BELOW_AT_PIXELS = 0.6


def shrink_below(print_px: int | None) -> float:
    """The read share below which a code of a model trained for prints ``print_px`` wide
    (``None``: the default training) is shrunk."""
    return SHRINK_BELOW if print_px is None else SHRINK_BELOW_AT_PIXELS


def read_share(errors: Tensor, bits: Tensor, correctable: int) -> float:
    """The share of captures (rows of ``errors``, ``(R, N_b)`` bool: code bits read wrong)
    with at most ``correctable`` errors among the code bits ``bits``."""
    return float((errors[:, bits].sum(1) <= correctable).double().mean())


def information(errors: Tensor) -> float:
    """The bits of information a window's captures carried: ``sum(1 - H(p_i))`` over the code
    bits, ``p_i`` the share of captures that read bit ``i`` wrong (at most 1/2: a bit read
    wrong more often than not still tells its value)."""
    total = 0.0
    for p in errors.double().mean(0).tolist():
        p = min(p, 1.0 - p)
        total += 1.0 if p <= 0.0 else 1.0 + p * math.log2(p) + (1.0 - p) * math.log2(1.0 - p)
    return total


def smaller_code(errors: Tensor, spec: CodecSpec, auto: AutoPayload) -> tuple[CodecSpec, list[int], float] | None:
    """The code to go on with, the current code bits it keeps (the best read, ascending) and
    the information the window's bits carried: the largest payload below ``spec``'s whose
    code fits halfway between ``spec``'s code bits (less one) and that information; where none
    fits, the smallest payload's code. ``None`` where no code is smaller than ``spec``'s.

    Args:
        errors: ``(R, N_b)`` bool, the code bits each capture of the window read wrong.
        spec: the code now.
        auto: the CRC and BCH the user fixed.
    """
    carried = information(errors)
    size = math.ceil((carried + spec.code_bits - 1) / 2)
    new: CodecSpec | None = None
    for payload in range(spec.payload_bits - 1, 0, -1):
        codes = payload_codes(payload, auto.crc_bits, ECC_CHOICES if auto.ecc_t is None else (auto.ecc_t,))
        fitting = [c for c in codes if c.code_bits <= size]
        if fitting or payload == 1:
            new = fitting[0] if fitting else min(codes, key=lambda c: c.code_bits, default=None)
            break
    if new is None or new.code_bits >= spec.code_bits:
        return None
    order = torch.argsort(errors.sum(0), stable=True)  # best read first
    return new, sorted(int(k) for k in order[: new.code_bits]), carried


def _linear(weight: Tensor, bias: Tensor | None, like: nn.Linear) -> nn.Linear:
    """A linear layer holding ``weight`` (``(out, in)``) and ``bias``, trainable as ``like`` is."""
    layer = nn.Linear(weight.shape[1], weight.shape[0], bias=bias is not None, device=weight.device)
    with torch.no_grad():
        layer.weight.copy_(weight)
        if bias is not None:
            layer.bias.copy_(bias)
    layer.requires_grad_(like.weight.requires_grad)
    return layer


def shrink_networks(model: DeepMorphModel, keep: list[int], spec: CodecSpec) -> None:
    """Make ``model`` carry ``spec``'s code on its code bits ``keep``: the encoder's columns
    and the decoder's outputs (its head and its readout) of the others are dropped; new code bit
    ``i`` is old bit ``keep[i]``."""
    if len(keep) != spec.code_bits:
        raise ValueError(f"{spec.code_bits} code bits need as many kept bits, got {len(keep)}")
    index = torch.tensor(keep, dtype=torch.long, device=model.encoder.linear.weight.device)
    with torch.no_grad():
        enc = model.encoder.linear
        model.encoder.linear = _linear(enc.weight[:, index], None, enc)
        out = model.decoder.head[-1]
        model.decoder.head[-1] = _linear(out.weight[index], out.bias[index], out)
        readout = model.decoder.readout
        if readout is not None:
            model.decoder.readout = _linear(readout.weight[index], readout.bias[index], readout)
    model.codec = PayloadCodec(spec)
    model.meta.codec = spec
    model.graphs.clear()  # made for the old code


def describe(shrink: CodeShrink) -> str:
    """One line for the user: what training found and did."""
    after = shrink.payload_bits[1]
    return (
        f"its {shrink.payload_bits[0]}-bit payload read {shrink.read:.0%} of code words at full corruption "
        f"by step {shrink.step} (its code bits carried about {shrink.information:.0f} bits); training went on "
        f"with {after} bit{'' if after == 1 else 's'} ({shrink.code_bits[1]} code bits; --payload-bits auto)"
    )


__all__ = [
    "SHRINK_BELOW",
    "SHRINK_BELOW_AT_PIXELS",
    "describe",
    "information",
    "read_share",
    "shrink_below",
    "shrink_networks",
    "smaller_code",
]
