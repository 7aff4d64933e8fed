"""A trained drawing, as users call it: hide payloads in it, read them back from photos.

Every method hands over to the library (``deepmorph_core`` for the model and its codes,
``deepmorph_detect`` for photos); nothing here decides anything of its own.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable

    from deepmorph_core.code import Code
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.payload import PayloadLike
    from deepmorph_detect.camera import Camera
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.results import Located


class Model:
    """A trained drawing (a ``.dmm`` bundle).

    Args:
        bundle: the loaded bundle (:func:`load` makes one from a file).
        detector: the photo chain's detector by name (default: the one the bundle names).
    """

    def __init__(self, bundle: DeepMorphModel, detector: str | None = None) -> None:
        self.bundle = bundle
        self._detector = detector
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
        """What ``deepmorph info --json`` prints: codec, image size, training record, ..."""
        return self.bundle.info()

    def encode(self, payload: PayloadLike) -> Code:
        """``payload`` (an int, hex or binary text, bytes, or a sequence of bits) hidden in the
        drawing: a :class:`~deepmorph_core.code.Code` with its SVG and renders for print.

        Raises:
            DeepMorphError: a payload of the wrong size or type, saying what was expected.
        """
        return self.bundle.code(payload)

    @property
    def locator(self) -> Locator:
        """The photo chain for this model (made on first use)."""
        if self._locator is None:
            from deepmorph_detect.locate import Locator

            self._locator = Locator(self.bundle, detector=self._detector)
        return self._locator

    def decode(self, image: Any, *, bgr: bool = False, camera: Camera | None = None) -> list[Located]:
        """Every drawing of this model in a photo, with its payload, corners and camera pose.

        Args:
            image: a path, a PIL image, or an ``(H, W)`` / ``(H, W, 3|4)`` array (uint8, or
                float in ``[0, 1]``). Colour arrays are RGB unless ``bgr`` is set (OpenCV's order).
            camera: calibrated intrinsics (:class:`~deepmorph_detect.camera.Camera`); without
                them the pose assumes a typical phone camera and says so.

        Returns:
            One :class:`~deepmorph_detect.results.Located` per drawing found (``[]`` for none):
            ``.payload`` (``.hex``, ``.int``, ``.bits``), ``.ok``, ``.pose``, ``.corners``.
        """
        from deepmorph_core.image_io import image_input

        return self.locator.locate(image_input(image, bgr=bgr), camera=camera)

    def __repr__(self) -> str:
        return f"deepmorph.Model({self.drawing_name!r}, {self.payload_bits} payload bits)"


def load(path: str | Path, *, detector: str | None = None) -> Model:
    """A trained model from its bundle file.

    Raises:
        DeepMorphError: a missing, corrupt or foreign file, in one line.
    """
    from deepmorph_core.model import DeepMorphModel

    return Model(DeepMorphModel.load(path), detector=detector)


def train(
    drawing: str | Path,
    out: str | Path,
    *,
    payload_bits: int = 24,
    crc_bits: int | None = None,
    ecc_t: int | None = None,
    move: float | None = None,
    steps: int = 3000,
    threads: int | None = None,
    seed: int = 0,
    resume: bool = False,
    on_log: Callable[[dict[str, Any]], None] | None = None,
    **settings: Any,
) -> Model:
    """Train a model for ``drawing`` and write it to ``out``, as ``deepmorph train`` does.

    Args:
        drawing: the SVG.
        out: the bundle to write (also the checkpoint ``resume`` continues).
        payload_bits, crc_bits, ecc_t: the payload and its code.
        move: default ``dm:move`` for elements the SVG gives no bounds.
        steps, threads, seed: the run.
        on_log: called with each log line (a dict with ``step``, ``loss``, ``bit_acc`` ...).
        **settings: further :class:`~deepmorph_core.train.TrainConfig` fields (``width``,
            ``batch``, ``severity`` ...).

    Returns:
        The trained model.
    """
    from deepmorph_core.train import train_model

    summary = train_model(
        drawing,
        out,
        payload_bits=payload_bits,
        crc_bits=crc_bits,
        ecc_t=ecc_t,
        bounds={"move": move},
        train={"steps": steps, "threads": threads, "seed": seed, **settings},
        resume=resume,
        on_start=(lambda total, done: on_log) if on_log else None,
    )
    return load(summary.bundle)


__all__ = ["Model", "load", "train"]
