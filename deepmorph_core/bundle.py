"""Model bundles: one ``.dmm`` file holding everything needed to encode and decode.

The file is a safetensors file. Its tensors are the network weights (and, in a training
checkpoint, the optimiser state and random-generator states). Its metadata holds one JSON
document, validated by :class:`BundleMeta`, with the drawing's SVG text, the bound defaults,
the codec, raster size, decoder architecture, augmentation and training configuration, the
versions that wrote it and the training record. Loading never unpickles and never runs code:
safetensors reads raw tensors, pydantic validates the JSON, and anything else (a corrupt,
truncated or foreign file) is one :class:`~deepmorph_core.errors.DeepMorphError`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import numpy as np
import torch
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError
from safetensors import SafetensorError
from safetensors.torch import load as load_bytes
from safetensors.torch import save as save_bytes
from torch import Tensor

from deepmorph_core.bounds import format_validation_error
from deepmorph_core.codec import CodecSpec
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write
from deepmorph_core.luminance import LUMA_WEIGHTS
from deepmorph_core.networks import DecoderConfig
from deepmorph_core.svg.reader import GEOMETRY_VERSION

FORMAT = "deepmorph-model/1"
_META_KEY = "deepmorph"
MAX_BUNDLE_BYTES = 512 * 1024 * 1024
MAX_HEADER_BYTES = 16 * 1024 * 1024  # the safetensors header: tensor table and our metadata
MAX_NAME_CHARS = 256
MAX_DRAWING_CHARS = 8 * 1024 * 1024
MAX_GRAPHS = 8  # stored ONNX graphs: one per network (the decoder, the detector)
_SHA256 = r"^[0-9a-f]{64}$"
_NAME = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]{0,31}$")]
_SHAPE = Annotated[list[Annotated[int, Field(ge=1, le=1 << 20)]], Field(min_length=1, max_length=8)]


class AutoPayload(BaseModel):
    """A payload sized by ``--payload-bits auto``: what the user fixed of its code (``None``:
    the codec's choice), kept when training shrinks it (:mod:`deepmorph.training.code_shrink`)."""

    model_config = ConfigDict(extra="forbid")

    crc_bits: int | None = None
    ecc_t: int | None = None


class CodeShrink(BaseModel):
    """Training made the code smaller (:mod:`deepmorph.training.code_shrink`).

    Attributes:
        step: the step it happened after.
        payload_bits, code_bits: ``(before, after)``.
        read: the share of code words read before: over the last window of batches at full
            corruption, or of fresh renders (``measured_on``).
        information: the bits of information the code's bits carried there.
        measured_on: ``batches`` (during training) or ``renders`` (when training ended).
    """

    model_config = ConfigDict(extra="forbid")

    step: int = Field(ge=0)
    payload_bits: tuple[int, int]
    code_bits: tuple[int, int]
    read: float
    information: float
    measured_on: Literal["batches", "renders"] = "batches"


class TrainingRecord(BaseModel):
    """What training did: steps, stages, time, and the last measured accuracies.

    Attributes:
        device, threads: where it ran last (``cpu`` or ``cuda``) and torch's CPU threads there.
        world_size: processes that trained it together (torchrun), when last run; ``None`` in
            bundles written before it was recorded.
        global_batch: perturbations per step over all processes; ``None`` where not recorded.
        stopped_early: training ended before its planned steps (``total_steps`` is then the
            step it ended at) because its batches read well enough (``TrainConfig.early_stop``).
        payload_auto: the payload was sized by ``--payload-bits auto`` (``None``: the user's size),
            so training may shrink its code; ``shrunk`` says when it did.
    """

    model_config = ConfigDict(extra="forbid")

    step: int = 0
    total_steps: int = 0
    stage: Literal[1, 2] = 1
    stage2_start: int | None = None
    elapsed_s: float = 0.0
    finished: bool = False
    device: str = "cpu"
    threads: int = 1
    world_size: int | None = Field(default=None, ge=1)
    global_batch: int | None = Field(default=None, ge=1)
    stopped_early: bool = False
    payload_auto: AutoPayload | None = None
    shrunk: list[CodeShrink] = Field(default_factory=list, max_length=64)
    metrics: dict[str, float] = Field(default_factory=dict)


class ValidationRecord(BaseModel):
    """How a trained model read fresh payloads (:mod:`deepmorph.training.validation`).

    Attributes:
        name: which validation (``renders``: real renders under the training corruption;
            ``close-ups``: simulated photos of prints filling the frame, through the photo chain).
        description: what was read, in a line.
        severity: the corruption or photo severity.
        samples: payloads tried.
        read: payloads read whole (the codec vouched and the payload was the one sent).
        wrong: payloads the codec vouched for that were not the one sent.
        bit_accuracy: share of code bits the network read right, over the captures it read.
        missed: captures in which the photo chain found no print (close-ups; ``None`` for renders).
        seconds: how long it took.
    """

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=64)
    description: str = Field(max_length=200)
    severity: str = Field(max_length=16)
    samples: int = Field(ge=1)
    read: int = Field(ge=0)
    wrong: int = Field(ge=0)
    bit_accuracy: float | None = Field(default=None, ge=0.0, le=1.0)
    missed: int | None = Field(default=None, ge=0)
    seconds: float = Field(ge=0.0)

    @property
    def rate(self) -> float:
        """Share of payloads read whole."""
        return self.read / self.samples


