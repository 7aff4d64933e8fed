"""The built-in augmentations' plugin module, loaded through the ``deepmorph`` entry point
(``builtin_augmentations``) exactly as third-party plugins are."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    from deepmorph_core.plugins import Register


@hookimpl
def deepmorph_register_augmentations(register: Register) -> None:
    """Register the built-in capture corruptions (imported here, not at load: see hookspecs)."""
    from deepmorph_augment.blur import Blur
    from deepmorph_augment.colour import ChromaSubsampling, InkFade, PaperTint, WhiteBalance
    from deepmorph_augment.defocus import Defocus
    from deepmorph_augment.gaussian_noise import GaussianNoise
    from deepmorph_augment.intensity import Intensity
    from deepmorph_augment.jpeg import Jpeg
    from deepmorph_augment.lighting import Lighting
    from deepmorph_augment.motion_blur import MotionBlur
    from deepmorph_augment.perspective import Perspective
    from deepmorph_augment.rotation import Rotation
    from deepmorph_augment.salt_pepper import SaltPepper
    from deepmorph_augment.scale import Scale
    from deepmorph_augment.shadow import Shadow
    from deepmorph_augment.translation import Translation

    for cls in (InkFade, PaperTint, WhiteBalance, ChromaSubsampling, Perspective, Scale, Rotation, Translation,
                Blur, Defocus, MotionBlur, Lighting, Shadow, Intensity, GaussianNoise, SaltPepper, Jpeg):  # fmt: skip
        register.augmentation(cls)
