"""A trained drawing, as users call it: hide payloads in it, read them back from photos.

Every method hands over to the library (``deepmorph_core`` for the model and its codes,
``deepmorph_detect`` for photos); nothing here decides anything of its own.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from deepmorph.training.settings import DEFAULTS, PAYLOAD_BITS, ReadIn, chosen

if TYPE_CHECKING:
    from collections.abc import Callable

    from deepmorph_core.code import Code
    from deepmorph_core.image_io import ImageLike
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.payload import PayloadLike
    from deepmorph_detect.camera import Camera
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.reading import SequenceReading
    from deepmorph_detect.results import Located

Severity = Literal["none", "easy", "medium", "hard"]


class Model:
    """A trained drawing (a ``.dmm`` bundle).

    Args:
        bundle: the loaded bundle (:func:`load` makes one from a file).
        detector: the photo chain's detector by name (default: the one the bundle names).
        device: where the photo chain's networks run: ``auto`` (CUDA where present, else the
            CPU), ``cpu`` or ``cuda``.

    Raises:
        DeepMorphError: an unknown device, or ``cuda`` where there is none.
    """

    def __init__(self, bundle: DeepMorphModel, detector: str | None = None, device: str = "auto") -> None:
        from deepmorph_core.device import resolve_device

        self.bundle = bundle
        self._detector = detector
        self._device = resolve_device(device)
        self._locator: Locator | None = None

    @property
    def payload_bits(self) -> int:
        """How many bits a payload of this model has."""
        return self.bundle.codec.spec.payload_bits

    @property
    def drawing_name(self) -> str:
        """The name of the drawing it was trained on."""
        return self.bundle.meta.drawing_name

    def info(self) -> dict[str, Any]:
        """What ``deepmorph info --json`` prints (JSON values): codec, image size, training record ..."""
        return self.bundle.info()

    def encode(self, payload: PayloadLike) -> Code:
        """``payload`` hidden in the drawing.

        Args:
            payload: exactly :attr:`payload_bits` bits, as an ``int`` (``0 <= payload <
                2**payload_bits``), hex text with ``0x`` and ``ceil(payload_bits / 4)`` digits,
                a decimal number after ``0d``, a string of ``payload_bits`` binary digits,
                ``ceil(payload_bits / 8)`` big-endian ``bytes``, or a sequence or array of
                ``payload_bits`` zeros and ones.

        Returns:
            A :class:`~deepmorph_core.code.Code`: ``.svg`` (the morphed SVG), ``.svg_at(width_mm)``,
            ``.pdf(width_mm)``, ``.png(width_mm, dpi)``, ``.save(path, width_mm)``.

        Raises:
            DeepMorphError: a payload of another type (a float, ``None``, a bool ...) or one
                that does not fit (too large, negative, the wrong number of digits, bytes or
                bits), saying what was expected.
        """
        return self.bundle.code(payload)

    @property
    def locator(self) -> Locator:
        """The photo chain for this model (made on first use)."""
        if self._locator is None:
            from deepmorph_detect.locate import Locator

            self._locator = Locator(self.bundle, detector=self._detector, device=self._device)
        return self._locator

    def decode(
        self, image: ImageLike, *, bgr: bool = False, camera: Camera | None = None, first: bool = False
    ) -> list[Located]:
        """Every drawing of this model in a photo, with its payload, corners and camera pose.

        Args:
            image: a path to an image file, a PIL image, or an ``(H, W)`` / ``(H, W, 3|4)``
                array (uint8, uint16, or float in ``[0, 1]``). Colour arrays are RGB(A), the
                order of PIL, imageio and matplotlib; pass ``bgr=True`` for OpenCV's BGR(A).
                The chain reads gray (OpenCV's weights), so a black print read with its red and
                blue swapped reads the same; only coloured ink would differ.
            bgr: the array's channels are in OpenCV's order.
            camera: calibrated intrinsics (:class:`~deepmorph_detect.camera.Camera`); without
                them the pose assumes a typical phone camera and says so.
            first: stop at the first drawing whose payload reads and give it alone, as a
                scanner looking for one code does; faster where other drawings are in view.

        Returns:
            One :class:`~deepmorph_detect.results.Located` per drawing found (``[]`` for none):
            ``.payload`` (``.hex``, ``.int``, ``.bits``), ``.ok``, ``.pose``, ``.corners``.

        Raises:
            DeepMorphError: a path that is not a readable image, another type, or an array of
                another shape or pixel type.
        """
        from deepmorph_core.image_io import image_input

        return self.locator.locate(image_input(image, bgr=bgr), camera=camera, first=first)

    def decode_sequence(
        self,
        source: str | Path,
        *,
        camera: Camera | None = None,
        every: int = 1,
        hard_decision: bool = False,
        on_frame: Callable[[], None] | None = None,
        on_skip: Callable[[str], None] | None = None,
        first: bool = False,
    ) -> SequenceReading:
        """Every drawing of this model in a sequence of frames, followed from frame to frame and
        its readings fused: what ``deepmorph decode`` does with a folder or a video.

        Args:
            source: a folder of frames (its image files in name order) or a video file.
            camera: calibrated intrinsics; without them the pose assumes a typical phone camera.
            every: use every ``every``-th frame of a video.
            hard_decision: hard-decision decoding only (``--hard-decision``), no soft (Chase).
            on_frame: called once per frame taken (a progress bar).
            on_skip: called with a message for each frame skipped: an unreadable file, or a
                frame the chain refused.
            first: each frame's search stops at the first drawing read (:meth:`decode`'s ``first``).

        Returns:
            A :class:`~deepmorph_detect.reading.SequenceReading`: ``.frames`` read, the fused
            ``.detections`` (as ``deepmorph decode --json`` gives them: ``payload``, ``ok``,
            ``frames`` ...), the ``.skipped`` frames and the ``.last`` frame read.

        Raises:
            DeepMorphError: a missing source, a single image (:meth:`decode` reads those), a
                folder without image files, a video that cannot be read, or not one readable
                frame.
        """
        from deepmorph_core.errors import DeepMorphError
        from deepmorph_detect.media import VIDEO_SUFFIXES
        from deepmorph_detect.reading import FrameSource, read_sequence

        path = Path(source)
        if every < 1:
            raise DeepMorphError(f"every={every}: expected a positive number of frames")
        sequence = FrameSource.open(path)  # a missing or unreadable video is refused before any work
        if sequence is None and path.exists():
            raise DeepMorphError(
                f"{path}: not a folder of frames or a video ({', '.join(sorted(VIDEO_SUFFIXES))}); "
                "Model.decode reads a single image"
            )
        if sequence is None:
            raise DeepMorphError(f"{path}: no such folder or video")
        return read_sequence(self.locator, sequence.frames(every), camera=camera, soft=not hard_decision,
                             on_frame=on_frame, on_skip=on_skip, name=str(path), first=first)  # fmt: skip

    def __repr__(self) -> str:
        return f"deepmorph.Model({self.drawing_name!r}, {self.payload_bits} payload bits)"


def load(path: str | Path, *, detector: str | None = None, device: str = "auto") -> Model:
    """A trained model from its bundle file; its photo chain's networks run on ``device``
    (``auto``: CUDA where present, else the CPU).

    Raises:
        DeepMorphError: a missing, corrupt or foreign file, in one line.
    """
    from deepmorph_core.model import DeepMorphModel

    return Model(DeepMorphModel.load(path), detector=detector, device=device)


def train(
    drawing: str | Path,
    out: str | Path,
    *,
    payload_bits: int | Literal["auto"] = PAYLOAD_BITS,
    crc_bits: int | None = None,
    ecc_t: int | None = None,
    steps: int = DEFAULTS.steps,
    batch: int = DEFAULTS.batch,
    image_width: int = DEFAULTS.width,
    pixels: int | None = DEFAULTS.print_px,
    severity: Severity = DEFAULTS.severity,
    real_render_share: float = DEFAULTS.hard_fraction,
    small_prints: float = DEFAULTS.small_prints,
    seed: int = DEFAULTS.seed,
    encoder_init: Literal["spread", "random"] = DEFAULTS.encoder_init,
    spatial_transformer: bool = DEFAULTS.spatial_transformer,
    readout: bool = DEFAULTS.readout,
    early_stop: bool = DEFAULTS.early_stop,
    renders_tune: int = DEFAULTS.renders_tune,
    verifier: bool | None = DEFAULTS.verifier,
    trust_samples: int | None = DEFAULTS.trust_samples,
    read_in: ReadIn = DEFAULTS.read_in,
    device: Literal["auto", "cpu", "cuda"] = DEFAULTS.device,
    shards: int | None = DEFAULTS.shards,
    threads: int | None = DEFAULTS.threads,
    resume: bool = False,
    checkpoint_every: int = DEFAULTS.checkpoint_every,
    move: float | None = None,
    shift: float | tuple[float, float] | None = None,
    scale: tuple[float, float] | None = None,
    rotate: tuple[float, float] | None = None,
    drop_unsupported: bool = False,
    validation: tuple[int, int] | None = None,
    on_log: Callable[[dict[str, float]], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
) -> Model:
    """Train a model for ``drawing`` and write it to ``out``: ``deepmorph train``, one keyword per
    option (``--crc`` is ``crc_bits``), with the same defaults
    (:mod:`deepmorph.training.settings`).

    Args:
        drawing: the SVG.
        out: the bundle to write (also the checkpoint ``resume`` continues).
        payload_bits, crc_bits, ecc_t: the payload and its code (CRC 8 or 16 bits; BCH
            correcting ``ecc_t`` bit errors; defaults chosen from ``payload_bits``);
            ``payload_bits="auto"``: the largest size ``deepmorph capacity`` predicts to read.
        steps, batch, image_width: training steps (both stages), morphs per step, the width in
            pixels of the image the decoder reads.
        pixels: the smallest width in pixels the print will have in photos (``--pixels``):
            the capture's blur, motion and misalignment are in those pixels, and narrower prints
            are reported too small.
        severity: the capture corruption reached at the end of the curriculum.
        real_render_share: share of each batch drawn by resvg.
        small_prints: share of each batch captured as a small print.
        seed, encoder_init, spatial_transformer, readout, device, threads: the run and its networks
            (``device="auto"``: CUDA where present).
        early_stop: end before ``steps`` once the batches at full corruption read their
            payloads well enough (:class:`~deepmorph.training.settings.TrainSettings`).
        renders_tune: with ``payload_bits="auto"``, steps trained on after a code that reads
            fewer than 99 % of fresh renders when training ends is made smaller (0: no check).
        verifier: then train the model's proposal verifier and store it (``deepmorph
            train-verifier``): photos holding other drawings' prints read faster. ``None``: with
            ``pixels``.
        trust_samples: hard close-ups that count the wrong payloads after validation; a
            ``payload_bits="auto"`` payload gives bits to a longer CRC where they call for it
            (``None``: 600 for a colour drawing that reads 90 % of its close-ups, else 0).
        read_in: the gray a colour drawing's prints are read in (``auto``: red, green or blue
            where its colours differ at least twice as much there, else luminance); a model not
            read in luminance needs its prints in colour.
        shards: random streams the batch is drawn from (default: one per torchrun process).
        resume: continue the checkpoint at ``out``.
        checkpoint_every: steps between checkpoints.
        move, shift, scale, rotate: default bounds for elements the SVG gives none
            (``dm:move``, ``dm:shift`` as one radius or ``(rx, ry)``, ``dm:scale`` and
            ``dm:rotate`` as ``(lo, hi)``).
        drop_unsupported: leave out what DeepMorph cannot model instead of refusing the file.
        validation: fresh payloads read after training from renders and from close-up photos
            (default 1000 and 200; ``(0, 0)`` skips it); the result is stored in the bundle and
            a model below 99 % warns.
        on_log: called with each log line (``step``, ``stage``, ``loss``, ``bit_acc`` ...).
        on_warning: called with each warning before training starts (default:
            :func:`warnings.warn`).

    Returns:
        The trained model.

    Raises:
        DeepMorphError: the drawing, a setting or the output refused, in one line.
    """
    settings = chosen(locals(), keywords=True)  # first: the keywords alone
    import warnings

    from deepmorph.training.codec import train_model

    def warn(text: str) -> None:
        warnings.warn(text, stacklevel=4)  # shown at the line that called deepmorph.train

    summary = train_model(
        drawing,
        out,
        payload_bits=payload_bits,
        crc_bits=crc_bits,
        ecc_t=ecc_t,
        bounds={"move": move, "shift": shift, "scale": scale, "rotate": rotate},
        train=settings,
        resume=resume,
        on_start=(lambda total, done: on_log) if on_log else None,
        on_warning=on_warning or warn,
        drop_unsupported=drop_unsupported,
        validation_samples=validation,
    )
    return load(summary.bundle)


__all__ = ["Model", "Severity", "load", "train"]