class TrustRecord(BaseModel):
    """How often the photo chain could give a wrong payload, measured when training ended
    (``deepmorph.training.trust``): hard close-ups of fresh payloads read with the CRC checked on
    only ``crc_checked`` of its bits, so that each wrong payload they gave stands for
    ``2**(crc_bits - crc_checked)`` fewer with the whole CRC.

    Attributes:
        severity: the close-ups' capture.
        print_px: about how wide the prints were in the close-ups, in camera pixels.
        samples: close-ups read.
        crc_checked: the CRC bits checked while they were read.
        wrong: close-ups that gave a payload other than the one printed.
        crc_bits, payload_bits: ``(when measured, now)``: training gives payload bits over to a
            longer CRC where the measured rate calls for it, and the code stays as large.
        seconds: how long it took.
    """

    model_config = ConfigDict(extra="forbid")

    severity: str = Field(max_length=16)
    print_px: int = Field(ge=1)
    samples: int = Field(ge=1)
    crc_checked: int = Field(ge=0)
    wrong: int = Field(ge=0)
    crc_bits: tuple[int, int]
    payload_bits: tuple[int, int]
    seconds: float = Field(ge=0.0)

    def wrong_per_read(self, crc_bits: int | None = None) -> float:
        """The wrong payloads per read the count implies with a CRC of ``crc_bits`` (default: the
        model's now); 0 where none was seen (:meth:`at_most_per_read` bounds it)."""
        return self._per_read(self.wrong, crc_bits)

    def at_most_per_read(self, crc_bits: int | None = None) -> float:
        """The rate's upper 95 % bound where no wrong payload was seen (three in ``samples``,
        the rule of three); otherwise :meth:`wrong_per_read`."""
        return self._per_read(self.wrong or 3, crc_bits)

    def _per_read(self, count: float, crc_bits: int | None) -> float:
        """``count`` wrong payloads in the close-ups, per read with a CRC of ``crc_bits`` (default: now)."""
        bits = self.crc_bits[1] if crc_bits is None else crc_bits
        return count / self.samples * 2.0 ** (self.crc_checked - bits)

    def describe(self) -> str:
        """One line: what was read, the wrong payloads seen, and the rate they imply now."""
        crc_now = self.crc_bits[1]
        rate = per_10k(self.at_most_per_read())
        estimate = f"an estimated {rate} per 10,000" if self.wrong else f"fewer than {rate} per 10,000 (95 %)"
        line = (
            f"{self.samples} {self.severity} close-ups of prints about {self.print_px} px wide, the CRC checked on "
            f"{self.crc_checked} of its {self.crc_bits[0]} bits: {self.wrong} wrong payloads, so {estimate} with "
            f"CRC-{crc_now}"
        )
        if self.crc_bits[0] != crc_now:
            after = self.payload_bits[1]
            line += (
                f" (lengthened from CRC-{self.crc_bits[0]}: payload {self.payload_bits[0]} -> "
                f"{after} bit{'' if after == 1 else 's'})"
            )
        return f"{line}; {self.seconds:.0f} s"


