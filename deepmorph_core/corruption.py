"""The capture-corruption pipeline: a validated config of steps and an ``nn.Module`` that
builds the steps from the plugin registry and applies them in a fixed physical order.

Order (by each augmentation's ``stage``, :data:`~deepmorph_core.protocols.STAGES`; config
order within a stage): colour (ink, paper, white balance, chroma subsampling: RGB images
only), then the conversion to luminance (or the channel the model reads), geometry (fused
into one warp), optics (blur, defocus, motion blur), lighting, intensity, noise, impulse (salt
and pepper), custom (plugins that name no known stage), compression (JPEG). Gray images skip
the colour stage; the output is always gray, clamped to ``[0, 1]``. The severity presets are
:mod:`deepmorph_core.severity`'s; the corruptions themselves are plugins
(:mod:`deepmorph_augment` holds the built-in ones).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from typing import Any, Union

import torch
from kornia.geometry.transform import warp_perspective
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from torch import Tensor, nn

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, to_channel
from deepmorph_core.plugins import Registry, default_registry
from deepmorph_core.protocols import STAGES
from deepmorph_core.severity import capture_steps, residual_steps

ParamValue = Union[float, list[float], str]


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
    def preset(
        cls,
        severity: str,
        *,
        size: int | None = None,
        colour: bool = False,
        print_px: float | None = None,
        registered: bool = False,
    ) -> AugmentConfig:
        """The decoder-frame corruption of a severity (:data:`deepmorph_core.severity.SEVERITIES`)
        at images ``size`` pixels wide showing a print ``print_px`` camera pixels wide, of renders
        ``registered`` onto the unmorphed drawing or not
        (:func:`~deepmorph_core.severity.residual_steps`), with its colour steps appended when
        ``colour``."""
        steps = residual_steps(severity, size, colour=colour, print_px=print_px, registered=registered)
        return cls(steps=[AugmentationSpec(name=n, p=p, params=params) for n, p, params in steps])

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


_COLOUR = STAGES.index("colour")


class AugmentPipeline(nn.Module):
    """Applies a config's augmentations in stage order, differentiably.

    RGB images go through the ``"colour"`` steps, then are converted to luminance (or the
    gray of :attr:`channel`: :func:`~deepmorph_core.luminance.to_channel`) for the other
    steps; gray images skip the colour steps (no draws either). Consecutive geometric steps
    (those with ``draw_matrices``) are composed into one warp, so the image is resampled once;
    their random draws are the same as applying them one by one.

    Args:
        config: the steps (an :class:`AugmentConfig` or its ``model_dump()``).
        registry: where step names are looked up; the process-wide default when ``None``.
        channel: the gray RGB images become after the colour stage: luminance, or the channel
            the model reads (:mod:`deepmorph_core.reading_channel`).

    Raises:
        AugmentConfigError: an invalid config, an unknown augmentation or parameter, or a
            parameter the augmentation refuses; the message names the step.
    """

    def __init__(
        self,
        config: AugmentConfig | Mapping[str, Any],
        registry: Registry | None = None,
        channel: Channel = LUMA_WEIGHTS,
    ):
        super().__init__()
        self.config = AugmentConfig.parse(config)
        self.channel = channel
        registry = registry if registry is not None else default_registry()
        built = [_build_step(i, spec, registry) for i, spec in enumerate(self.config.steps)]
        order = sorted(range(len(built)), key=lambda i: (_stage(built[i]), i))
        self.steps = [built[i] for i in order]
        self._colour = [step for step in self.steps if _stage(step) == _COLOUR]
        self._runs: list[Any] = []  # an augmentation, or a list of geometric ones to fuse
        for step in self.steps[len(self._colour) :]:
            if hasattr(step, "draw_matrices"):
                if self._runs and isinstance(self._runs[-1], list):
                    self._runs[-1].append(step)
                else:
                    self._runs.append([step])
            else:
                self._runs.append(step)

    def colour_only(self, images: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Only the colour stage, then luminance (or :attr:`channel`): how a colour print and the camera's colour
        handling reach the gray photo chain, for photo simulators that do their own geometry,
        optics and noise.

        Shape:
            images: ``(B, 3, H, W)`` RGB (or ``(B, 1, H, W)``, returned as it is); returns
            ``(B, 1, H, W)`` in ``[0, 1]``.
        """
        return to_channel(self.colour_stage(images, generator), self.channel).clamp(0.0, 1.0)

    def colour_stage(self, images: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Only the colour stage, images kept as they are (RGB stays RGB): a colour print as a
        colour photo shows it, for photo simulators that keep the photo in colour.

        Shape:
            images: ``(B, 3, H, W)`` RGB (or ``(B, 1, H, W)``, returned as it is); returns the same.
        """
        out = images
        if images.shape[1] == 3:
            for step in self._colour:
                out = step(out, generator)
        return out

    def capture(self, images: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """The steps after the colour and geometric stages on every channel as it is (no
        conversion to luminance), clamped to ``[0, 1]``: what a camera does to a whole photo
        whose prints a simulator has already coloured and placed in 3-D
        (:mod:`deepmorph_detect.scenes`). Geometric steps are skipped: the simulator's pose
        is the geometry.

        Shape:
            images: ``(B, C, H, W)`` (RGB photos: ``C = 3``); returns the same.
        """
        check_images(images, "capture")
        out = images
        for run in self._runs:
            if not isinstance(run, list):
                out = run(out, generator)
        return out.clamp(0.0, 1.0)

    def forward(self, images: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Corrupt ``images`` (gray or RGB in ``[0, 1]``, white paper = 1).

        Shape:
            images: ``(B, 1, H, W)`` or ``(B, 3, H, W)``; returns ``(B, 1, H, W)``, same device
            and dtype, in ``[0, 1]``.

        Raises:
            ValueError: not a floating batch of 1 or 3 channels.
        """
        check_images(images, "augment")
        if images.shape[1] not in (1, 3):
            shape = tuple(images.shape)
            raise ValueError(f"augment: expected gray (B, 1, H, W) or RGB (B, 3, H, W) images, got {shape}")
        out = images
        if images.shape[1] == 3:
            for step in self._colour:
                out = step(out, generator)
            out = to_channel(out, self.channel)
        for run in self._runs:
            if isinstance(run, list):
                out = self._warp(run, out, generator)
            else:
                out = run(out, generator)
        return out.clamp(0.0, 1.0)

    @staticmethod
    def _warp(steps: list[Any], images: Tensor, generator: torch.Generator | None) -> Tensor:
        return warp_chosen(images, *fused_matrices(steps, images, generator))

    def extra_repr(self) -> str:
        return "\n".join(repr(step) for step in self.steps)


def check_images(images: Tensor, where: str) -> None:
    """Raise ``ValueError`` naming ``where`` unless ``images`` is a floating ``(B, C, H, W)``
    batch (any channel count is accepted: RGB for the colour steps, and the others treat
    channels alike)."""
    if not isinstance(images, Tensor):
        raise ValueError(f"{where}: expected a tensor, got {type(images).__name__}")
    if images.dim() != 4:
        raise ValueError(f"{where}: expected images of shape (B, C, H, W), got {tuple(images.shape)}")
    if not images.is_floating_point():
        raise ValueError(f"{where}: expected floating images, got {images.dtype}")


def apply_to(images: Tensor, chosen: Tensor, fn: Callable[[Tensor, Tensor | slice], Tensor]) -> Tensor:
    """``fn`` applied to the chosen samples only, the others passed through unchanged.

    Args:
        images: the batch.
        chosen: ``(B,)`` bool.
        fn: called as ``fn(images[idx], idx)`` with the chosen indices (a full slice when all are).

    Shape:
        images: ``(B, C, H, W)``; returns the same.
    """
    idx = chosen.nonzero().squeeze(1)
    if idx.numel() == 0:
        return images
    if idx.numel() == images.shape[0]:
        return fn(images, slice(None))
    return images.index_copy(0, idx, fn(images[idx], idx))


def fused_matrices(steps: list[Any], images: Tensor, generator: torch.Generator | None) -> tuple[Tensor, Tensor]:
    """One warp for consecutive geometric ``steps``: the samples any of them chose, and the
    product of their matrices (the first step's applied first).

    Shape:
        images: ``(B, C, H, W)``; returns ``(B,)`` bool and ``(B, 3, 3)`` pixel-space matrices.
    """
    chosen, matrix = steps[0].draw_matrices(images, generator)
    for step in steps[1:]:
        c, m = step.draw_matrices(images, generator)
        chosen, matrix = chosen | c, m @ matrix
    return chosen, matrix


def warp_white(images: Tensor, matrix: Tensor) -> Tensor:
    """Warp ``images`` by ``matrix`` (source pixel -> destination pixel), bilinear, with
    everything outside the source filled white (paper).

    White fill is done as ``1 - warp(1 - images)`` with zero padding: exact, and one grid
    sample where kornia's ``padding_mode="fill"`` takes two (it warps a mask of ones too).

    Shape:
        images: ``(B, C, H, W)``; matrix: ``(B, 3, 3)`` in pixel coordinates (``x`` right,
        ``y`` down, pixel centres at integers); returns ``(B, C, H, W)``.
    """
    if matrix.shape != (images.shape[0], 3, 3):
        raise ValueError(f"warp_white: expected matrix of shape ({images.shape[0]}, 3, 3), got {tuple(matrix.shape)}")
    size = (images.shape[-2], images.shape[-1])
    return 1.0 - warp_perspective(1.0 - images, matrix.to(images.dtype), size, align_corners=True)


def warp_chosen(images: Tensor, chosen: Tensor, matrix: Tensor) -> Tensor:
    """:func:`warp_white` on the chosen samples only.

    Shape:
        images: ``(B, C, H, W)``; chosen: ``(B,)`` bool; matrix: ``(B, 3, 3)``.
    """
    return apply_to(images, chosen, lambda x, idx: warp_white(x, matrix[idx]))


def added_steps(severity: str, config: Mapping[str, Any] | None, width: int) -> list[AugmentationSpec]:
    """The steps of a stored training ``config`` that its severity's preset lacks (by name):
    the corruptions a user or a plugin added to training, which photo simulators add to their
    capture so that what a model was trained against also reaches its validation and benchmarks."""
    if not config:
        return []
    preset = {spec.name for spec in AugmentConfig.preset(severity, size=width, colour=True).steps}
    return [spec for spec in AugmentConfig.parse(config).steps if spec.name not in preset]


def capture_pipeline(
    severity: str, shrink: float = 1.0, extra: list[AugmentationSpec] | None = None
) -> AugmentPipeline:
    """The camera's steps of a photo severity on photos as taken (``shrink`` 1) or shrunk
    (:func:`deepmorph_core.severity.capture_steps`), plus ``extra`` steps, through the
    registered plugins; applied with :meth:`AugmentPipeline.capture`.

    Raises:
        DeepMorphError: an unknown severity or ``none``; AugmentConfigError: a bad extra step.
    """
    steps = [AugmentationSpec(name=n, p=p, params=params) for n, p, params in capture_steps(severity, shrink)]
    return AugmentPipeline(AugmentConfig(steps=steps + list(extra or [])))


def build_pipeline(
    severity: str,
    width: int,
    config: dict[str, Any] | None = None,
    *,
    colour: bool = False,
    print_px: float | None = None,
    channel: Channel = LUMA_WEIGHTS,
    registered: bool = False,
) -> AugmentPipeline:
    """The corruption pipeline of a severity preset at an image width (showing a print
    ``print_px`` camera pixels wide, its renders ``registered`` or not: :meth:`AugmentConfig.preset`),
    with its colour steps when ``colour`` (or of a stored config), whose RGB images become the
    gray of ``channel``."""
    cfg = (
        AugmentConfig.parse(config)
        if config
        else AugmentConfig.preset(severity, size=width, colour=colour, print_px=print_px, registered=registered)
    )
    return AugmentPipeline(cfg, channel=channel)
