"""How often a trained model's photos could give a wrong payload, and a CRC long enough to keep it rare.

A wrong payload takes three things: a misread that the error correction carries to another code
word, that word's CRC passing by chance (one in ``2**crc_bits``), and the payload check (the
morph's fit, the bits' evidence) failing to refuse it. The last is the drawing's own: a thin
stroke read in hard light fits a wrong word's morph nearly as well as the right one's, a bold
black outline does not. So the rate is measured for each model after its validation, where the
photo chain reads hard close-ups of fresh payloads at the trained print width with
:data:`TRUST_UNCHECKED_BITS` of the CRC's bits left unchecked
(:func:`~deepmorph_detect.photo_validation.count_wrong_payloads`): each wrong payload seen there
stands for ``2**TRUST_UNCHECKED_BITS`` (64) fewer with the whole CRC.

Where that estimate is above :data:`TRUST_TARGET`, a payload sized by training (``--payload-bits
auto``, the CRC left to DeepMorph) gives bits over to a longer CRC (:data:`~deepmorph_core.codec.
CRC_WIDTHS`): the payload and its CRC fill the same code bits, so the networks, and all they
read, stay as they are, and each bit given halves the rate. Where the payload cannot give enough,
or its size or CRC is the user's, training warns with the estimate instead.
"""

from __future__ import annotations

from collections.abc import Callable

from deepmorph_core.bundle import TrustRecord, per_10k
from deepmorph_core.codec import CodecSpec, widths_within, with_crc
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.photo_validation import close_up_width, count_wrong_payloads
from deepmorph_detect.scenes import CLOSE_UP_SIZE

#: Wrong payloads per read a model may give in hard close-ups at its trained width: 0.1 in
#: 10,000, so that 10,000 reads give none nine times in ten.
TRUST_TARGET = 1e-5
#: The CRC bits left unchecked while the rate is measured (all but these are checked: two of
#: CRC-8's): a wrong word passes 64 times as often as with the whole CRC, whatever its width, so
#: one wrong payload in 600 close-ups is 0.26 in 10,000, a wrong word passed seldom ends a search
#: early (held-out colour drawings at ``--pixels 200``: 1-66 in 1000, ``bench/trust.py``), and
#: the close-ups take as long to count with CRC-16 as with CRC-8.
TRUST_UNCHECKED_BITS = 6
#: Hard close-ups read by the measurement (0.2-0.9 s each for a colour drawing on one core).
TRUST_SAMPLES = 600
TRUST_SEVERITY = "hard"
#: A model is counted by default only where its validation read at least this share of its
#: close-ups: one that reads fewer has its warning, and a misreading model's close-ups take long.
COUNTED_FROM = 0.9
#: The measurement's payloads and photos draw from the training's seed plus this.
TRUST_SEED_OFFSET = 4217


def trust_samples(setting: int | None, colour: bool) -> int:
    """The close-ups a training measures its wrong payloads on: ``setting`` where the user set
    it; else :data:`TRUST_SAMPLES` for a colour drawing and none for black ink. Every colour
    drawing measured so was above :data:`TRUST_TARGET` with CRC-8 (0.16-10 in 10,000); black ink
    read 10,000 medium and hard close-ups at each size without a wrong payload, and its counts
    here were 0 and 1 in 1000 (``bench/README.md``), where one count would cost two payload bits."""
    if setting is not None:
        return setting
    return TRUST_SAMPLES if colour else 0


def measure_trust(model: DeepMorphModel, samples: int, seed: int, workers: int = 1) -> TrustRecord:
    """Count the wrong payloads of ``samples`` hard close-ups of ``model`` at its trained width,
    :data:`TRUST_UNCHECKED_BITS` of the CRC's bits left unchecked, read by ``workers`` processes."""
    spec = model.codec.spec
    checked = max(0, spec.crc_bits - TRUST_UNCHECKED_BITS)
    seed += TRUST_SEED_OFFSET
    count = count_wrong_payloads(model, samples, seed, checked, TRUST_SEVERITY, workers=workers)
    return TrustRecord(
        severity=TRUST_SEVERITY,
        print_px=round(close_up_width(model) * sum(CLOSE_UP_SIZE) / 2),
        samples=samples,
        crc_checked=checked,
        wrong=count.wrong,
        crc_bits=(spec.crc_bits, spec.crc_bits),
        payload_bits=(spec.payload_bits, spec.payload_bits),
        seconds=count.seconds,
    )


def crc_for(record: TrustRecord, spec: CodecSpec) -> int | None:
    """The shortest CRC within ``spec``'s code (:func:`widths_within`) whose estimated rate meets
    :data:`TRUST_TARGET`; ``None`` where none does."""
    return next((w for w in widths_within(spec) if record.wrong_per_read(w) <= TRUST_TARGET), None)


def crc_needed(record: TrustRecord, spec: CodecSpec) -> int:
    """The CRC :func:`lengthen_crc` gives ``spec``'s code: :func:`crc_for`'s, or where none meets
    :data:`TRUST_TARGET` the most the payload can give (all but one bit, within the widths there
    are)."""
    width = crc_for(record, spec)
    return widths_within(spec)[-1] if width is None else width


def lengthen_crc(model: DeepMorphModel, record: TrustRecord) -> TrustRecord:
    """Give ``model``'s payload bits over to the CRC its measured rate needs, where training
    sized the payload and the user left the CRC to it; the record, with the code now."""
    auto = model.meta.record.payload_auto
    spec = model.codec.spec
    if auto is None or auto.crc_bits is not None or record.wrong_per_read() <= TRUST_TARGET:
        return record
    width = crc_needed(record, spec)
    if width <= spec.crc_bits:
        return record
    longer = with_crc(spec, width)
    model.use_code(longer)
    return record.model_copy(
        update={"crc_bits": (spec.crc_bits, width), "payload_bits": (spec.payload_bits, longer.payload_bits)}
    )


def trust_warning(record: TrustRecord, label: str) -> str | None:
    """A warning where the estimated rate is still above :data:`TRUST_TARGET`; else ``None``."""
    if record.wrong_per_read() <= TRUST_TARGET:
        return None
    return (
        f"{label}: an estimated {per_10k(record.wrong_per_read())} wrong payloads per 10,000 hard photos "
        f"({record.wrong} in {record.samples} close-ups read with {record.crc_checked} CRC bits checked); "
        f"{TRUST_TARGET * 1e4:g} is the aim. A longer CRC (--crc 16) or a smaller payload makes them rarer"
    )


def check_trust(
    model: DeepMorphModel,
    samples: int,
    seed: int,
    label: str,
    warn: Callable[[str], None],
    workers: int = 1,
) -> TrustRecord | None:
    """Measure ``model``'s wrong payloads on ``samples`` hard close-ups (none: nothing) read by
    ``workers`` processes, lengthen its CRC where that is the model's to choose
    (:func:`lengthen_crc`), store the record in its metadata and warn where the rate is still
    above :data:`TRUST_TARGET`."""
    if samples <= 0 or not model.codec.spec.crc_bits:
        return None
    record = lengthen_crc(model, measure_trust(model, samples, seed, workers))
    model.meta.trust = record
    warning = trust_warning(record, label)
    if warning:
        warn(warning)
    return record


__all__ = [
    "COUNTED_FROM",
    "TRUST_SAMPLES",
    "TRUST_TARGET",
    "TRUST_UNCHECKED_BITS",
    "check_trust",
    "crc_for",
    "crc_needed",
    "lengthen_crc",
    "measure_trust",
    "trust_samples",
    "trust_warning",
]
