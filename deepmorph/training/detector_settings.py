"""The settings of a detector trained on scenes, each declared once: type, default, bounds, help.

:class:`SceneSettings` holds what every detector trained on scenes takes (the universal
detector's training, :mod:`deepmorph.training.universal`); :class:`DetectorSettings`
a model's own detector's, a short fine-tune of the universal one by default. The validated
configurations stored in bundles (:class:`~deepmorph.training.detector.SceneTrainingConfig`,
:class:`~deepmorph.training.detector.DetectorConfig`) inherit these fields, and
``deepmorph train-detector`` takes its options' defaults, bounds and help from
:data:`DETECTOR_DEFAULTS` (:func:`deepmorph.training.settings.exposed`).

Nothing here imports torch or pydantic: building the command line reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from annotated_types import Ge, Gt, Le

from deepmorph.training.settings import setting


@dataclass(frozen=True)
class SceneSettings:
    """Settings of a detector network trained on scenes (stored with it).

    Attributes:
        steps, batch, lr: optimisation (Adam, cosine decay to 5 %).
        width: channel width of the network.
        seed: scenes and initialisation.
        threads: torch threads of the training process.
        workers: scene-making processes (0: in the training process).
        device: where the network trains (``auto``: CUDA where present); scenes are made on
            the CPU whatever the device.
        checkpoint_every, log_every: in steps.
    """

    steps: Annotated[int, Ge(1), Le(10_000_000)] = setting(2000, "steps", "Training steps.")
    batch: Annotated[int, Ge(1), Le(1024)] = setting(16, "batch", "Scenes per step.")
    lr: Annotated[float, Gt(0), Le(1)] = setting(2e-3, "lr", "Start learning rate (cosine to 5 %).")
    width: Annotated[int, Ge(8), Le(256)] = setting(
        32, "channels", "Channel width of the network (16: about half the time)."
    )
    seed: int = setting(0, "seed")
    threads: Annotated[int | None, Ge(1), Le(256)] = setting(1, "threads")
    workers: Annotated[int, Ge(0), Le(16)] = setting(1, "workers", "Scene-making processes.")
    device: Literal["cpu", "cuda", "auto"] = setting("auto", "device")
    checkpoint_every: Annotated[int, Ge(1)] = 200
    log_every: Annotated[int, Ge(1)] = 25


@dataclass(frozen=True)
class DetectorSettings(SceneSettings):
    """A model's own detector's settings: by default a short fine-tune of the shipped universal
    detector (:mod:`deepmorph_detect.universal`), 300 steps at ``lr`` 5e-4; from scratch
    (``start="scratch"``) takes about 2000 steps at 2e-3.

    Attributes:
        fine_tune: start from the detector already in the bundle (same width); the runs it
            came from are kept in the bundle (``DetectorMeta.earlier``).
        start: without ``fine_tune``, where the network starts: the universal detector (whose
            width it must have) or ``scratch``.
    """

    steps: Annotated[int, Ge(1), Le(10_000_000)] = setting(
        300, "steps", "Training steps (from scratch: about 2000, with --lr 2e-3)."
    )
    lr: Annotated[float, Gt(0), Le(1)] = setting(5e-4, "lr", "Start learning rate (cosine to 5 %).")
    fine_tune: bool = False
    start: Literal["universal", "scratch"] = "universal"


#: A model's own detector's settings at their defaults.
DETECTOR_DEFAULTS = DetectorSettings()

__all__ = ["DETECTOR_DEFAULTS", "DetectorSettings", "SceneSettings"]