def per_10k(rate: float) -> str:
    """A rate per read written per 10,000 reads, to two significant figures."""
    value = rate * 1e4
    if value <= 0:
        return "0"
    digits = max(0, 1 - math.floor(math.log10(value)))
    return f"{value:.{digits}f}"


@dataclass
class PayloadTally:
    """Payloads read back, counted as a :class:`ValidationRecord` counts them."""

    read: int = 0
    wrong: int = 0

    def add(self, vouched: Iterable[np.ndarray], sent: np.ndarray) -> None:
        """Count one capture: ``vouched`` are the payloads the codec vouched for in it (none:
        neither read nor wrong), ``sent`` the one hidden. It is read when one of them is
        ``sent``, wrong when none is."""
        vouched = list(vouched)
        if vouched:
            same = any(np.array_equal(payload, sent) for payload in vouched)
            self.read += same
            self.wrong += not same


def _reading_weights(channel: tuple[float, float, float]) -> tuple[float, float, float]:
    if any(w < 0 for w in channel) or abs(sum(channel) - 1.0) > 1e-6:
        raise ValueError("the reading channel's red, green and blue weights must be non-negative and add up to 1")
    return channel


#: red, green and blue weights of a model's reading channel (checked when a bundle loads)
ReadingChannel = Annotated[tuple[float, float, float], AfterValidator(_reading_weights)]


class DetectorMeta(BaseModel):
    """The detector stored beside the codec networks (``deepmorph train-detector``).

    Attributes:
        name: the registered detector that reads these weights (the built-in ``centrenet``
            when a bundle stores no name).
    """

    model_config = ConfigDict(extra="forbid")

    name: str = Field(default="centrenet", min_length=1, max_length=64)
    config: dict[str, Any]
    record: TrainingRecord
    # the runs a fine-tuned detector started from (``train-detector --fine-tune``), oldest first,
    # each ``{"config": ..., "record": ...}`` as above
    earlier: list[dict[str, Any]] = Field(default_factory=list)


class VerifierCheck(BaseModel):
    """A proposal verifier measured on scenes held out of its training: the universal
    detector's proposals there, labelled by the placement nearest each.

    Attributes:
        scenes: scenes looked at (half medium, half hard).
        prints, prints_kept: proposals of this drawing's prints, and those scored at or above
            the threshold.
        others, others_turned_away: proposals of anything else, and those scored below it.
        searched_prints, searched_prints_kept, searched_others, searched_others_turned_away:
            the same among proposals whose quick look is not final: those the verifier decides
            on (the others never reach it).
        lowest_print_score: the lowest score of a print's proposal.
    """

    model_config = ConfigDict(extra="forbid")

    scenes: int = Field(ge=0)
    prints: int = Field(ge=0)
    prints_kept: int = Field(ge=0)
    others: int = Field(ge=0)
    others_turned_away: int = Field(ge=0)
    searched_prints: int = Field(ge=0)
    searched_prints_kept: int = Field(ge=0)
    searched_others: int = Field(ge=0)
    searched_others_turned_away: int = Field(ge=0)
    lowest_print_score: float | None = Field(default=None, ge=0, le=1)


class VerifierMeta(BaseModel):
    """The proposal verifier stored beside the codec networks (``deepmorph train-verifier``,
    :mod:`deepmorph_detect.verifier`): its weights are the tensors ``verifier.*``.

    Attributes:
        threshold: a blind proposal scored below it skips the wider searches.
        config: the training settings.
        check: how it did on scenes held out of its training.
        crops: training crops, and how many of them were the drawing's prints.
        threads, elapsed_s: torch threads and seconds of the whole run.
    """

    model_config = ConfigDict(extra="forbid")

    threshold: float = Field(gt=0, lt=1)
    config: dict[str, Any]
    check: VerifierCheck
    crops: int = Field(ge=0)
    print_crops: int = Field(ge=0)
    threads: int = Field(ge=1)
    elapsed_s: float = Field(ge=0)


