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
  and BCH the user fixed, if any, else a BCH strength the plan chooses from
  (:meth:`CutRules.ecc_strengths`);
* the code bits the decoder read best over the window are kept, with their encoder columns and
  decoder outputs; the others are dropped (:func:`shrink_networks`).

Training goes on from there with the same networks, and watches again after another settling
window, so a code that still does not read is halved again towards its information.

Batches are a coarse judge near the limit: a ``--pixels`` code that read 97.5 % of close-ups
read 0.78 of its batch words, one that read 99.5 % read 0.75. So when training ends, an ``auto``
code is also judged as validation will judge it (:func:`code_for_renders`): fresh payloads
rendered by resvg and read through the medium corruption. A code that reads fewer than
:data:`RENDER_SHRINK_BELOW` of them is made smaller, towards the size its best-read bits need,
with the reliabilities the renders measured, to read :data:`RENDER_FIT` of them: the first
time halfway there in code bits, later the whole way, and each time training goes on for
``renders_tune`` steps (at most :data:`RENDER_ROUNDS` times). Halfway, because the bits kept read
better once the dropped ones free their variables, which the reliabilities measured in the larger
code cannot show (three black-and-white drawings and a colour one read as many close-ups so).
A user-given size is never changed: its model reads what it reads, and validation says so.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor, nn

from deepmorph.training.validation import RENDER_SAMPLES, TARGET_RATE, read_renders, tally_decoded
from deepmorph_core.bundle import AutoPayload, CodeShrink
from deepmorph_core.capacity import default_crc_code, payload_codes, plan_code, plan_ecc
from deepmorph_core.codec import CodecSpec, PayloadCodec
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import random_payloads

#: A code that reads fewer of its words than this over a window at full corruption is shrunk.
#: Codes that go on to read 99 % of photos read 98-99.6 % there (the time-to-print panel).
SHRINK_BELOW = 0.9
#: The same for a model trained with ``--pixels``: its corruption is the camera's at the
#: narrowest print it reads, with a share of hard captures, and its batches read few words while
#: it still learns. At the first window judged (step 2000 of 4000), codes that went on to read
#: 91-100 % of renders read 0.16-0.99 of their words; codes of 44-48 bits that read 60-76 %, 0.03-0.06
#: (``bench/README.md``). The check when training ends judges the rest (:func:`code_for_renders`).
SHRINK_BELOW_AT_PIXELS = 0.1


#: An auto code whose finished model reads fewer fresh renders than this is shrunk (validation's bar).
RENDER_SHRINK_BELOW = TARGET_RATE
#: The smaller code is the largest whose best-read bits, at the reliabilities the renders
#: measured, read this share of them: a margin over the bar, under the renders no code reads.
#: ``codepen``'s 20-bit model at ``--pixels 200``: every code of 10-16 payload bits on its best
#: bits reads 99.6-100 % of 1000 renders, 17 bits 99.4 %, 18 bits 99.3 %, 20 bits 98.0-98.4 %, and
#: adjacent sizes differ by less than the sampling's 0.2 points. A bar at 99.5 % cut it to 12 bits.
RENDER_FIT = 0.993
#: How many times the end-of-training check may shrink one training (it reads as many fresh
#: renders as validation, :data:`~deepmorph.training.validation.RENDER_SAMPLES`): once halfway,
#: then twice the whole way (:func:`code_fitting`).
RENDER_ROUNDS = 3
#: The check's payloads and corruption draw from the training's seed plus this, apart from validation's.
RENDER_SEED_OFFSET = 7919


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


