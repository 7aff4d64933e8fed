"""The capture-corruption pipeline: a validated config of steps, presets for print-and-photo
severities, and an ``nn.Module`` that builds the steps from the plugin registry and applies
them in a fixed physical order.

Order (by each augmentation's ``stage``; config order within a stage): geometry (fused into one
warp), optics (blur, defocus, motion blur), lighting, intensity, noise, impulse (salt and
pepper), custom (plugins that name no known stage), compression (JPEG). The output is clamped
to ``[0, 1]``.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any, Literal, Union

import torch
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from torch import Tensor, nn

from deepmorph_augment.base import STAGES
from deepmorph_augment.geometric import warp_chosen
from deepmorph_augment.sampling import check_images
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.plugins import Registry, default_registry

Severity = Literal["none", "easy", "medium", "hard"]
ParamValue = Union[float, list[float], str]

#: Reference image width of the presets' pixel-valued parameters.
PRESET_SIZE = 96
#: Parameters measured in pixels (scaled by ``size / PRESET_SIZE`` in :meth:`AugmentConfig.preset`).
PIXEL_PARAMS = {("blur", "sigma"), ("defocus", "radius"), ("motion_blur", "length")}

# (name, p, params) per severity; "medium" is a phone photo of a print on a desk after rough
# rectification. Pixel values are at PRESET_SIZE.
#: Geometry here is what is left *after* framing: training and decoding both frame a drawing by
#: its ink's centre and spread (deepmorph_core.imaging), which removes the photo's translation
#: and scale; what remains is a little residual scale/shift, rotation and perspective.
_PRESETS: dict[str, list[tuple[str, float, dict[str, Any]]]] = {
    "none": [],
    "easy": [
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
    ],
    "medium": [
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
    ],
    "hard": [
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
    ],
}


class AugmentConfigError(DeepMorphError):
    """An augmentation config that cannot be built; the message names the step."""


class AugmentationSpec(BaseModel):
    """One step: a registered augmentation's name, its probability per sample and its
    constructor parameters (numbers, ``[lo, hi]`` ranges or strings: JSON-safe)."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=64)
    p: float = Field(default=1.0, ge=0.0, le=1.0)
    params: dict[str, ParamValue] = Field(default_factory=dict)


class AugmentConfig(BaseModel):
    """The steps of a pipeline (applied in stage order, not list order); stored in model
    bundles as ``model_dump()`` JSON."""

    model_config = ConfigDict(extra="forbid")

    steps: list[AugmentationSpec] = Field(default_factory=list, max_length=64)

    @classmethod
    def preset(cls, severity: Severity, *, size: int = PRESET_SIZE) -> AugmentConfig:
        """Print-and-photo settings of a severity.

        Args:
            severity: ``"none"`` (no corruption), ``"easy"``, ``"medium"`` (a phone photo of a
                print on a desk after rough rectification) or ``"hard"``.
            size: image width the pixel-valued parameters (blur sigma, defocus radius, motion
                length) are scaled to; the tables are for 96 pixels.
        """
        if severity not in _PRESETS:
            raise AugmentConfigError(f"unknown augmentation severity {severity!r} (known: {', '.join(_PRESETS)})")
        factor = size / PRESET_SIZE
        steps = []
        for name, p, params in _PRESETS[severity]:
            scaled = {
                key: ([v * factor for v in value] if isinstance(value, list) else value * factor)
                if (name, key) in PIXEL_PARAMS
                else value
                for key, value in params.items()
            }
            steps.append(AugmentationSpec(name=name, p=p, params=scaled))
        return cls(steps=steps)

    @classmethod
    def parse(cls, data: AugmentConfig | Mapping[str, Any]) -> AugmentConfig:
        """Validate ``data`` (e.g. from JSON).

        Raises:
            AugmentConfigError: one ``steps[i] 'name': field: problem`` line per problem.
        """
        if isinstance(data, AugmentConfig):
            return data
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise AugmentConfigError(_describe(exc, data)) from None


def _step_label(data: Any, index: int) -> str:
    try:
        return f"steps[{index}] {data['steps'][index]['name']!r}"
    except (KeyError, IndexError, TypeError):
        return f"steps[{index}]"