class GraphMeta(BaseModel):
    """An ONNX graph stored in a bundle: tensor ``graph.<name>`` holds its bytes; it was exported
    from the network whose weights the bundle files under ``<name>.``.

    Attributes:
        size, sha256: the graph's length in bytes and its SHA-256 (a damaged graph is not run).
        weights_sha256: :func:`~deepmorph_core.graphs.weights_fingerprint` of the weights it was
            exported from (a graph of other weights is not run).
        inputs, outputs: names and shapes, in order (every tensor float32).
        opset: the ONNX operator set.
        exporter: what exported it (``torch.onnx.export`` and the torch version).
        max_abs_diff: the largest difference between its outputs and PyTorch's on the check
            inputs, measured before it was stored.
    """

    model_config = ConfigDict(extra="forbid")

    size: int = Field(ge=1, le=MAX_BUNDLE_BYTES)
    sha256: str = Field(pattern=_SHA256)
    weights_sha256: str = Field(pattern=_SHA256)
    inputs: dict[_NAME, _SHAPE] = Field(min_length=1, max_length=4)
    outputs: dict[_NAME, _SHAPE] = Field(min_length=1, max_length=4)
    opset: int = Field(ge=1, le=1000)
    exporter: str = Field(max_length=200)
    max_abs_diff: float = Field(ge=0)


class BundleMeta(BaseModel):
    """The JSON part of a bundle (everything but tensors)."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["deepmorph-model/1"] = FORMAT
    versions: dict[str, str]
    drawing_name: str = Field(max_length=MAX_NAME_CHARS)
    drawing_svg: str = Field(max_length=MAX_DRAWING_CHARS)
    bounds_defaults: dict[str, Any]
    # the morph geometry the model was trained with (deepmorph_core.svg.reader.GEOMETRY_VERSION);
    # bundles written before it was recorded used version 1
    geometry: int = Field(default=1, ge=1, le=GEOMETRY_VERSION)
    n_variables: int = Field(ge=1)
    # the gray the model reads colour prints in: red, green and blue weights (deepmorph_core.
    # reading_channel); bundles written before it was recorded read luminance
    reading_channel: ReadingChannel = LUMA_WEIGHTS
    codec: CodecSpec
    image_width: int = Field(ge=16, le=1024)
    raster: dict[str, Any]
    decoder: DecoderConfig
    augment: dict[str, Any]
    train: dict[str, Any]
    record: TrainingRecord
    detector: DetectorMeta | None = None
    # bundles written before the verifier existed have none
    verifier: VerifierMeta | None = None
    tuning: list[dict[str, Any]] = Field(default_factory=list)  # decoder tunings after training, oldest first
    # the last validation of the codec as it now is (after training, tuning or `deepmorph validate`)
    validation: list[ValidationRecord] = Field(default_factory=list, max_length=16)
    # the wrong payloads measured when training ended; bundles written before it, or trained
    # without it, have none
    trust: TrustRecord | None = None
    graphs: dict[_NAME, GraphMeta] = Field(default_factory=dict, max_length=MAX_GRAPHS)


MODEL_FILE = "DeepMorph model file"
_Meta = TypeVar("_Meta", bound=BaseModel)


def _bad(path: Path | str, why: str, what: str = MODEL_FILE) -> DeepMorphError:
    return DeepMorphError(f"{path}: not a usable {what} ({why})")


def save_bundle(path: str | Path, meta: BundleMeta, tensors: dict[str, Tensor]) -> None:
    """Write a bundle atomically: a crash or Ctrl-C never leaves a half-written file behind."""
    save_tagged(path, meta, tensors)


def save_tagged(path: str | Path, meta: BaseModel, tensors: dict[str, Tensor]) -> None:
    """Write tensors and their JSON metadata (``meta``) as one safetensors file, atomically."""
    payload = save_bytes(
        {k: v.detach().contiguous().cpu() for k, v in tensors.items()},
        metadata={_META_KEY: meta.model_dump_json()},
    )
    atomic_write(Path(path), payload)


def load_bundle(path: str | Path) -> tuple[BundleMeta, dict[str, Tensor]]:
    """Read and validate a bundle.

    Raises:
        DeepMorphError: missing, unreadable, truncated, corrupt or foreign files, and files from
            an incompatible format version.
    """
    return load_tagged(path, BundleMeta, FORMAT, MODEL_FILE)


def load_tagged(
    path: str | Path, schema: type[_Meta], fmt_expected: str, what: str, max_bytes: int = MAX_BUNDLE_BYTES
) -> tuple[_Meta, dict[str, Tensor]]:
    """Read a safetensors file written by :func:`save_tagged` and validate its metadata.

    Args:
        schema: the pydantic model of the metadata; its ``format`` must be ``fmt_expected``.
        what: what the file is, for errors ("DeepMorph model file").

    Raises:
        DeepMorphError: missing, unreadable, truncated, corrupt or foreign files, and files from
            an incompatible format version.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise DeepMorphError(f"{path}: cannot read {what.removeprefix('DeepMorph ')}: {exc.strerror or exc}") from None
    if not path.is_file():
        raise _bad(path, "not a regular file", what)
    if size > max_bytes:
        raise _bad(path, f"{size} bytes is larger than any such file", what)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DeepMorphError(f"{path}: cannot read {what.removeprefix('DeepMorph ')}: {exc.strerror or exc}") from None
    header_len = int.from_bytes(data[:8], "little") if len(data) >= 8 else -1
    if not 0 < header_len <= min(MAX_HEADER_BYTES, len(data) - 8):
        raise _bad(path, "corrupt or truncated: no tensor table where one should be", what)
    try:
        header = json.loads(data[8 : 8 + header_len])
        tensors = load_bytes(data)
    except RecursionError:
        raise _bad(path, "its metadata is nested too deeply", what) from None
    except (SafetensorError, ValueError, UnicodeDecodeError, OverflowError) as exc:
        raise _bad(path, f"corrupt or truncated: {str(exc).splitlines()[0][:120]}", what) from None
    if not isinstance(header, dict):
        raise _bad(path, "corrupt or truncated: the tensor table is not a table", what)
    raw = (header.get("__metadata__") or {}).get(_META_KEY)
    if raw is None:
        raise _bad(path, "a safetensors file without DeepMorph metadata", what)
    try:
        fmt = json.loads(raw).get("format")
    except RecursionError:
        raise _bad(path, "its metadata is nested too deeply", what) from None
    except (ValueError, AttributeError, TypeError):
        raise _bad(path, "its metadata is not JSON", what) from None
    if fmt != fmt_expected:
        raise _bad(path, f"format {fmt!r}, this version reads {fmt_expected!r}", what)
    try:
        meta = schema.model_validate_json(raw)
    except ValidationError as exc:
        raise _bad(path, format_validation_error(exc, prefix="", known=None, kind="field"), what) from None
    return meta, tensors