@dataclass(frozen=True)
class CutRules:
    """What every cut of one training keeps: the CRC and BCH the user fixed (``auto``), the print
    width the model is trained for (``print_px``, ``None``: the default training) and whether the
    drawing is in colour (its codes planned with a longer CRC,
    :func:`~deepmorph_core.capacity.plan_code`)."""

    auto: AutoPayload = field(default_factory=AutoPayload)
    print_px: int | None = None
    colour: bool = False

    @classmethod
    def of(cls, model: DeepMorphModel, auto: AutoPayload) -> CutRules:
        """The rules for cutting ``model``'s code, sized by ``auto``."""
        return cls(auto, model.print_px, bool(model.drawing.colour))

    def ecc_strengths(self) -> tuple[int, ...]:
        """The BCH strengths a cut code may have: the user's, or those the plan for the print
        width chooses from (:func:`~deepmorph_core.capacity.plan_ecc`: t = 2 alone under
        ``--pixels 200``, where a t = 1 code cut from a t = 2 one passed a wrong payload in
        10,008 close-ups)."""
        return (self.auto.ecc_t,) if self.auto.ecc_t is not None else plan_ecc(self.print_px)

    def planned_from(self, spec: CodecSpec) -> CodecSpec:
        """The code the plan made ``spec`` from: a colour code's CRC-8 form where the CRC is
        DeepMorph's (:func:`~deepmorph_core.capacity.default_crc_code`), else ``spec``."""
        return default_crc_code(spec) if self.colour and self.auto.crc_bits is None else spec

    def codes(self, payload_bits: int) -> list[CodecSpec]:
        """The codes a cut to ``payload_bits`` may go on with, in the plan's order."""
        return [
            plan_code(c, self.colour, self.auto.crc_bits)
            for c in payload_codes(payload_bits, self.auto.crc_bits, self.ecc_strengths())
        ]


def largest_smaller(spec: CodecSpec, rules: CutRules, fits: Callable[[CodecSpec], bool]) -> CodecSpec | None:
    """The code a cut goes on with: the largest payload below ``spec``'s with a code that ``fits``
    (of :meth:`CutRules.codes`, the first in their order); where none does, the smallest
    payload's smallest code. ``None`` where that code is not smaller than ``spec``'s. Payloads
    are counted from the code ``spec`` was planned from (:meth:`CutRules.planned_from`), so a
    colour code loses what its CRC-8 form would."""
    for payload in range(rules.planned_from(spec).payload_bits - 1, 0, -1):
        codes = rules.codes(payload)
        fitting = [c for c in codes if fits(c)]
        if fitting or payload == 1:
            new = fitting[0] if fitting else min(codes, key=lambda c: c.code_bits, default=None)
            return new if new is not None and new.code_bits < spec.code_bits else None
    return None


def code_halfway(spec: CodecSpec, toward_bits: float, rules: CutRules) -> CodecSpec | None:
    """The largest payload below ``spec``'s (:func:`largest_smaller`) whose code fits halfway, in
    code bits, between ``spec``'s (less one) and ``toward_bits``: how far both cuts go when they
    go halfway (:func:`smaller_code`, and :func:`code_fitting`'s first)."""
    size = math.ceil((toward_bits + spec.code_bits - 1) / 2)
    return largest_smaller(spec, rules, lambda c: c.code_bits <= size)


def smaller_code(errors: Tensor, spec: CodecSpec, rules: CutRules) -> tuple[CodecSpec, list[int], float] | None:
    """The code to go on with, the current code bits it keeps (the best read, ascending) and
    the information the window's bits carried: the largest payload below ``spec``'s whose
    code fits halfway between ``spec``'s code bits (less one) and that information; where none
    fits, the smallest payload's code. ``None`` where no code is smaller than ``spec``'s.

    Args:
        errors: ``(R, N_b)`` bool, the code bits each capture of the window read wrong.
        spec: the code now.
        rules: what the cut keeps (the user's CRC and BCH, the print width, colour).
    """
    carried = information(errors)
    new = code_halfway(spec, carried, rules)
    if new is None:
        return None
    order = torch.argsort(errors.sum(0), stable=True)  # best read first
    return new, sorted(int(k) for k in order[: new.code_bits]), carried


@dataclass(frozen=True)
class RenderShrink:
    """What :func:`code_for_renders` found: the code to go on with and the current code bits it
    keeps (ascending), the share of renders the current code read, and the information its bits
    carried there (:func:`information`)."""

    spec: CodecSpec
    keep: list[int]
    read: float
    information: float


def simulated_read(right: np.ndarray, spec: CodecSpec, rng: np.random.Generator) -> float:
    """The share of fresh ``spec`` words the codec reads when each capture's bits are read as
    reliably as measured: ``right`` is ``(R, spec.code_bits)``, the decoder's probability of the
    right value of each bit of each capture (read on other words: a bit's reliability does not
    depend on the value it carries)."""
    codec = PayloadCodec(spec)
    payloads = random_payloads(len(right), spec.payload_bits, rng)
    words = codec.encode(payloads)
    probs = np.where(words == 1, right, 1.0 - right)
    return tally_decoded(codec, probs, payloads).read / len(right)


