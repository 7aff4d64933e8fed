"""The training settings, each declared once: its type, default, bounds and help.

:class:`TrainSettings` is the one declaration. :class:`deepmorph.training.codec.TrainConfig` (the
validated settings a bundle stores) inherits its fields; ``deepmorph train`` and
``deepmorph train-many`` take their options' defaults, bounds and help from it
(:func:`exposed`, :data:`DEFAULTS`), :func:`deepmorph.train` its keywords' defaults, and the
studio its Train form's. Changing a default here changes it in all of them, and :func:`chosen`
hands what each face was given on to training, so a new setting is passed on with no more code.

Nothing here imports torch or pydantic: building the command line (``deepmorph --help``) reads
it. Bounds are :mod:`annotated_types` constraints, which pydantic validates and the command line
turns into its options' ranges.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import Annotated, Any, Literal, get_args, get_origin, get_type_hints

from annotated_types import Ge, Gt, Le

#: The payload length a new model hides unless told (``--payload-bits``, ``payload_bits=``).
PAYLOAD_BITS = 24
#: Fresh payloads read back after training unless told: from renders and from close-up photos
#: (``--validation``, ``validation=``; :mod:`deepmorph.training.validation`).
RENDER_SAMPLES, PHOTO_SAMPLES = 1000, 200
#: The early stop's window (steps at full corruption) and the share of code words they must read.
EARLY_STOP_WINDOW, EARLY_STOP_RATE = 250, 0.995
#: Steps an auto code shrunk by its renders at the end of training is trained on for (``renders_tune``):
#: ``codepen``'s 20-bit code at ``--pixels 200``, which read 97.6 % of renders, cut to 16 bits, read
#: 99.3-99.6 % 400 steps later.
RENDERS_TUNE = 400
#: Small prints are shrunk to this share of the decoder's width (``small_prints``).
SMALL_PRINT_SCALE = (0.55, 0.95)


def setting(default: Any, option: str | None = None, help: str = "") -> Any:  # noqa: A002 - the option's help
    """A field of a settings dataclass (:class:`TrainSettings`, :class:`TuneSettings`, the
    detector's): ``option`` is its public name (``--image-width`` on the command line,
    ``image_width=`` in Python) where a command exposes it, ``help`` its one line."""
    return dataclasses.field(default=default, metadata={"option": option, "help": help})


#: What a colour drawing's prints are read in (``--read-in``): ``auto`` or a channel's name
#: (:data:`deepmorph_core.reading_channel.CHANNELS`).
ReadIn = Literal["auto", "luminance", "red", "green", "blue"]


@dataclass(frozen=True)
class TrainSettings:
    """Training settings (stored in the bundle, as :class:`deepmorph.training.codec.TrainConfig`).

    Attributes:
        steps: total optimisation steps (both stages).
        batch: perturbations per step.
        width: image width in pixels (decoder input; the height follows the drawing).
        print_px: the smallest width in camera pixels the print will have in photos
            (``--pixels``). The capture's blur, motion, shadow and the misalignment left after
            framing are then in those pixels (:func:`~deepmorph_core.severity.residual_steps`),
            so a print seen larger carries more; ``decode`` calls narrower prints too small and
            reads no payload from them. ``None``: the default, a frame that stands for a print
            96 px wide.
        registered: register every training render onto the unmorphed drawing as the photo
            chain aligns its photos (:mod:`deepmorph_core.registration`), leaving only
            :data:`~deepmorph_core.severity.REGISTERED_ALIGNMENT` of the ``print_px``
            misalignment to the corruption. ``None`` (the default): with ``print_px``. Bundles
            from before it was stored were not.
        lr, encoder_lr: Adam learning rates of the decoder and the encoder (decayed by a cosine
            to 10 % over stage 2).
        stage1_max_fraction: stage 1 ends at this share of ``steps`` at the latest.
        plateau_window, plateau_gain: stage 1 also ends when the bit accuracy (averaged over a
            window) gains less than ``plateau_gain`` from one window to the next.
        hard_fraction: share of each batch rendered by the real renderer (resvg).
        small_prints: share of each batch captured as a small print: shrunk to
            :data:`SMALL_PRINT_SCALE` of the decoder's width, corrupted at that size (the
            preset scaled to it), and enlarged again. A print 60 px wide in a photo is blurred,
            noised and compressed at 60 px, not at the decoder's width. A decoder tuned so
            (:func:`~deepmorph.training.codec.tune_decoder`) reads more payloads from photos, and
            lets a few more CRC collisions through (``docs/training.md``).
        severity: capture-corruption preset (``none``, ``easy``, ``medium``, ``hard``) reached
            at the end of the curriculum.
        curriculum: share of ``steps`` over which corruption ramps up through the milder presets
            (a decoder facing full corruption from a random start stays at chance); by default
            the first 1500 of 4000 steps, so the last 2500 train at ``severity``.
        read_in: the gray a colour drawing's prints are read in (``auto``:
            :func:`~deepmorph_core.reading_channel.choose_channel`); a model read in red, green
            or blue needs its prints in colour (``docs/colour.md``).
        encoder_init: the encoder's start. ``spread`` (default): each code bit drives its own
            variables at full range (:func:`deepmorph_core.networks.spread_weights`), for far
            fewer bit errors under corruption. ``random``: the paper's dense random matrix.
        spatial_transformer: put a learned homography in front of the decoder
            (:mod:`deepmorph_core.spatial`), trained with it end to end; it undoes the
            perspective and turn that framing by ink moments leaves (``docs/training.md``).
        readout: give the decoder a linear readout of the pixels, fitted by least squares
            (:func:`~deepmorph.training.codec.fit_readout`) and then trained with the CNN where the
            CNN alone stalls in stage 1 (below :data:`~deepmorph.training.codec.READOUT_STALL` of
            bits); left out of the bundle where it does not (``docs/training.md``).
        early_stop: end training before ``steps`` once it reads well enough: when, over the last
            ``early_stop_window`` steps, all at ``severity`` (the curriculum's ramp done), at
            least ``early_stop_rate`` of the batches' code words had no more bit errors than the
            code corrects. Each batch is scored before the step learns from it, so the share is
            measured on captures the decoder had not seen. The learning-rate schedule still runs
            over ``steps``: a run stopped at step N is the full run's model at step N.
        early_stop_window, early_stop_rate: see ``early_stop``.
        renders_tune: a ``--payload-bits auto`` code is checked on fresh renders when training
            ends; one that reads fewer than 99 % of them is made smaller and trained on for this
            many steps (:func:`~deepmorph.training.code_shrink.code_for_renders`). 0: no check.
        verifier: when the codec is trained and validated, train the model's proposal verifier
            (:func:`~deepmorph.training.verifier.train_verifier`, ``deepmorph train-verifier``) and
            store it in the bundle: photos holding other drawings' prints read faster.
            ``None`` (the default): with ``print_px``, where wide frames hold other prints
            (``--pixels 200`` models: 0.83-1.64x QR's frame time without it, 0.57-0.90x with it).
        trust_samples: when the codec is validated, hard close-ups of fresh payloads read with the
            CRC checked on all but six of its bits, to estimate the wrong payloads the photo chain gives
            (:mod:`deepmorph.training.trust`); a ``--payload-bits auto`` payload whose estimate
            is above 0.1 in 10,000 gives bits over to a longer CRC, validated again. ``None``: 600
            for a colour drawing whose validation read 90 % of its close-ups, else 0 (black ink
            read 10,000 close-ups at each size without a wrong one).
        freeze_encoder: train the decoder alone, the encoder as it is (no spread start, no
            stage 2), learning rate decaying by a cosine to 10 % over all steps: what
            :func:`~deepmorph.training.codec.tune_decoder` runs on a trained bundle.
        seed: makes a run reproducible (same seed, same threads: same model).
        device: ``cpu``, ``cuda`` or ``auto`` (CUDA where present); a bundle stores the device
            it resolved to.
        shards: random streams the batch is drawn from (:mod:`deepmorph.training.distributed`):
            the processes of a torchrun share them, so a run's numbers depend on its seed and
            shards, not on how many processes train it. ``None``: one per process.
        threads: torch CPU threads (``None``: torch's default).
        checkpoint_every, log_every: in steps.
    """

    steps: Annotated[int, Ge(1), Le(10_000_000)] = setting(4000, "steps", "Training steps (both stages).")
    batch: Annotated[int, Ge(2), Le(4096)] = setting(32, "batch", "Morphs per step.")
    width: Annotated[int, Ge(32), Le(512)] = setting(
        96, "image-width", "Width in pixels of the image the decoder reads."
    )
    print_px: Annotated[int | None, Ge(32), Le(2000)] = setting(
        None,
        "pixels",
        "The smallest width in pixels the print will have in photos: blur, motion and misalignment in those "
        "pixels; narrower prints are too small.",
    )
    registered: bool | None = None
    lr: Annotated[float, Gt(0), Le(1)] = 2e-3
    encoder_lr: Annotated[float, Gt(0), Le(10)] = 1e-2
    stage1_max_fraction: Annotated[float, Ge(0), Le(1)] = 0.35
    plateau_window: Annotated[int, Ge(10)] = 150
    plateau_gain: Annotated[float, Ge(0)] = 0.004
    hard_fraction: Annotated[float, Ge(0), Le(1)] = setting(
        0.25, "real-render-share", "Share of each batch drawn by resvg."
    )
    small_prints: Annotated[float, Ge(0), Le(1)] = setting(
        0.0,
        "small-prints",
        "Share of each batch captured as a small print (corrupted at "
        f"{SMALL_PRINT_SCALE[0] * 100:.0f}-{SMALL_PRINT_SCALE[1] * 100:.0f} % of the width, enlarged).",
    )
    severity: Literal["none", "easy", "medium", "hard"] = setting(
        "medium", "severity", "Capture corruption to train against."
    )
    curriculum: Annotated[float, Ge(0), Le(1)] = 0.375
    encoder_init: Literal["spread", "random"] = setting(
        "spread", "encoder-init", "Encoder start: spread (each bit drives its own variables) or random (the paper's)."
    )
    spatial_transformer: bool = setting(
        True, "spatial-transformer", "Learn a homography in front of the decoder that undoes leftover perspective."
    )
    readout: bool = setting(
        True, "readout", "Where the CNN stalls in stage 1, add a linear readout of the pixels fitted by least squares."
    )
    early_stop: bool = setting(
        True,
        "early-stop",
        f"Stop before --steps once {EARLY_STOP_WINDOW} steps at full corruption have read "
        f"{EARLY_STOP_RATE:.1%} of their code words.",
    )
    early_stop_window: Annotated[int, Ge(10)] = EARLY_STOP_WINDOW
    early_stop_rate: Annotated[float, Gt(0), Le(1)] = EARLY_STOP_RATE
    renders_tune: Annotated[int, Ge(0), Le(100_000)] = setting(
        RENDERS_TUNE,
        "renders-tune",
        "With --payload-bits auto: steps trained on after a code that reads fewer than 99 % of fresh renders when "
        "training ends is made smaller (0: no such check).",
    )
    verifier: bool | None = setting(
        None,
        "verifier",
        "Then train a proposal verifier (as train-verifier does, minutes): photos with other drawings read faster. "
        "Default: with --pixels.",
    )
    trust_samples: Annotated[int | None, Ge(0), Le(100_000)] = setting(
        None,
        "trust-samples",
        "Hard close-ups that count wrong payloads after validation; with --payload-bits auto, payload bits go to a "
        "longer CRC where they call for it. Default: 600 for a colour drawing that reads 90 % of its close-ups.",
    )
    freeze_encoder: bool = False
    seed: int = setting(0, "seed")
    device: Literal["cpu", "cuda", "auto"] = setting("auto", "device")
    read_in: ReadIn = setting(
        "auto",
        "read-in",
        "The gray colour prints are read in: auto (red, green or blue where the drawing's colours differ at least "
        "twice as much there, else luminance), or that one. Print in colour unless it is luminance.",
    )
    shards: Annotated[int | None, Ge(1), Le(1024)] = setting(
        None,
        "shards",
        "Random streams the batch is drawn from, shared by torchrun's processes (default: one per process).",
    )
    threads: Annotated[int | None, Ge(1), Le(256)] = setting(None, "threads")
    checkpoint_every: Annotated[int, Ge(1)] = setting(
        250, "checkpoint-every", "Steps between checkpoints (a crash loses at most these)."
    )
    log_every: Annotated[int, Ge(1)] = 25


#: Every setting at its default.
DEFAULTS = TrainSettings()


@dataclass(frozen=True)
class TuneSettings:
    """What a decoder tuning (:func:`deepmorph.training.codec.tune_decoder`, ``deepmorph
    tune-decoder``) sets for itself; everything else is the bundle's own training settings.

    Attributes:
        steps: tuning steps, at full corruption from the first.
        small_prints: share of each batch captured as a small print (as
            :attr:`TrainSettings.small_prints`).
        lr: the decoder's start learning rate, decaying by a cosine to 10 %.
    """

    steps: Annotated[int, Ge(1), Le(10_000_000)] = setting(800, "steps", "Tuning steps.")
    small_prints: Annotated[float, Ge(0), Le(1)] = setting(
        0.5, "small-prints", "Share of each batch captured as a small print."
    )
    lr: Annotated[float, Ge(1e-6), Le(1e-1)] = setting(3e-4, "lr", "Start learning rate (cosine to 10 %).")


#: Every tuning setting at its default.
TUNE_DEFAULTS = TuneSettings()


@dataclass(frozen=True)
class Exposed:
    """A setting as ``deepmorph train`` and :func:`deepmorph.train` take it (its default is
    :data:`DEFAULTS`').

    Attributes:
        field: its name in :class:`TrainSettings` (and in a bundle's ``train``).
        option: its public name: ``--{option}`` on the command line, ``{option}`` with
            underscores as a keyword.
        help: one line for ``--help`` (empty where the option is one that other commands share,
            with its own help: ``--seed``, ``--device``, ``--threads``).
        ge, gt, le: its bounds (``None``: unbounded).
        choices: the values of a fixed choice (``None``: not one).
        switch: on or off (``--{option}/--no-{option}``).
    """

    field: str
    option: str
    help: str
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    choices: tuple[str, ...] | None = None
    switch: bool = False

    @property
    def keyword(self) -> str:
        """Its keyword in :func:`deepmorph.train`."""
        return self.option.replace("-", "_")


@cache
def exposed(settings: type = TrainSettings) -> dict[str, Exposed]:
    """The settings ``deepmorph train`` and :func:`deepmorph.train` take (with ``settings``
    :class:`TuneSettings`: those ``deepmorph tune-decoder`` takes), by field name, in
    declaration order."""
    hints = get_type_hints(settings, include_extras=True)
    found = {}
    for f in dataclasses.fields(settings):
        if f.metadata.get("option") is None:
            continue
        hint, meta = hints[f.name], []
        if get_origin(hint) is Annotated:
            hint, *meta = get_args(hint)
        found[f.name] = Exposed(
            f.name,
            f.metadata["option"],
            f.metadata["help"],
            ge=next((m.ge for m in meta if isinstance(m, Ge)), None),
            gt=next((m.gt for m in meta if isinstance(m, Gt)), None),
            le=next((m.le for m in meta if isinstance(m, Le)), None),
            choices=tuple(get_args(hint)) if get_origin(hint) is Literal else None,
            switch=hint in (bool, bool | None),
        )
    return found


def chosen(arguments: Mapping[str, Any], *, keywords: bool = False) -> dict[str, Any]:
    """The training settings a face was given, as
    :func:`~deepmorph.training.codec.train_model` takes them (``train=``) and a bundle stores
    them: by field name.

    Args:
        arguments: a face's arguments by name (its ``locals()`` on entry): a command's
            parameters, named after the fields (``deepmorph train``), or, with ``keywords``,
            :func:`deepmorph.train`'s keywords (``image_width`` for ``width``).
        keywords: ``arguments`` are named by :attr:`Exposed.keyword`.

    Returns:
        Each :func:`exposed` setting found among ``arguments`` (a command may expose only some,
        as ``train-many`` does); the other arguments are left out.
    """
    found = {}
    for field, setting in exposed().items():
        name = setting.keyword if keywords else field
        if name in arguments:
            found[field] = arguments[name]
    return found


__all__ = [
    "DEFAULTS",
    "EARLY_STOP_RATE",
    "EARLY_STOP_WINDOW",
    "PAYLOAD_BITS",
    "PHOTO_SAMPLES",
    "RENDER_SAMPLES",
    "SMALL_PRINT_SCALE",
    "TUNE_DEFAULTS",
    "Exposed",
    "TrainSettings",
    "TuneSettings",
    "chosen",
    "exposed",
    "setting",
]
