"""The severity table: what ``easy``, ``medium`` and ``hard`` mean, in one place.

A severity names how rough a capture is. Two things read it:

* **the residual corruption** of training (:mod:`deepmorph_core.corruption`): what is left of
  a print-and-photo once the drawing is framed in the decoder's image. Framing by the ink's
  centre and spread (:mod:`deepmorph_core.framing`) removes the photo's translation and scale;
  what remains is a little residual scale, shift, rotation and perspective, then blur, light,
  noise and compression at the decoder's size. Pixel-valued parameters are given for
  :data:`PRESET_SIZE`-pixel images and scaled to the decoder's width; for a model trained for
  prints of a known width in the photo (``train --pixels``) they are the camera's, scaled from
  that width to the decoder's. Colour prints add the
  severity's colour steps (:attr:`Severity.colour`: faded ink, tinted paper, white balance,
  chroma subsampling), asked for with ``residual_steps(name, size, colour=True)``.
* **the photo simulator** (:mod:`deepmorph_detect.scenes`): :attr:`Severity.photo` places the
  print (tilt, size in the frame, how far a close-up may turn) and :attr:`Severity.capture` is
  what the camera then does to the whole photo (light, shadow, contrast, blur, motion, noise,
  JPEG), as steps of the same registered augmentation plugins training uses, their
  pixel-valued parameters in the camera's own pixels: a print 60 px wide in a photo is blurred
  by the same pixels as one 400 px wide, so small prints lose detail as they do in a camera.

``none`` corrupts nothing and has no photo settings.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from deepmorph_core.errors import DeepMorphError

#: Reference image width of the residual steps' pixel-valued parameters.
PRESET_SIZE = 96
#: The width of the simulated camera's scenes (a VGA frame, what the photo chain's detector sees
#: shrunk): a scene made smaller stands for this frame shrunk (its pixel parameters scaled).
PHOTO_SIZE = 640
#: A close-up photo's width in camera pixels and the share of it a print spans (the middle of the
#: photo simulator's 60-80 %): what a camera's pixel parameters are scaled from when the decoder's
#: frame meets them (:func:`camera_shadow`).
CLOSE_UP_PHOTO_PX, SHADOW_FRAME_SHARE = 240, 0.7
#: The misalignment left for the corruption of a model whose renders are registered onto the
#: unmorphed drawing (:mod:`deepmorph_core.registration`), as a share of its ``print_px``
#: residual: what the photo chain's alignment itself gets wrong once the morph's own pull on it
#: is in the training. Aligned to its true morph, a close-up's view is a median 0.04-0.08 px off
#: in the decoder's frame (90th percentile 0.09-0.20, ``bench/first_look.py``); this share of a
#: 200-px print's residual is about 0.18 px rms.
REGISTERED_ALIGNMENT = 0.2
#: Parameters measured in pixels (scaled by ``size / PRESET_SIZE``, or by a photo's shrink).
PIXEL_PARAMS = {("blur", "sigma"), ("defocus", "radius"), ("motion_blur", "length"), ("shadow", "softness")}

Step = tuple[str, float, dict[str, Any]]  # (augmentation name, probability, parameters)


@dataclass(frozen=True)
class PhotoRanges:
    """Where a print lies in a simulated photo (angles in degrees, sizes as shares of the
    frame width; each pair is a range drawn uniformly).

    Attributes:
        tilt_deg: the print's tilt away from the camera, at most.
        size: the drawing's printed width in a scene.
        spin_deg: a close-up's in-plane turn, at most (scenes turn prints any way).
    """

    tilt_deg: float
    size: tuple[float, float]
    spin_deg: float


@dataclass(frozen=True)
class Severity:
    """One level of the table.

    Attributes:
        name: ``none``, ``easy``, ``medium`` or ``hard``.
        residual: the decoder-frame corruption steps ``(name, p, params)``.
        photo: where the photo simulator puts prints (``None`` for ``none``).
        capture: the camera's steps on a whole photo, pixel parameters in camera pixels.
        colour: the colour steps of a colour print (the pipeline's ``"colour"`` stage, on RGB).
    """

    name: str
    residual: tuple[Step, ...] = field(default=())
    photo: PhotoRanges | None = None
    capture: tuple[Step, ...] = field(default=())
    colour: tuple[Step, ...] = field(default=())


def _camera(
    light: float,
    shadow_p: float,
    contrast: tuple[float, float],
    blur: tuple[float, float],
    motion_p: float,
    noise: tuple[float, float],
    jpeg: tuple[float, float],
) -> tuple[Step, ...]:
    """A camera's capture steps: a light gradient and fall-off of strength ``light`` (the gain
    moves by up to ``light / 2`` at the edges and corners), a soft shadow with chance
    ``shadow_p``, a contrast factor, Gaussian blur (sigma), motion blur with chance
    ``motion_p``, sensor noise (sigma) and JPEG quality. The motion smears 3-9 px: the line
    kernel's anti-aliased ends add about a pixel, so its lengths are 1.5-7.5 (the same mean
    second moment, 2.86 px^2, as box smears of 3, 5, 7 and 9 px)."""
    return (
        ("lighting", 1.0, {"gradient": light / 2, "vignette": [0.0, light / 2]}),
        ("shadow", shadow_p, {"strength": [0.2, 0.5], "softness": [2.0, 12.0]}),
        ("intensity", 1.0, {"contrast": list(contrast), "brightness": 0.06}),
        ("blur", 1.0, {"sigma": list(blur)}),
        ("motion_blur", motion_p, {"length": [1.5, 7.5]}),
        ("gaussian_noise", 1.0, {"sigma": list(noise)}),
        ("jpeg", 1.0, {"quality": list(jpeg)}),
    )


SEVERITIES: dict[str, Severity] = {
    "none": Severity("none"),
    "easy": Severity(
        "easy",
        residual=(
            ("perspective", 1.0, {"jitter": 0.02}),
            ("scale", 1.0, {"factor": [0.98, 1.02]}),
            ("rotation", 1.0, {"degrees": 2.0}),
            ("translation", 1.0, {"fraction": 0.01}),
            ("blur", 1.0, {"sigma": [0.0, 0.5]}),
            ("motion_blur", 0.3, {"length": [0.0, 1.5]}),
            ("lighting", 1.0, {"gradient": 0.1, "vignette": [0.0, 0.05]}),
            ("intensity", 1.0, {"contrast": [0.8, 1.05], "brightness": 0.08}),
            ("gaussian_noise", 1.0, {"sigma": [0.0, 0.02]}),
            ("salt_pepper", 0.3, {"amount": [0.0, 0.003]}),
            ("jpeg", 0.5, {"quality": [70.0, 95.0]}),
        ),
        photo=PhotoRanges(30, (0.25, 0.7), 2),
        capture=_camera(0.15, 0.15, (0.8, 1.0), (0.2, 0.7), 0.0, (0.003, 0.012), (80, 95)),
        colour=(
            ("ink_fade", 1.0, {"desaturation": [0.0, 0.1], "black_lift": [0.0, 0.03]}),
            ("paper_tint", 1.0, {"grey": [0.0, 0.015], "warmth": 0.02}),
            ("white_balance", 1.0, {"temperature": 0.04, "tint": 0.02}),
            ("chroma_subsampling", 0.5, {}),
        ),
    ),
    "medium": Severity(
        "medium",
        residual=(
            ("perspective", 1.0, {"jitter": 0.03}),
            ("scale", 1.0, {"factor": [0.96, 1.04]}),
            ("rotation", 1.0, {"degrees": 5.0}),
            ("translation", 1.0, {"fraction": 0.015}),
            ("blur", 1.0, {"sigma": [0.0, 1.0]}),
            ("motion_blur", 0.5, {"length": [0.0, 3.0]}),
            ("lighting", 1.0, {"gradient": 0.2, "vignette": [0.0, 0.1]}),
            ("intensity", 1.0, {"contrast": [0.6, 1.1], "brightness": 0.15}),
            ("gaussian_noise", 1.0, {"sigma": [0.0, 0.04]}),
            ("salt_pepper", 0.5, {"amount": [0.0, 0.01]}),
            ("jpeg", 0.8, {"quality": [40.0, 90.0]}),
        ),
        photo=PhotoRanges(45, (0.15, 0.7), 5),
        capture=_camera(0.3, 0.35, (0.6, 0.95), (0.3, 1.1), 0.15, (0.008, 0.025), (55, 90)),
        colour=(
            ("ink_fade", 1.0, {"desaturation": [0.0, 0.25], "black_lift": [0.0, 0.08]}),
            ("paper_tint", 1.0, {"grey": [0.0, 0.03], "warmth": 0.04}),
            ("white_balance", 1.0, {"temperature": 0.1, "tint": 0.04}),
            ("chroma_subsampling", 1.0, {}),
        ),
    ),
    "hard": Severity(
        "hard",
        residual=(
            ("perspective", 1.0, {"jitter": 0.06}),
            ("scale", 1.0, {"factor": [0.93, 1.07]}),
            ("rotation", 1.0, {"degrees": 10.0}),
            ("translation", 1.0, {"fraction": 0.03}),
            ("blur", 1.0, {"sigma": [0.0, 1.6]}),
            ("defocus", 0.3, {"radius": [0.0, 2.0]}),
            ("motion_blur", 0.6, {"length": [0.0, 5.0]}),
            ("lighting", 1.0, {"gradient": 0.35, "vignette": [0.0, 0.25]}),
            ("intensity", 1.0, {"contrast": [0.4, 1.2], "brightness": 0.25}),
            ("gaussian_noise", 1.0, {"sigma": [0.0, 0.07]}),
            ("salt_pepper", 0.6, {"amount": [0.0, 0.02]}),
            ("jpeg", 0.9, {"quality": [20.0, 80.0]}),
        ),
        photo=PhotoRanges(60, (0.10, 0.7), 10),
        capture=_camera(0.45, 0.5, (0.45, 0.9), (0.4, 1.6), 0.35, (0.015, 0.045), (35, 75)),
        colour=(
            ("ink_fade", 1.0, {"desaturation": [0.0, 0.45], "black_lift": [0.0, 0.15]}),
            ("paper_tint", 1.0, {"grey": [0.0, 0.08], "warmth": 0.08}),
            ("white_balance", 1.0, {"temperature": 0.18, "tint": 0.07, "cast": 0.03}),
            ("chroma_subsampling", 1.0, {}),
        ),
    ),
}

#: Severities from mildest to roughest (training's curriculum climbs them).
LADDER = tuple(SEVERITIES)
#: The severities a photo can have.
PHOTO_SEVERITIES = tuple(k for k, v in SEVERITIES.items() if v.photo is not None)
#: The severity trained models are validated at: renders (:mod:`deepmorph.training.validation`)
#: and close-up photos (:mod:`deepmorph_detect.photo_validation`).
VALIDATION_SEVERITY = "medium"


def severity(name: str) -> Severity:
    """The table's entry for ``name``.

    Raises:
        DeepMorphError: an unknown name, listing the known ones.
    """
    found = SEVERITIES.get(name)
    if found is None:
        raise DeepMorphError(f"unknown severity {name!r} (known: {', '.join(SEVERITIES)})")
    return found


def photo_ranges(name: str) -> PhotoRanges:
    """The photo simulator's ranges of a severity.

    Raises:
        DeepMorphError: an unknown severity, or ``none`` (a photo is never clean).
    """
    photo = severity(name).photo
    if photo is None:
        known = ", ".join(k for k, v in SEVERITIES.items() if v.photo is not None)
        raise DeepMorphError(f"severity {name!r} has no photo settings (photos are {known})")
    return photo


def residual_steps(
    name: str,
    size: int | None = None,
    *,
    colour: bool = False,
    print_px: float | None = None,
    registered: bool = False,
) -> list[Step]:
    """The residual corruption steps of a severity at ``size``-pixel images (:data:`PRESET_SIZE`
    when ``None``); when ``colour`` (a colour drawing's training), with the camera's shadow after
    the light (:func:`camera_shadow`) and followed by the colour steps (for RGB renders; the
    pipeline skips them on gray ones).

    The preset's pixel parameters are pixels of a print :data:`PRESET_SIZE` pixels wide in the
    photo. Without ``print_px`` the frame stands for such a print whatever its width: they are
    scaled by ``size / PRESET_SIZE``, and a wider frame is only a finer picture of the same
    blur. With ``print_px`` the frame shows a print ``print_px`` camera pixels wide: blur,
    motion and shadow are the camera's, in its pixels (scaled by ``size / print_px``), so a
    larger print in the photo keeps more of its morph (``deepmorph train --pixels``).
    ``registered`` (with ``print_px``): the renders are registered onto the unmorphed drawing
    as the photo chain aligns its photos (:mod:`deepmorph_core.registration`), so only
    :data:`REGISTERED_ALIGNMENT` of the misalignment is left."""
    level = severity(name)
    steps = level.residual
    if colour:
        after_light = next((i + 1 for i, (step, _, _) in enumerate(steps) if step == "lighting"), len(steps))
        # with print_px every step is in camera pixels: the shadow's as the camera has it
        shadow = camera_shadow(level, None if print_px is None else PRESET_SIZE)
        steps = steps[:after_light] + shadow + steps[after_light:] + level.colour
    scaled = scaled_steps(steps, (size or PRESET_SIZE) / (print_px or PRESET_SIZE))
    if print_px is None:
        return scaled
    return aligned_steps(scaled, PRESET_SIZE / print_px * (REGISTERED_ALIGNMENT if registered else 1.0))


#: The residual's geometric parameters: how far the framed print is off, as shares of the frame
#: (a scale factor's distance from 1).
ALIGNMENT_PARAMS = {
    ("perspective", "jitter"),
    ("scale", "factor"),
    ("rotation", "degrees"),
    ("translation", "fraction"),
}


def aligned_steps(steps: list[Step], factor: float) -> list[Step]:
    """``steps`` with their geometric residual (:data:`ALIGNMENT_PARAMS`) ``factor`` times as
    large: an alignment in a print ``1 / factor`` times as many pixels wide is off by as many
    of the photo's pixels, so by a smaller share of the print."""
    return _rescaled(steps, factor, ALIGNMENT_PARAMS)


def camera_shadow(level: Severity, print_px: float | None = None) -> tuple[Step, ...]:
    """The camera's shadow step of a severity (:attr:`Severity.capture`), its softness in pixels
    of a :data:`PRESET_SIZE`-pixel frame that shows a print ``print_px`` camera pixels wide (by
    default a close-up's print, :data:`SHADOW_FRAME_SHARE` of a :data:`CLOSE_UP_PHOTO_PX` photo).

    Why a colour drawing trains with it: a shadow as dark as a light ink is an edge the
    decoder never met in training renders. Framed by the alignment and read, shadowed medium
    close-ups of ``face-without-mouth`` that its decoder read at chance read whole once it had
    trained with shadows (``docs/design-notes.md``). Black ink stays far darker than any
    shadow; black-and-white training is unchanged."""
    shadows = [step for step in level.capture if step[0] == "shadow"]
    seen_px = print_px or SHADOW_FRAME_SHARE * CLOSE_UP_PHOTO_PX
    return tuple(scaled_steps(tuple(shadows), PRESET_SIZE / seen_px))


def capture_steps(name: str, shrink: float = 1.0) -> list[Step]:
    """The camera's steps of a photo severity, on a photo as the camera took it (``shrink``
    1) or shrunk to ``shrink`` of its pixels (pixel parameters scaled by it).

    Raises:
        DeepMorphError: an unknown severity, or ``none`` (a photo is never clean).
    """
    photo_ranges(name)
    return scaled_steps(severity(name).capture, shrink)


def scaled_steps(steps: tuple[Step, ...] | list[Step], factor: float) -> list[Step]:
    """``steps`` with their pixel-valued parameters (:data:`PIXEL_PARAMS`) times ``factor``."""
    return _rescaled(steps, factor, PIXEL_PARAMS)


def _rescaled(steps: tuple[Step, ...] | list[Step], factor: float, which: set[tuple[str, str]]) -> list[Step]:
    """``steps`` with the parameters named in ``which`` ``factor`` times as far from their
    neutral value: 0, or 1 for a scale factor (a number or each end of a range)."""

    def rescale(value: float, neutral: float) -> float:
        return neutral + (value - neutral) * factor

    out = []
    for step_name, p, params in steps:
        neutral = 1.0 if step_name == "scale" else 0.0
        changed = {
            key: ([rescale(v, neutral) for v in value] if isinstance(value, list) else rescale(value, neutral))
            if (step_name, key) in which
            else value
            for key, value in params.items()
        }
        out.append((step_name, p, changed))
    return out