def code_fitting(
    right: np.ndarray, spec: CodecSpec, rules: CutRules, rng: np.random.Generator, halfway: bool = False
) -> tuple[CodecSpec, list[int]] | None:
    """The code to go on with and the current code bits it keeps (ascending, the most reliable),
    for a code whose bits were read with the reliabilities ``right`` (``(R, spec.code_bits)``,
    each capture's probability of each bit's right value): the largest payload below ``spec``'s
    (of :meth:`CutRules.codes`) whose code, on the most reliable bits, reads at least
    :data:`RENDER_FIT` of the captures (:func:`simulated_read`); otherwise as
    :func:`largest_smaller` says. ``halfway``: the largest payload whose code fits halfway
    between ``spec``'s code bits (less one) and that code's. A `--pixels 200` `cpu` whose 24-bit
    payload read 96.9 % of renders fitted 15 bits so, where the halfway code (19 bits), trained
    on, read 99.4 % of them and 99.5-100 % of close-ups."""
    order = np.argsort(-right.mean(0), kind="stable")  # most reliable first

    def fits(code: CodecSpec) -> bool:  # read on its best bits (a code no smaller is not tried)
        best = right[:, order[: code.code_bits]]
        return code.code_bits < spec.code_bits and simulated_read(best, code, rng) >= RENDER_FIT

    new = largest_smaller(spec, rules, fits)
    if new is None:
        return None
    if halfway:
        new = code_halfway(spec, new.code_bits, rules) or new
    return new, sorted(int(k) for k in order[: new.code_bits])


def code_for_renders(
    model: DeepMorphModel,
    auto: AutoPayload,
    seed: int = 0,
    device: str = "cpu",
    samples: int = RENDER_SAMPLES,
    halfway: bool = False,
) -> RenderShrink | None:
    """A smaller code (:func:`code_fitting`, ``halfway`` or not) for a trained ``model`` whose code
    reads fewer than :data:`RENDER_SHRINK_BELOW` of ``samples`` fresh renders
    (:func:`~deepmorph.training.validation.read_renders`; payloads and corruption drawn from
    ``seed``, the networks on ``device`` and back on the CPU after); ``None`` where it reads
    enough, or no code is smaller."""
    codec, spec = model.codec, model.codec.spec
    rng = np.random.default_rng(seed)
    payloads = random_payloads(samples, spec.payload_bits, rng)
    words = codec.encode(payloads)
    probs = read_renders(model, words, seed=seed, device=device)
    read = tally_decoded(codec, probs, payloads).read / samples
    if read >= RENDER_SHRINK_BELOW:
        return None
    right = np.where(words == 1, probs, 1.0 - probs)
    found = code_fitting(right, spec, CutRules.of(model, auto), rng, halfway)
    if found is None:
        return None
    return RenderShrink(found[0], found[1], read, information(torch.from_numpy(right < 0.5)))


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
    model.use_code(spec)
    model.graphs.clear()  # made for the old code


def describe(shrink: CodeShrink) -> str:
    """One line for the user: what training found and did."""
    after = shrink.payload_bits[1]
    found = (
        f"read {shrink.read:.1%} of fresh renders when training ended at step {shrink.step}"
        if shrink.measured_on == "renders"
        else f"read {shrink.read:.0%} of code words at full corruption by step {shrink.step}"
    )
    return (
        f"its {shrink.payload_bits[0]}-bit payload {found} (its code bits carried about "
        f"{shrink.information:.0f} bits); training went on with {after} bit{'' if after == 1 else 's'} "
        f"({shrink.code_bits[1]} code bits; --payload-bits auto)"
    )


__all__ = [
    "RENDER_FIT",
    "RENDER_ROUNDS",
    "RENDER_SHRINK_BELOW",
    "SHRINK_BELOW",
    "SHRINK_BELOW_AT_PIXELS",
    "CutRules",
    "RenderShrink",
    "code_fitting",
    "code_halfway",
    "code_for_renders",
    "describe",
    "information",
    "largest_smaller",
    "read_share",
    "shrink_below",
    "shrink_networks",
    "simulated_read",
    "smaller_code",
]