def check_weights(
    path: str | Path, what: str, expected: Mapping[str, Tensor], given: Mapping[str, Tensor], file: str = MODEL_FILE
) -> None:
    """Refuse weights that do not fit a network before they are loaded into it: a missing or
    unexpected tensor, another shape or type (an int8 tensor would be cast without a word),
    or a value that is not finite.

    Raises:
        DeepMorphError: naming the file, the network and the first tensor at fault.
    """
    missing = sorted(set(expected) - set(given))
    extra = sorted(set(given) - set(expected))
    if missing or extra:
        name = missing[0] if missing else extra[0]
        why = "is missing" if missing else "is not part of it"
        raise _bad(path, f"the {what}'s weights do not fit: {name} {why}", file)
    for name, want in expected.items():
        got = given[name]
        if tuple(got.shape) != tuple(want.shape) or got.dtype != want.dtype:
            raise _bad(
                path,
                f"the {what}'s weights do not fit: {name} is {got.dtype} {tuple(got.shape)}, "
                f"expected {want.dtype} {tuple(want.shape)}",
                file,
            )
        if got.is_floating_point() and not bool(torch.isfinite(got).all()):
            raise _bad(path, f"the {what}'s weights are not finite ({name})", file)


def versions() -> dict[str, str]:
    """Versions recorded in bundles."""
    from deepmorph_core import __version__

    return {"deepmorph": __version__, "torch": torch.__version__.split("+")[0]}