def _describe(exc: ValidationError, data: Any) -> str:
    lines = []
    for err in exc.errors():
        loc, msg = list(err["loc"]), err["msg"].removeprefix("Value error, ")
        where = "augment config"
        if len(loc) >= 2 and loc[0] == "steps" and isinstance(loc[1], int):
            where, loc = _step_label(data, loc[1]), loc[2:]
        field = ".".join(str(x) for x in loc)
        lines.append(f"{where}: {field}: {msg}" if field else f"{where}: {msg}")
    return "; ".join(lines)


def _build_step(index: int, spec: AugmentationSpec, registry: Registry) -> Any:
    label = f"steps[{index}] {spec.name!r}"
    registration = registry.augmentations.get(spec.name)
    if registration is None:
        known = ", ".join(sorted(registry.augmentations)) or "none registered"
        raise AugmentConfigError(f"{label}: unknown augmentation (known: {known})")
    cls = registration.obj
    if "p" in spec.params:
        raise AugmentConfigError(f"{label}: give p as the step's own field, not in params")
    signature = inspect.signature(cls)
    if not any(par.kind is inspect.Parameter.VAR_KEYWORD for par in signature.parameters.values()):
        known = [n for n, par in signature.parameters.items() if par.kind is not inspect.Parameter.VAR_POSITIONAL]
        unknown = sorted(set(spec.params) - set(known))
        if unknown:
            raise AugmentConfigError(
                f"{label}: unknown parameter{'s' if len(unknown) > 1 else ''} {', '.join(unknown)} "
                f"(known: {', '.join(known)})"
            )
    try:
        return cls(p=spec.p, **spec.params)
    except (TypeError, ValueError) as exc:
        raise AugmentConfigError(f"{label}: {exc}") from None


def _stage(step: Any) -> int:
    stage = getattr(step, "stage", "custom")
    return STAGES.index(stage if stage in STAGES else "custom")


class AugmentPipeline(nn.Module):
    """Applies a config's augmentations in stage order, differentiably.

    Consecutive geometric steps (those with ``draw_matrices``) are composed into one warp, so
    the image is resampled once; their random draws are the same as applying them one by one.

    Args:
        config: the steps (an :class:`AugmentConfig` or its ``model_dump()``).
        registry: where step names are looked up; the process-wide default when ``None``.

    Raises:
        AugmentConfigError: an invalid config, an unknown augmentation or parameter, or a
            parameter the augmentation refuses; the message names the step.
    """

    def __init__(self, config: AugmentConfig | Mapping[str, Any], registry: Registry | None = None):
        super().__init__()
        self.config = AugmentConfig.parse(config)
        registry = registry if registry is not None else default_registry()
        built = [_build_step(i, spec, registry) for i, spec in enumerate(self.config.steps)]
        order = sorted(range(len(built)), key=lambda i: (_stage(built[i]), i))
        self.steps = [built[i] for i in order]
        self._runs: list[Any] = []  # an augmentation, or a list of geometric ones to fuse
        for step in self.steps:
            if hasattr(step, "draw_matrices"):
                if self._runs and isinstance(self._runs[-1], list):
                    self._runs[-1].append(step)
                else:
                    self._runs.append([step])
            else:
                self._runs.append(step)

    def forward(self, images: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Corrupt ``images`` (``(B, 1, H, W)`` in ``[0, 1]``, white paper = 1).

        Shape:
            images: ``(B, C, H, W)``; returns the same shape, device and dtype, in ``[0, 1]``.
        """
        check_images(images, "augment")
        out = images
        for run in self._runs:
            if isinstance(run, list):
                out = self._warp(run, out, generator)
            else:
                out = run(out, generator)
        return out.clamp(0.0, 1.0)

    @staticmethod
    def _warp(steps: list[Any], images: Tensor, generator: torch.Generator | None) -> Tensor:
        chosen, matrix = steps[0].draw_matrices(images, generator)
        for step in steps[1:]:
            c, m = step.draw_matrices(images, generator)
            chosen, matrix = chosen | c, m @ matrix
        return warp_chosen(images, chosen, matrix)

    def extra_repr(self) -> str:
        return "\n".join(repr(step) for step in self.steps)
