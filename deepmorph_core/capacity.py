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
(:mod:`deepmorph_core.registration`), and carries more: :data:`CODE_BITS_PER_GROUP_AT_PIXELS`
code bits per readable group, up to :data:`LARGEST_CODE_AT_PIXELS`, in codes correcting two bit
errors (:data:`ECC_AT_PIXELS`, the codes it was measured with), fitted on two drawings of
``bench/pixels_panel.py``'s rule and checked on four more (``bench/README.md``). The plan can
overshoot a drawing whose outline aligns poorly (``codepen``: 20 payload bits planned, 14 read);
``train --payload-bits auto`` then cuts the code on fresh renders when training ends
(``deepmorph.training.code_shrink``). It can also undershoot, which nothing catches: ``cloud-snow``
(20 groups) is planned 7 payload bits and reads 15, ``cpu`` is planned 24 and reads 30. Below
that width nothing larger was measured, and the 96-px figure stands.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from deepmorph_core.codec import CodecSpec, choose_codec
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.morphable import INVISIBLE, MorphableDrawing
from deepmorph_core.networks import twin_groups
from deepmorph_core.payload import MAX_PAYLOAD_BITS

#: Code bits a decoder reads reliably per readable group (see the module docstring).
CODE_BITS_PER_GROUP = 0.70
#: Code bits per readable group of a model trained with ``--pixels`` of at least
#: :data:`PIXELS_MEASURED` (see the module docstring).
CODE_BITS_PER_GROUP_AT_PIXELS = 1.25
#: The print width in photo pixels :data:`CODE_BITS_PER_GROUP_AT_PIXELS` was measured at.
PIXELS_MEASURED = 200
#: BCH codes the prediction at :data:`PIXELS_MEASURED` uses: correcting two bit errors.
ECC_AT_PIXELS = (2,)
#: The largest code the prediction at :data:`PIXELS_MEASURED` gives: the largest measured to read
#: on ``codesandbox`` (48 readable groups: 44 code bits from 100 % of close-ups, 52 from 95 %);
#: ``battery-charging`` read 44 from 98.5-99 %.
LARGEST_CODE_AT_PIXELS = 44
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

    def fits(self, spec: CodecSpec) -> bool:
        """Whether a code is within the prediction."""
        return spec.code_bits <= self.code_bits

    def limits(self) -> list[str]:
        """What limits the capacity, and where loosening bounds would help, in lines."""
        lines = []
        uncapped = _code_bits_of_groups(self.readable_groups, self.print_px)
        largest = figures_for(self.print_px).largest_code
        if uncapped > largest:
            lines.append(
                f"the prediction stops at {largest} code bits, the largest code measured to read on a "
                f"crowded drawing ({self.readable_groups} readable variables would give {uncapped}); above it only "
                "a training's validation says what reads"
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


@dataclass(frozen=True)
class ReadingFigures:
    """The measured figures a plan uses for one kind of model.

    Attributes:
        bits_per_group: code bits read reliably per readable group.
        largest_code: the largest code the plan gives.
        ecc: the BCH strengths the plan chooses from.
    """

    bits_per_group: float
    largest_code: int
    ecc: tuple[int, ...]


#: The default training: every print read in the decoder's 96-px frame.
FIGURES_96 = ReadingFigures(CODE_BITS_PER_GROUP, LARGEST_CODE_MEASURED, ECC_CHOICES)
#: A model trained with ``--pixels`` of at least :data:`PIXELS_MEASURED`.
FIGURES_AT_PIXELS = ReadingFigures(CODE_BITS_PER_GROUP_AT_PIXELS, LARGEST_CODE_AT_PIXELS, ECC_AT_PIXELS)


def at_pixels(print_px: int | None) -> bool:
    """Whether a model trained for prints ``print_px`` wide is planned with the figures measured
    at :data:`PIXELS_MEASURED` px."""
    return print_px is not None and print_px >= PIXELS_MEASURED


def figures_for(print_px: int | None = None) -> ReadingFigures:
    """The figures of a model trained for prints ``print_px`` wide (``None``: the default
    training): :data:`FIGURES_AT_PIXELS` from :data:`PIXELS_MEASURED` up, else :data:`FIGURES_96`."""
    return FIGURES_AT_PIXELS if at_pixels(print_px) else FIGURES_96


def code_bits_for(readable_groups: int, print_px: int | None = None) -> int:
    """Code bits a decoder reads reliably from ``readable_groups`` groups of a model trained for
    prints ``print_px`` wide (:func:`figures_for`), at most its largest code."""
    return min(_code_bits_of_groups(readable_groups, print_px), figures_for(print_px).largest_code)


def _code_bits_of_groups(readable_groups: int, print_px: int | None = None) -> int:
    """:func:`figures_for`'s code bits per group, before the cap (rounded down)."""
    return int(math.floor(figures_for(print_px).bits_per_group * readable_groups + 1e-9))


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
    bit errors (default: :func:`figures_for` ``print_px``), for a model trained for prints
    ``print_px`` wide in the photo (``train --pixels``; ``None``: the default reading)."""
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
    code_bits, spec = _planned_code(readable, print_px, crc_bits, ecc)
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
    return CapacityReport(
        n,
        int(shown.sum()),
        readable,
        code_bits,
        0 if spec is None else spec.payload_bits,
        spec,
        elements,
        static,
        [bool(v) for v in shown],
        print_px,
    )


def for_print(
    report: CapacityReport, print_px: int | None, crc_bits: int | None = None, ecc: tuple[int, ...] | None = None
) -> CapacityReport:
    """``report``'s prediction for a model trained for prints ``print_px`` wide instead (the
    same readable groups; no new renders), with codes of ``crc_bits`` and ``ecc``."""
    code_bits, spec = _planned_code(report.readable_groups, print_px, crc_bits, ecc)
    payload = 0 if spec is None else spec.payload_bits
    return replace(report, code_bits=code_bits, payload_bits=payload, codec=spec, print_px=print_px)


def payload_for_width(
    report: CapacityReport, pixels: float, needs_px: float, crc_bits: int | None = None
) -> tuple[int | None, int | None]:
    """The payload bits a print ``pixels`` wide in the photo carries, and the ``--pixels`` to
    train its model with (``None``: the default training): ``(None, None)`` below ``needs_px``,
    the narrowest print a default model reads; from :data:`PIXELS_MEASURED` up, a model trained
    for that width (it reads wider prints too); between, the default prediction (nothing else
    was measured there)."""
    if pixels < needs_px:
        return None, None
    if at_pixels(int(pixels)):
        return for_print(report, PIXELS_MEASURED, crc_bits).payload_bits, PIXELS_MEASURED
    return for_print(report, None, crc_bits).payload_bits, None


def _planned_code(
    readable_groups: int, print_px: int | None, crc_bits: int | None, ecc: tuple[int, ...] | None
) -> tuple[int, CodecSpec | None]:
    """The code bits ``readable_groups`` carry for prints ``print_px`` wide, and the largest
    payload's code in them (BCH strengths ``ecc``, default :func:`figures_for`'s). Never less than the
    default reading's plan: a ``--pixels`` model reads prints at least as well (a crowded
    drawing's 96-px plan, in a BCH t = 1 code, can carry more than the capped t = 2 one)."""
    code_bits = code_bits_for(readable_groups, print_px)
    spec = largest_payload(code_bits, crc_bits, figures_for(print_px).ecc if ecc is None else ecc)
    if at_pixels(print_px):
        default_bits, default = _planned_code(readable_groups, None, crc_bits, ecc)
        if default is not None and (spec is None or default.payload_bits > spec.payload_bits):
            return default_bits, default
    return code_bits, spec


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
    "CODE_BITS_PER_GROUP_AT_PIXELS",
    "ECC_AT_PIXELS",
    "FIGURES_96",
    "FIGURES_AT_PIXELS",
    "LARGEST_CODE_AT_PIXELS",
    "LARGEST_CODE_MEASURED",
    "PIXELS_MEASURED",
    "CapacityReport",
    "ElementCapacity",
    "ReadingFigures",
    "at_pixels",
    "code_bits_for",
    "figures_for",
    "for_print",
    "payload_for_width",
    "largest_payload",
    "payload_codes",
    "predict",
    "size_warning",
]
