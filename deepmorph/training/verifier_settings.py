"""The settings of a model's proposal verifier (``deepmorph train-verifier``), each declared
once: type, default, bounds, help. The validated configuration stored in bundles
(:class:`~deepmorph.training.verifier.VerifierConfig`) inherits these fields, and the command
takes its options' defaults, bounds and help from :data:`VERIFIER_DEFAULTS`.

Nothing here imports torch or pydantic: building the command line reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from annotated_types import Ge, Gt, Le, Lt

from deepmorph.training.settings import setting

#: the threshold is at most this (:func:`deepmorph.training.verifier.threshold_for`)
MAX_THRESHOLD = 0.1


@dataclass(frozen=True)
class VerifierSettings:
    """A proposal verifier's training settings (stored in the bundle).

    Attributes:
        scenes: training scenes per severity (medium and hard).
        check_scenes: held-out scenes per severity, which set the threshold and are reported.
        steps, batch, lr: optimisation (Adam, constant rate).
        noise: the standard deviation of the Gaussian noise added to each training crop.
        seed: scenes and initialisation.
        threads: torch threads of the training process.
        workers: scene-making processes (0: in the training process).
        max_threshold: the most the threshold may be.
    """

    scenes: Annotated[int, Ge(1), Le(100_000)] = setting(600, "scenes", "Training scenes per severity.")
    check_scenes: Annotated[int, Ge(1), Le(100_000)] = setting(
        150, "check-scenes", "Held-out scenes per severity: they set the threshold."
    )
    steps: Annotated[int, Ge(1), Le(1_000_000)] = setting(4000, "steps", "Training steps.")
    batch: Annotated[int, Ge(1), Le(4096)] = 64
    lr: Annotated[float, Gt(0), Le(1)] = 2e-3
    noise: Annotated[float, Ge(0), Le(1)] = 0.05
    seed: int = setting(0, "seed")
    threads: Annotated[int | None, Ge(1), Le(256)] = setting(1, "threads")
    workers: Annotated[int, Ge(0), Le(16)] = setting(2, "workers", "Scene-making processes.")
    max_threshold: Annotated[float, Gt(0), Lt(1)] = MAX_THRESHOLD


#: A verifier's settings at their defaults.
VERIFIER_DEFAULTS = VerifierSettings()

__all__ = ["MAX_THRESHOLD", "VERIFIER_DEFAULTS", "VerifierSettings"]
