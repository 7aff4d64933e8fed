"""The photo chain's plugin module, loaded through the ``deepmorph`` entry point
(``builtin_detectors``) exactly as third-party plugins are: the built-in detectors and the
validation of trained models on close-up photos. The photo commands are the application's
(:mod:`deepmorph.cli.photo_commands`, registered by :mod:`deepmorph.plugin`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    from deepmorph_core.bundle import ValidationRecord
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.plugins import Register


@hookimpl
def deepmorph_register_detectors(register: Register) -> None:
    """Register the built-in detectors: the per-drawing one and the universal one (imported
    here, not at load: see hookspecs)."""
    from deepmorph_detect.centrenet import CentreNetDetector
    from deepmorph_detect.universal import UniversalDetector

    register.detector(CentreNetDetector)
    register.detector(UniversalDetector)


@hookimpl
def deepmorph_validate_model(model: DeepMorphModel, samples: int, seed: int) -> ValidationRecord:
    """Close-up photos of fresh codes through the photo chain (:mod:`deepmorph_detect.photo_validation`),
    one process per thread the caller runs torch on."""
    from deepmorph_detect.close_up_pool import one_per_thread
    from deepmorph_detect.photo_validation import validate_close_ups

    return validate_close_ups(model, samples, seed, workers=one_per_thread())
