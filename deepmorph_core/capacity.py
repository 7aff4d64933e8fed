"""How many payload bits a drawing carries, predicted before any training.

The decoder reads code bits from the variables a renderer shows. What limits a drawing:

* **invisible variables** change nothing a renderer draws (a point moving along its own straight
  line, or under other ink): :meth:`MorphableDrawing.visibility
  <deepmorph_core.morphable.MorphableDrawing.visibility>` at or below
  :data:`~deepmorph_core.morphable.INVISIBLE` of the median variable;
* **faint shapes**: a shape whose edges differ little in luminance from what lies around them
  (a colour close to its neighbour's, :data:`FAINT`) moves just as faintly; its variables are not
  counted;
* **look-alikes**: variables whose effects on the picture are the same
  (:func:`~deepmorph_core.networks.twin_groups`, the two ends of a half circle) carry what one
  variable does.

What is left are the drawing's *readable groups*. A trained decoder reads about
:data:`CODE_BITS_PER_GROUP` code bits per readable group reliably enough for whole payloads to
come back from 99 % of captures, up to :data:`LARGEST_CODE_MEASURED` code bits: the capacity
panel (``bench/capacity.py``, ``bench/README.md``) is what both were fitted on. The largest
payload is then the largest one whose code (CRC and a BCH code correcting one or two bit errors,
:func:`~deepmorph_core.codec.choose_codec`) fits in that many code bits.

A model trained for prints at least :data:`PIXELS_MEASURED` px wide in the photo (``train
--pixels``) sees each print sharper and is trained on the photo chain's own view of it
(:mod:`deepmorph_core.registration`). Its plan starts from the drawing's measured channel
(:func:`deepmorph_core.channel.read_channel` at :data:`PIXELS_MEASURED` px, about half a minute):
how well a linear reading of photos of the print tells each readable group's two ends apart, which
sees how far each variable moves in the photo's pixels, the contrast of the edge it moves and how
groups crowd each other. A model reads :data:`CHANNEL_SHARE` of the payload that reading carries,
in codes correcting two bit errors (:data:`ECC_AT_PIXELS`, the codes it was measured with) of at
most :data:`LARGEST_CODE_MEASURED` code bits, as at 96 px:
fitted on two drawings of ``bench/pixels_panel.py``'s rule and checked on seven more
(``bench/README.md``). Below that width nothing larger was measured, and the 96-px figure stands.

A colour drawing's planned code gives payload bits to a CRC of :data:`COLOUR_CRC` bits where the
CRC is DeepMorph's to choose (:func:`plan_code`): the same code bits, so the same networks, but a
colour print's wrong words pass the photo chain's checks far more often than black ink's.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
import torch

from deepmorph_core.codec import COLOUR_CRC, CodecSpec, choose_codec, widths_within, with_crc
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.morphable import INVISIBLE, MorphableDrawing
from deepmorph_core.networks import twin_groups
from deepmorph_core.payload import MAX_PAYLOAD_BITS

#: Code bits a decoder reads reliably per readable group (see the module docstring).
CODE_BITS_PER_GROUP = 0.70
#: The share of its channel's payload (:func:`deepmorph_core.channel.read_channel` at
#: :data:`PIXELS_MEASURED` px) a model trained with ``--pixels`` of at least that reads from 99 %
#: of captures (see the module docstring).
CHANNEL_SHARE = 0.48
#: The print width in photo pixels :data:`CHANNEL_SHARE` was measured at.
PIXELS_MEASURED = 200
#: BCH codes the prediction at :data:`PIXELS_MEASURED` uses: correcting two bit errors.
ECC_AT_PIXELS = (2,)
#: The largest code a model of a crowded drawing (many readable groups in a small space, which
#: the count of groups does not see) was measured to read from 99 % of captures; the prediction
#: does not reach beyond it (a drawing with many readable groups is not predicted to carry more).
LARGEST_CODE_MEASURED = 58
#: BCH codes the predicted size may use: correcting one or two bit errors.
ECC_CHOICES = (2, 1)
#: A variable this visible or less is weak: it reads, but a wider bound would help most.
WEAK = 0.3
#: A shape whose removal changes the render's luminance by less than this is faint: its edges
#: barely differ from what lies around them (a colour close to its neighbour's, or to paper).
FAINT = 0.2
#: What training kept of a colour drawing's plan (payload bits, ``train --payload-bits auto``) on
#: the eleven colour drawings measured (``bench/README.md``, *Reading colour prints* and *Colour
#: drawings nobody chose*): least, median and most. The plan counts shapes that show, not how
#: faint their edges are in a photo, so it overshoots colour drawings by up to three times.
COLOUR_KEPT = (0.31, 0.64, 1.0)
#: A colour drawing found in less than this share of simulated hard photos
#: (:mod:`deepmorph_detect.findable`) is called out: 3 of 20 colour drawings nobody chose fell
#: below it (``bench/README.md``, *Finding colour prints*; median 93.8 %).
FOUND_ENOUGH = 0.8


@dataclass(frozen=True)
class ElementCapacity:
    """What one element contributes.

    Attributes:
        index: its place among the drawing's primitives (0 first).
        line: its line in the SVG.
        kind: its primitive kind.
        variables: its morph variables.
        visible: how many of them a renderer shows.
        weak: how many of those show only a little (a wider ``dm:move`` helps most here).
        contrast: the largest luminance change the shape makes to the render
            (:meth:`~deepmorph_core.morphable.MorphableDrawing.contrast`): 1 for black on white.
    """

    index: int
    line: int | None
    kind: str
    variables: int
    visible: int
    weak: int
    contrast: float = 1.0

    @property
    def where(self) -> str:
        """``shape 3 (<path>, line 12)``: how messages name it."""
        return f"shape {self.index} (<{self.kind}>, line {self.line})"


@dataclass(frozen=True)
class CapacityReport:
    """The predicted capacity of a drawing.

    Attributes:
        n_variables: ``N_v``.
        visible: variables a renderer shows.
        readable_groups: visible variables with look-alikes counted once.
        code_bits: code bits a decoder is predicted to read reliably.
        payload_bits: the largest payload predicted to read from 99 % of captures (0: none).
        codec: its code (``None`` when no payload fits).
        elements: per element, what it contributes (in document order).
        static: lines of elements that do not morph at all (fixed, or no bounds).
        visible_mask: per variable, whether it is counted as visible (not in the JSON).
        print_px: the print width the prediction is for (``train --pixels``); ``None``: the
            default reading in the decoder's 96-px frame.
        channel_payload: the payload a linear reading of photos of the print carries at 99 % at
            :data:`PIXELS_MEASURED` px (:func:`deepmorph_core.channel.read_channel`), which the
            plan for ``--pixels`` models starts from; ``None``: not measured.
        colour: the drawing is in colour: its plan overshoots (:data:`COLOUR_KEPT`), and
            :meth:`limits` says by how much.
        found: in how many simulated hard photos the photo chain found the print, of how many
            (:func:`deepmorph_detect.findable.findability`); ``None``: not simulated.
        crc_bits: the CRC the user fixed (``--crc``); ``None``: the plan's (a colour plan's may be
            longer than 8, :func:`plan_code`).
    """

    n_variables: int
    visible: int
    readable_groups: int
    code_bits: int
    payload_bits: int
    codec: CodecSpec | None
    elements: list[ElementCapacity] = field(default_factory=list)
    static: list[int | None] = field(default_factory=list)
    visible_mask: list[bool] = field(default_factory=list)
    print_px: int | None = None
    channel_payload: int | None = None
    colour: bool = False
    found: tuple[int, int] | None = None
    crc_bits: int | None = None

    def fits(self, spec: CodecSpec) -> bool:
        """Whether a code is within the prediction."""
        return spec.code_bits <= self.code_bits

    def limits(self) -> list[str]:
        """What limits the capacity, and where loosening bounds would help, in lines."""
        lines = []
        uncapped = _code_bits_of_groups(self.readable_groups)
        if at_pixels(self.print_px) and self.channel_payload is not None:
            lines.append(
                f"photos of a print {PIXELS_MEASURED} px wide show its moves well enough for a linear reading to "
                f"carry {self.channel_payload} payload bits at 99 %; a trained model reads about "
                f"{CHANNEL_SHARE:.2f} of that"
            )
            share = channel_share(self.channel_payload)  # payload bits with CRC-8, as the plan's before its CRC
            if share > (0 if self.codec is None else default_crc_code(self.codec).payload_bits):
                lines.append(
                    f"the prediction stops at {LARGEST_CODE_MEASURED} code bits, the largest code measured to read "
                    f"({share} payload bits would need more); above it only a training's validation says what reads"
                )
        elif uncapped > LARGEST_CODE_MEASURED:
            lines.append(
                f"the prediction stops at {LARGEST_CODE_MEASURED} code bits, the largest code measured to read on a "
                f"crowded drawing ({self.readable_groups} readable variables would give {uncapped}); above it only "
                "a training's validation says what reads"
            )
        if self.colour and self.payload_bits:
            least, median, most = COLOUR_KEPT
            lines.append(
                f"a colour drawing's plan counts the shapes that show, not how faint their edges are in a photo: "
                f"on eleven colour drawings training kept {least:.2f}-{most:.2f} of it (median {median:.2f}); "
                "`train --payload-bits auto` cuts a code its renders do not read"
            )
        if (
            self.colour
            and self.crc_bits is None
            and self.codec is not None
            and default_crc_code(self.codec) != self.codec
        ):
            lines.append(
                f"a colour drawing's payload gives bits to a CRC of {self.codec.crc_bits} (black ink: 8): wrong words "
                "from photos of colour prints pass the photo chain's checks far more often; training counts this "
                "model's wrong payloads and may give the CRC more (six colour drawings measured needed 10-15 bits)"
            )
        if self.found is not None and self.found[0] < FOUND_ENOUGH * self.found[1]:
            lines.append(
                f"the photo chain found the print in only {self.found[0]} of {self.found[1]} simulated hard photos "
                "(colour drawings measured: median 93.8 %): prints of it will often go unfound in hard light "
                "(the least found measured: one pale rounded shape, a thin flag, a pale outline beside a dark badge)"
            )
        hidden = self.n_variables - self.visible
        if hidden:
            lines.append(
                f"{hidden} of {self.n_variables} variables change nothing a renderer shows (points moving along "
                "their own straight lines, under other ink, or on faint shapes)"
            )
        twins = self.visible - self.readable_groups
        if twins > 0:
            what = "visible variable repeats" if twins == 1 else "visible variables repeat"
            lines.append(f"{twins} {what} another's effect (counted once)")
        if self.static:
            where = ", ".join(str(line) for line in self.static[:8]) + (" ..." if len(self.static) > 8 else "")
            lines.append(f"{len(self.static)} elements do not morph (dm:fixed or no bounds): lines {where}")
        hiding = sorted((e for e in self.elements if e.visible < e.variables), key=lambda e: e.visible - e.variables)
        for e in hiding[:5]:
            lines.append(
                f"{e.where}: {e.variables - e.visible} of its {e.variables} variables change nothing a renderer shows"
                + (" clearly (a faint shape)" if e.contrast < FAINT else "")
            )
        faint = sorted((e for e in self.elements if e.contrast < FAINT), key=lambda e: e.contrast)
        for e in faint[:5]:
            lines.append(
                f"{e.where}: its edges differ from what lies around them by only {e.contrast:.2f} in luminance"
                " (black on white: 1); a colour further from its neighbours' carries more"
            )
        weakest = sorted((e for e in self.elements if e.weak), key=lambda e: -e.weak)[:5]
        for e in weakest:
            lines.append(
                f"{e.where}: {e.weak} of its {e.visible} visible variables show only a little; "
                "a wider dm:move there adds capacity"
            )
        return lines

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        del data["visible_mask"]
        data["codec"] = None if self.codec is None else {**self.codec.model_dump(), "code_bits": self.codec.code_bits}
        data["limits"] = self.limits()
        return data


def at_pixels(print_px: int | None) -> bool:
    """Whether a model trained for prints ``print_px`` wide is planned from its channel, measured
    at :data:`PIXELS_MEASURED` px."""
    return print_px is not None and print_px >= PIXELS_MEASURED


def plan_ecc(print_px: int | None = None) -> tuple[int, ...]:
    """The BCH strengths the plan for a model trained for prints ``print_px`` wide chooses from:
    :data:`ECC_AT_PIXELS` from :data:`PIXELS_MEASURED` up, else :data:`ECC_CHOICES`."""
    return ECC_AT_PIXELS if at_pixels(print_px) else ECC_CHOICES


def code_bits_for(readable_groups: int) -> int:
    """Code bits the default training's decoder reads reliably from ``readable_groups`` groups,
    at most :data:`LARGEST_CODE_MEASURED`."""
    return min(_code_bits_of_groups(readable_groups), LARGEST_CODE_MEASURED)


def _code_bits_of_groups(readable_groups: int) -> int:
    """:data:`CODE_BITS_PER_GROUP` times the groups, before the cap (rounded down)."""
    return int(math.floor(CODE_BITS_PER_GROUP * readable_groups + 1e-9))


def largest_payload(
    code_bits: int, crc_bits: int | None = None, ecc: tuple[int, ...] = ECC_CHOICES
) -> CodecSpec | None:
    """The code of the largest payload whose code fits in ``code_bits`` (a BCH code correcting
    ``ecc`` errors, by default one or two; the default CRC unless ``crc_bits``); ``None`` when
    none fits."""
    best: CodecSpec | None = None
    for payload in range(1, MAX_PAYLOAD_BITS + 1):
        for spec in payload_codes(payload, crc_bits, ecc):
            if spec.code_bits <= code_bits and (best is None or payload > best.payload_bits):
                best = spec
    return best


def payload_codes(
    payload_bits: int, crc_bits: int | None = None, ecc: tuple[int, ...] = ECC_CHOICES
) -> list[CodecSpec]:
    """The codes of a payload with each BCH strength in ``ecc`` that exists (in ``ecc``'s order;
    the default CRC unless ``crc_bits``)."""
    found = []
    for t in ecc:
        try:
            found.append(choose_codec(payload_bits, crc_bits, t))
        except DeepMorphError:
            continue
    return found


def predict(
    drawing: MorphableDrawing,
    width: int = 96,
    crc_bits: int | None = None,
    ecc: tuple[int, ...] | None = None,
    print_px: int | None = None,
) -> CapacityReport:
    """Predict what ``drawing`` carries, from renders of each variable at both ends of its
    range (real renderer for visibility, soft rasterizer for look-alikes) at ``width`` pixels,
    with codes of ``crc_bits`` (default: the codec's choice) and BCH codes correcting ``ecc``
    bit errors (default: :func:`plan_ecc` ``print_px``), for a model trained for prints
    ``print_px`` wide in the photo (``train --pixels``; ``None``: the default reading). From
    :data:`PIXELS_MEASURED` px up it measures the drawing's channel too (:func:`with_channel`)."""
    n = drawing.n_variables
    if n == 0:
        return CapacityReport(0, 0, 0, 0, 0, None, [], [p.line for p in drawing.drawing.primitives], print_px=print_px)
    visibility = drawing.visibility(width)
    contrast = drawing.contrast(width)
    # a faint shape's moves are as faint as its edges: its variables are not counted as readable
    faint = np.array([v.owner == "primitive" and contrast[v.index] < FAINT for v in drawing.variables], dtype=bool)
    shown = (visibility > INVISIBLE) & ~faint
    groups = twin_groups(drawing.effects(drawing.rasterizer(width)))
    readable = sum(1 for members, _ in groups if shown[members].any())
    per_prim: dict[int, list[int]] = {}
    for k, var in enumerate(drawing.variables):
        if var.owner == "primitive":
            per_prim.setdefault(var.index, []).append(k)
    elements, static = [], []
    for prim in drawing.drawing.primitives:
        ks = per_prim.get(prim.index, [])
        if not ks:
            static.append(prim.line)
            continue
        vis = np.where(faint[np.array(ks)], 0.0, visibility[np.array(ks)])
        elements.append(
            ElementCapacity(
                prim.index,
                prim.line,
                prim.primitive.kind,
                len(ks),
                int((vis > INVISIBLE).sum()),
                int(((vis > INVISIBLE) & (vis < WEAK)).sum()),
                round(float(contrast[prim.index]), 3),
            )
        )
    code_bits, spec = _planned_code(readable, None, crc_bits, ecc, colour=bool(drawing.colour))
    report = CapacityReport(
        n,
        int(shown.sum()),
        readable,
        code_bits,
        0 if spec is None else spec.payload_bits,
        spec,
        elements,
        static,
        [bool(v) for v in shown],
        colour=bool(drawing.colour),
        crc_bits=crc_bits,
    )
    if at_pixels(print_px):
        report = for_print(with_channel(report, drawing), print_px, crc_bits, ecc)
    return report


def with_channel(report: CapacityReport, drawing: MorphableDrawing, measure: bool = True) -> CapacityReport:
    """``report`` (``drawing``'s :func:`predict`) with the drawing's channel measured at
    :data:`PIXELS_MEASURED` px (:func:`deepmorph_core.channel.read_channel`, about half a
    minute), which plans for ``--pixels`` models need; as it is when already measured. The
    measurement is kept for the drawing with the same bounds and reading channel, so that a
    process that plans it again (the studio's capacity tab, each time it is opened) measures it
    once. ``measure`` false: only a measurement this process kept is filled in (the studio
    measures in the background)."""
    if report.channel_payload is not None:
        return report
    if report.readable_groups == 0:
        return replace(report, channel_payload=0)
    key = channel_key(drawing)
    if key not in _CHANNELS:
        if not measure:
            return report
        from deepmorph_core.channel import read_channel

        _CHANNELS[key] = read_channel(drawing, PIXELS_MEASURED).payload_bits
        while len(_CHANNELS) > _CHANNELS_KEPT:
            _CHANNELS.pop(next(iter(_CHANNELS)))
    return replace(report, channel_payload=_CHANNELS[key])


#: Measured channels' payloads by :func:`channel_key`, the last :data:`_CHANNELS_KEPT`.
_CHANNELS: dict[str, int] = {}
_CHANNELS_KEPT = 16


def channel_key(drawing: MorphableDrawing) -> str:
    """A digest of what a channel measurement depends on: the drawing as written, the ends of
    every variable's range (its bounds) and the channel it is read in."""
    ends = drawing.values_from_unit(torch.stack([torch.zeros(drawing.n_variables), torch.ones(drawing.n_variables)]))
    digest = hashlib.sha256(drawing.to_svg(drawing.neutral_values()[0]).encode("utf-8"))
    digest.update(ends.detach().double().numpy().tobytes())
    digest.update(np.asarray(drawing.channel, dtype=np.float64).tobytes())
    return digest.hexdigest()


def for_print(
    report: CapacityReport, print_px: int | None, crc_bits: int | None = None, ecc: tuple[int, ...] | None = None
) -> CapacityReport:
    """``report``'s prediction for a model trained for prints ``print_px`` wide instead (the
    same readable groups and channel; no new renders), with codes of ``crc_bits`` and ``ecc``.
    From :data:`PIXELS_MEASURED` px up the report must hold the channel (:func:`with_channel`)."""
    code_bits, spec = _planned_code(
        report.readable_groups, print_px, crc_bits, ecc, report.channel_payload, colour=report.colour
    )
    payload = 0 if spec is None else spec.payload_bits
    return replace(report, code_bits=code_bits, payload_bits=payload, codec=spec, print_px=print_px, crc_bits=crc_bits)


def payload_for_width(
    report: CapacityReport, pixels: float, needs_px: float, crc_bits: int | None = None
) -> tuple[int | None, int | None]:
    """The payload bits a print ``pixels`` wide in the photo carries, and the ``--pixels`` to
    train its model with (``None``: the default training): ``(None, None)`` below ``needs_px``,
    the narrowest print a default model reads; from :data:`PIXELS_MEASURED` up, a model trained
    for that width (it reads wider prints too), its payload ``None`` while ``report``'s channel is
    not measured (:func:`with_channel`); between, the default prediction (nothing else was
    measured there)."""
    if pixels < needs_px:
        return None, None
    if at_pixels(int(pixels)):
        if report.channel_payload is None:
            return None, PIXELS_MEASURED
        return for_print(report, PIXELS_MEASURED, crc_bits).payload_bits, PIXELS_MEASURED
    return for_print(report, None, crc_bits).payload_bits, None


def _planned_code(
    readable_groups: int,
    print_px: int | None,
    crc_bits: int | None,
    ecc: tuple[int, ...] | None,
    channel_payload: int | None = None,
    colour: bool = False,
) -> tuple[int, CodecSpec | None]:
    """The code bits a model trained for prints ``print_px`` wide reads reliably, and the largest
    payload's code in them (BCH strengths ``ecc``, default :func:`plan_ecc`'s): for the default
    training, :data:`CODE_BITS_PER_GROUP` per readable group; from :data:`PIXELS_MEASURED` px,
    :data:`CHANNEL_SHARE` of ``channel_payload``, the payload of the drawing's channel, in at most
    :data:`LARGEST_CODE_MEASURED` code bits (no larger code was measured to read at any width: a
    colour emoji's channel of 213 bits would otherwise plan 102). Never less than the default
    training's plan: a ``--pixels`` model reads prints at least as well. A ``colour`` drawing's
    code then gets its longer CRC (:func:`plan_code`)."""
    bits, spec = _uncoloured_plan(readable_groups, print_px, crc_bits, ecc, channel_payload)
    return bits, None if spec is None else plan_code(spec, colour, crc_bits)


def _uncoloured_plan(
    readable_groups: int,
    print_px: int | None,
    crc_bits: int | None,
    ecc: tuple[int, ...] | None,
    channel_payload: int | None,
) -> tuple[int, CodecSpec | None]:
    """:func:`_planned_code` before a colour drawing's longer CRC."""
    default_bits = code_bits_for(readable_groups)
    default = largest_payload(default_bits, crc_bits, ECC_CHOICES if ecc is None else ecc)
    if not at_pixels(print_px):
        return default_bits, default
    if channel_payload is None:
        raise ValueError(f"a plan for prints {print_px} px wide needs the drawing's channel (capacity.with_channel)")
    spec = _largest_code_within(channel_share(channel_payload), crc_bits, ecc or ECC_AT_PIXELS, LARGEST_CODE_MEASURED)
    if default is not None and (spec is None or default.payload_bits > spec.payload_bits):
        return default_bits, default
    return (0 if spec is None else spec.code_bits), spec


def channel_share(channel_payload: int) -> int:
    """The payload bits a ``--pixels`` model is planned from a channel of ``channel_payload``:
    :data:`CHANNEL_SHARE` of it, rounded down (before any code is fitted to it)."""
    return math.floor(CHANNEL_SHARE * channel_payload + 1e-9)


def _largest_code_within(
    payload_bits: int, crc_bits: int | None, ecc: tuple[int, ...], code_bits: int
) -> CodecSpec | None:
    """The code (BCH strengths ``ecc``, the first that exists) of the largest payload of at most
    ``payload_bits`` whose code has at most ``code_bits``; ``None`` when there is none."""
    for payload in range(min(payload_bits, MAX_PAYLOAD_BITS), 0, -1):
        codes = [spec for spec in payload_codes(payload, crc_bits, ecc) if spec.code_bits <= code_bits]
        if codes:
            return codes[0]
    return None


def plan_code(spec: CodecSpec, colour: bool, crc_bits: int | None = None) -> CodecSpec:
    """The code a plan gives: ``spec`` (a code with the codec's default CRC), or for a ``colour``
    drawing whose CRC is DeepMorph's (``crc_bits`` ``None``) the same code with payload bits given
    to the longest CRC of at most :data:`COLOUR_CRC` bits that leaves one
    (:func:`~deepmorph_core.codec.with_crc`): 16 payload bits and CRC-8 become 12 and CRC-12, 3
    and CRC-8 become 1 and CRC-10, a payload above 32 bits keeps its CRC-16."""
    if not colour or crc_bits is not None:
        return spec
    width = max((w for w in widths_within(spec) if w <= COLOUR_CRC), default=spec.crc_bits)
    return spec if width == spec.crc_bits else with_crc(spec, width)


def default_crc_code(spec: CodecSpec) -> CodecSpec:
    """The code :func:`plan_code` made ``spec`` from (a CRC of 10-:data:`COLOUR_CRC` bits back to
    CRC-8, its bits back to the payload); any other code as it is. Cuts of a planned code start
    from it (:mod:`deepmorph.training.code_shrink`)."""
    if 8 < spec.crc_bits <= COLOUR_CRC:
        return with_crc(spec, 8)
    return spec


def size_warning(spec: CodecSpec, report: CapacityReport, label: str) -> str | None:
    """Why payloads of ``spec`` are unlikely to read, when its code is above the prediction,
    with the largest size that fits; ``None`` when it is within."""
    if report.fits(spec):
        return None
    if report.codec is None:
        advice = "no payload is predicted to read reliably; let more of the drawing morph (dm: bounds, --move)"
    else:
        bits = report.payload_bits
        advice = f"the largest predicted to read is {bits} bit{'' if bits == 1 else 's'} (--payload-bits auto)"
    return (
        f"{label}: a {spec.payload_bits}-bit payload needs {spec.code_bits} code bits but the drawing's "
        f"{report.readable_groups} readable variables are predicted to carry {report.code_bits}; expect fewer "
        f"than 99 % of payloads to read; {advice}"
    )


__all__ = [
    "CODE_BITS_PER_GROUP",
    "CHANNEL_SHARE",
    "ECC_AT_PIXELS",
    "COLOUR_CRC",
    "COLOUR_KEPT",
    "LARGEST_CODE_MEASURED",
    "PIXELS_MEASURED",
    "CapacityReport",
    "ElementCapacity",
    "at_pixels",
    "code_bits_for",
    "channel_key",
    "plan_ecc",
    "with_channel",
    "for_print",
    "payload_for_width",
    "largest_payload",
    "payload_codes",
    "plan_code",
    "default_crc_code",
    "predict",
    "size_warning",
]
