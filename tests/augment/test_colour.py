"""The colour corruptions and the pipeline's colour stage: registration, shapes, neutral
parameters, gradients, gray input left alone without a draw, what each one does to colours,
chroma subsampling against Pillow's JPEG, luminance against OpenCV, and the severity presets'
colour steps."""

from __future__ import annotations

import io

import cv2
import numpy as np
import pytest
import torch
from kornia.color import rgb_to_ycbcr
from PIL import Image

import deepmorph_augment.plugin as augment_plugin
from deepmorph_augment.colour import (
    PaperTint,
    WhiteBalance,
    fade_ink,
    paper_tint,
    subsample_chroma,
    white_balance_gains,
)
from deepmorph_core.corruption import AugmentConfig, AugmentConfigError, AugmentPipeline
from deepmorph_core.luminance import to_luminance
from deepmorph_core.plugins import Registry, default_registry, load_registry
from deepmorph_core.protocols import STAGES, Augmentation
from deepmorph_core.severity import CLOSE_UP_PHOTO_PX, SEVERITIES, SHADOW_FRAME_SHARE, residual_steps

torch.set_num_threads(1)

STRONG: dict[str, dict] = {
    "ink_fade": {"desaturation": [0.4, 0.6], "black_lift": [0.1, 0.2]},
    "paper_tint": {"grey": [0.05, 0.1], "warmth": [0.05, 0.1]},
    "white_balance": {"temperature": [0.1, 0.2], "tint": 0.05, "cast": 0.02},
    "chroma_subsampling": {},
}
NAMES = sorted(STRONG)
NEUTRAL: dict[str, dict] = {
    "ink_fade": {"desaturation": 0.0, "black_lift": 0.0},
    "paper_tint": {"grey": 0.0, "warmth": 0.0},
    "white_balance": {"temperature": 0.0, "tint": 0.0, "cast": 0.0},
}


@pytest.fixture(scope="module")
def registry() -> Registry:
    return load_registry([augment_plugin], entry_points=False)


def make(registry: Registry, name: str, p: float = 1.0, **overrides):
    return registry.augmentations[name].obj(p=p, **{**STRONG[name], **overrides})


def seeded(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def colour_drawing(batch: int = 4, size: int = 32, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """White paper with a red bar, a blue ring, a black square and fine green stripes
    (1 pixel wide: chroma detail), different in every sample."""
    y, x = torch.meshgrid(torch.arange(size, dtype=dtype), torch.arange(size, dtype=dtype), indexing="ij")
    images = torch.ones(batch, 3, size, size, dtype=dtype)
    for i in range(batch):
        c = size / 2 + i - batch / 2
        ring = torch.sigmoid(4 * (1.5 - (((x - c) ** 2 + (y - size / 2) ** 2).sqrt() - size / 4).abs()))
        images[i] -= ring * torch.tensor([0.9, 0.7, 0.1], dtype=dtype)[:, None, None]
        images[i, :, 4 : size - 4, 3 + i : 6 + i] = torch.tensor([0.9, 0.1, 0.1], dtype=dtype)[:, None, None]
        images[i, :, 2:8, size - 10 : size - 3] = 0.0
        images[i, 0, size - 6 : size - 2, 2 : size - 2 : 2] = 0.2
        images[i, 2, size - 6 : size - 2, 2 : size - 2 : 2] = 0.2
    return images


def test_colour_steps_are_registered_through_the_plugin(registry: Registry) -> None:
    # The module's own registry, and the process-wide one that pipelines use by default.
    for reg in (registry, default_registry()):
        for name in NAMES:
            found = reg.augmentations[name]
            assert found.plugin == augment_plugin.__name__
            assert found.obj.name == name and found.obj.stage == "colour"
            assert isinstance(found.obj(), Augmentation)
    assert STAGES[0] == "colour"


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_shape_dtype_range_and_effect(registry: Registry, name: str, dtype: torch.dtype) -> None:
    images = colour_drawing(dtype=dtype)
    out = make(registry, name)(images, seeded())
    assert out.shape == images.shape and out.dtype == dtype and out.device == images.device
    assert out.min() >= 0.0 and out.max() <= 1.0
    assert (out - images).abs().amax(dim=(1, 2, 3)).min() > 1e-2, "every sample should change at p=1"


@pytest.mark.parametrize("name", sorted(NEUTRAL))
def test_neutral_parameters_are_identity(registry: Registry, name: str) -> None:
    images = colour_drawing()
    assert torch.equal(make(registry, name, **NEUTRAL[name])(images, seeded()), images)


def test_chroma_subsampling_leaves_flat_chroma_alone() -> None:
    images = colour_drawing(batch=2)
    gray = images.mean(1, keepdim=True).expand(-1, 3, -1, -1)  # no chroma at all
    torch.testing.assert_close(subsample_chroma(gray), gray, atol=1e-6, rtol=0)
    # Colour constant over each 2x2 block survives nearest upsampling.
    blocks = torch.rand(2, 3, 8, 8, generator=seeded(3)).repeat_interleave(2, -2).repeat_interleave(2, -1)
    torch.testing.assert_close(subsample_chroma(blocks, "nearest"), blocks, atol=1e-6, rtol=0)


@pytest.mark.parametrize("name", NAMES)
def test_p_zero_is_identity_and_replays(registry: Registry, name: str) -> None:
    images = colour_drawing(batch=8)
    assert torch.equal(make(registry, name, p=0.0)(images, seeded()), images)
    aug = make(registry, name, p=0.5)
    first = aug(images, seeded(3))
    assert torch.equal(first, aug(images, seeded(3)))
    changed = (first - images).abs().amax(dim=(1, 2, 3)) > 1e-6
    assert 0 < int(changed.sum()) < 8


@pytest.mark.parametrize("name", NAMES)
def test_gradcheck_float64(registry: Registry, name: str) -> None:
    aug = make(registry, name, p=0.75)
    images = (0.05 + 0.9 * torch.rand(3, 3, 8, 8, dtype=torch.float64, generator=seeded(5))).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: aug(x, seeded(2)), (images,))


@pytest.mark.parametrize("name", NAMES)
def test_backward_through_a_drawing_is_finite(registry: Registry, name: str) -> None:
    images = colour_drawing().requires_grad_(True)
    weights = torch.rand(images.shape, generator=seeded(1))
    (make(registry, name)(images, seeded()) * weights).sum().backward()
    assert torch.isfinite(images.grad).all() and images.grad.abs().sum() > 0


@pytest.mark.parametrize("name", NAMES)
def test_gray_input_is_untouched_and_draws_nothing(registry: Registry, name: str) -> None:
    gray = colour_drawing()[:, :1]
    generator = seeded(9)
    state = generator.get_state()
    out = make(registry, name)(gray, generator)
    assert out is gray
    assert torch.equal(generator.get_state(), state)


def test_other_channel_counts_are_refused(registry: Registry) -> None:
    with pytest.raises(ValueError, match=r"ink_fade: expected RGB \(B, 3, H, W\) or gray \(B, 1, H, W\)"):
        make(registry, "ink_fade")(torch.ones(2, 2, 8, 8))
    with pytest.raises(ValueError, match=r"augment: expected gray \(B, 1, H, W\) or RGB \(B, 3, H, W\)"):
        AugmentPipeline({"steps": []}, registry)(torch.ones(2, 4, 8, 8))


def test_ink_fade_moves_colour_toward_luminance_and_lifts_black() -> None:
    images = colour_drawing(batch=2, dtype=torch.float64)
    lum = to_luminance(images)
    gray = fade_ink(images, torch.ones(2, dtype=torch.float64), torch.zeros(2, dtype=torch.float64))
    torch.testing.assert_close(gray, lum.expand(-1, 3, -1, -1))
    half = fade_ink(images, torch.full((2,), 0.5, dtype=torch.float64), torch.zeros(2, dtype=torch.float64))
    torch.testing.assert_close(half, (images + lum) / 2)
    torch.testing.assert_close(to_luminance(half), lum)  # desaturation keeps luminance
    ends = fade_ink(
        torch.tensor([0.0, 1.0]).reshape(2, 1, 1, 1).expand(-1, 3, 1, 1), torch.zeros(2), torch.full((2,), 0.2)
    )
    assert ends[0].flatten().tolist() == pytest.approx([0.2] * 3)  # black lifted
    assert ends[1].flatten().tolist() == pytest.approx([1.0] * 3)  # paper stays white


def test_paper_tint_colours_paper_and_keeps_black() -> None:
    tint = paper_tint(torch.tensor([0.0, 0.0, 0.1]), torch.tensor([0.08, -0.08, 0.0]))
    assert tint[0].tolist() == pytest.approx([1.0, 0.98, 0.92])  # cream: blue absorbed
    assert tint[1].tolist() == pytest.approx([0.92, 0.98, 1.0])  # bluish: red absorbed
    assert tint[2].tolist() == pytest.approx([0.9, 0.9, 0.9])  # grey
    images = torch.zeros(2, 3, 4, 4)
    images[:, :, :, 2:] = 1.0  # left half black ink, right half paper
    out = PaperTint(grey=[0.1, 0.1], warmth=[0.08, 0.08])(images, seeded())
    assert out[:, :, :, :2].abs().max() == 0.0
    assert out[0, :, 0, 3].tolist() == pytest.approx([0.9, 0.9 * 0.98, 0.9 * 0.92])


def test_white_balance_keeps_the_luminance_of_grays() -> None:
    gains = white_balance_gains(torch.tensor([0.2, -0.2, 0.0]), torch.tensor([0.0, 0.05, -0.1]))
    weights = torch.tensor([0.299, 0.587, 0.114])
    torch.testing.assert_close(gains @ weights, torch.ones(3))
    assert gains[0, 0] > 1.1 and gains[0, 2] < 0.85  # warm: red up, blue down
    assert gains[1, 0] < 0.85 and gains[1, 2] > 1.1  # cool
    mid = torch.full((3, 3, 4, 4), 0.5)
    out = WhiteBalance(temperature=0.2, tint=0.1)(mid, seeded())
    torch.testing.assert_close(to_luminance(out), torch.full((3, 1, 4, 4), 0.5))
    assert (out.amax(1) - out.amin(1)).min() > 0.05  # but it is coloured


def test_chroma_subsampling_keeps_luminance_before_clipping() -> None:
    images = torch.rand(2, 3, 17, 22, dtype=torch.float64, generator=seeded(4))
    out = subsample_chroma(images)
    unclipped = ((out > 0) & (out < 1)).all(1, keepdim=True)
    assert unclipped.float().mean() > 0.3
    diff = (to_luminance(out) - to_luminance(images)).abs()
    assert diff[unclipped].max() < 1e-5
    assert diff.max() > 1e-3  # where it clips, it shows
    # Mild colours never clip: luminance is kept everywhere, in float32 too.
    mild = 0.5 + 0.2 * (torch.rand(2, 3, 16, 16, generator=seeded(6)) - 0.5)
    assert (to_luminance(subsample_chroma(mild)) - to_luminance(mild)).abs().max() < 1e-5


def test_chroma_subsampling_removes_a_checkerboards_chroma() -> None:
    yy, xx = torch.meshgrid(torch.arange(8), torch.arange(8), indexing="ij")
    red = ((yy + xx) % 2 == 0).double()
    board = torch.stack([red, 1 - red, torch.zeros_like(red)])[None]  # 1-pixel red/green checkerboard

    def chroma_contrast(images: torch.Tensor) -> float:
        c = rgb_to_ycbcr(images)[:, 1:]
        return float((c[..., 1:] - c[..., :-1]).abs().mean())

    before = chroma_contrast(board)
    assert before > 0.5
    for upsample in ("bilinear", "nearest"):
        assert chroma_contrast(subsample_chroma(board, upsample)) < 0.1 * before


def test_chroma_subsampling_matches_pillow_420() -> None:
    """Against libjpeg's 4:2:0 through Pillow at quality 100 (where its DCT rounding is all
    that is left): bilinear is libjpeg's fancy upsampling; 4:4:4 shows what is at stake."""
    h, w = 45, 47
    yy, xx = np.mgrid[0:h, 0:w]
    rng = np.random.default_rng(0)
    rgb = np.stack(
        [0.5 + 0.4 * np.sin(xx / 3 + yy / 5), 0.5 + 0.4 * np.cos(yy / 2.5), 0.5 + 0.4 * np.sin((xx - yy) / 4)], -1
    )
    pixels = (np.clip(rgb + rng.normal(0, 0.05, rgb.shape), 0, 1) * 255).round().astype(np.uint8)

    def pillow(subsampling: int) -> np.ndarray:
        buffer = io.BytesIO()
        Image.fromarray(pixels).save(buffer, format="JPEG", quality=100, subsampling=subsampling)
        return np.asarray(Image.open(buffer)).astype(np.float64) / 255.0

    ours = subsample_chroma(torch.from_numpy(pixels / 255.0).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()
    error = np.abs(ours - pillow(2)) * 255
    assert error.mean() < 1.0 and error.max() < 6.0
    assert (np.abs(pixels / 255.0 - pillow(2)) * 255).mean() > 5.0
    nearest = subsample_chroma(torch.from_numpy(pixels / 255.0).permute(2, 0, 1)[None], "nearest")
    assert (np.abs(nearest[0].permute(1, 2, 0).numpy() - pillow(2)) * 255).mean() > 5 * error.mean()


def test_to_luminance_matches_opencv() -> None:
    pixels = np.random.default_rng(1).integers(0, 256, (37, 41, 3), dtype=np.uint8)
    reference = cv2.cvtColor(pixels, cv2.COLOR_RGB2GRAY).astype(np.float64) / 255.0
    ours = to_luminance(torch.from_numpy(pixels / 255.0).permute(2, 0, 1)[None])[0, 0].numpy()
    assert np.abs(ours - reference).max() <= 1.0 / 255.0
    assert np.abs(ours - reference).mean() < 0.3 / 255.0
    gray = torch.rand(2, 1, 5, 5)
    assert to_luminance(gray) is gray
    with pytest.raises(ValueError, match="to_channel: expected"):
        to_luminance(torch.rand(2, 2, 5, 5))


def test_pipeline_without_steps_reads_luminance(registry: Registry) -> None:
    images = colour_drawing()
    out = AugmentPipeline({"steps": []}, registry)(images, seeded())
    assert out.shape == (4, 1, 32, 32)
    torch.testing.assert_close(out, to_luminance(images).clamp(0, 1), atol=1e-7, rtol=0)
    assert abs(float(out[0, 0, 0, 0]) - 1.0) < 1e-6  # paper
    assert abs(float(out[0, 0, 10, 4]) - (0.299 * 0.9 + 0.587 * 0.1 + 0.114 * 0.1)) < 1e-6  # red bar


def test_pipeline_runs_colour_steps_first_then_gray_ones(registry: Registry) -> None:
    config = {
        "steps": [{"name": "blur", "params": {"sigma": [1.0, 1.0]}}, {"name": "ink_fade", "params": STRONG["ink_fade"]}]
    }
    pipe = AugmentPipeline(config, registry)
    assert [s.name for s in pipe.steps] == ["ink_fade", "blur"]
    images = colour_drawing()
    generator = seeded(2)
    faded = to_luminance(make(registry, "ink_fade")(images, generator))
    expected = registry.augmentations["blur"].obj(sigma=[1.0, 1.0])(faded, generator).clamp(0, 1)
    torch.testing.assert_close(pipe(images, seeded(2)), expected)


@pytest.mark.parametrize("severity", ["none", "easy", "medium", "hard"])
def test_gray_pipelines_skip_the_colour_steps(registry: Registry, severity: str) -> None:
    """A colour preset run on gray images is its steps without the colour ones."""
    gray = colour_drawing(batch=6)[:, :1]
    preset = AugmentConfig.preset(severity, colour=True)
    colour_names = {name for name, _, _ in SEVERITIES[severity].colour}
    without = AugmentConfig(steps=[step for step in preset.steps if step.name not in colour_names])
    plain = AugmentPipeline(without, registry)(gray, seeded(5))
    coloured = AugmentPipeline(preset, registry)(gray, seeded(5))
    assert torch.equal(plain, coloured)


@pytest.mark.parametrize("severity", ["easy", "medium", "hard"])
def test_colour_presets_build_and_run(registry: Registry, severity: str) -> None:
    pipe = AugmentPipeline(AugmentConfig.preset(severity, colour=True), registry)
    assert [s.name for s in pipe.steps][:4] == ["ink_fade", "paper_tint", "white_balance", "chroma_subsampling"]
    images = colour_drawing(batch=6).requires_grad_(True)
    out = pipe(images, seeded())
    assert out.shape == (6, 1, 32, 32) and 0.0 <= out.min() and out.max() <= 1.0
    assert torch.equal(out, pipe(images, seeded()))
    out.sum().backward()
    assert torch.isfinite(images.grad).all() and images.grad.abs().sum() > 0


def test_colour_steps_grow_with_severity(registry: Registry) -> None:
    images = colour_drawing(batch=16)
    errors = []
    for severity in ("none", "easy", "medium", "hard"):
        steps = [{"name": n, "p": p, "params": params} for n, p, params in SEVERITIES[severity].colour]
        out = AugmentPipeline({"steps": steps}, registry)(images, seeded())
        errors.append(float((out - to_luminance(images).clamp(0, 1)).abs().mean()))
    assert errors == sorted(errors) and errors[0] == 0.0 and errors[1] > 1e-3


def test_presets_only_gain_colour_steps_and_the_cameras_shadow_when_asked() -> None:
    """A colour drawing's training meets the camera's shadow (its chance and strength, softness
    in the decoder frame's pixels) after the light, then the colour steps; black and white
    training is the residual alone."""
    for severity in ("none", "easy", "medium", "hard"):
        plain = residual_steps(severity, 192)
        assert [n for n, _, _ in plain] == [n for n, _, _ in SEVERITIES[severity].residual]
        coloured = residual_steps(severity, 192, colour=True)
        shadow = [] if severity == "none" else ["shadow"]
        assert [n for n, _, _ in coloured if n != "shadow"][: len(plain)] == [n for n, _, _ in plain]
        assert [n for n, _, _ in coloured[len(plain) + len(shadow) :]] == (
            [] if severity == "none" else ["ink_fade", "paper_tint", "white_balance", "chroma_subsampling"]
        )
        if shadow:
            names = [n for n, _, _ in coloured]
            assert names.index("shadow") == names.index("lighting") + 1
            camera = next(step for step in SEVERITIES[severity].capture if step[0] == "shadow")
            _, p, params = coloured[names.index("shadow")]
            assert p == camera[1] and params["strength"] == camera[2]["strength"]
            scale = 192 / (SHADOW_FRAME_SHARE * CLOSE_UP_PHOTO_PX)
            assert params["softness"] == pytest.approx([v * scale for v in camera[2]["softness"]])
        assert AugmentConfig.preset(severity, size=192) == AugmentConfig(
            steps=[s for s in AugmentConfig.preset(severity, size=192, colour=True).steps if s.name != "shadow"][
                : len(plain)
            ]
        )
    medium = {n: (p, params) for n, p, params in residual_steps("medium", colour=True)}
    assert medium["chroma_subsampling"][0] == 1.0
    assert medium["paper_tint"][1] == {"grey": [0.0, 0.03], "warmth": 0.04}
    assert medium["white_balance"][1]["temperature"] == 0.1


def test_a_print_of_known_pixels_meets_the_cameras_own_pixels() -> None:
    """With ``print_px`` (``train --pixels``) every pixel parameter, the shadow's too, is the
    camera's, scaled from a print that many pixels wide to the frame: a 192-px frame of a
    200-px print blurs by 0.96 of the preset, where a 96-px model's 192-px frame blurs by 2.
    Its residual misalignment is the preset's in pixels of a 96-px print, a smaller share."""
    for severity in ("easy", "medium", "hard"):
        wide = {n: params for n, _, params in residual_steps(severity, 192, colour=True, print_px=200)}
        old = {n: params for n, _, params in residual_steps(severity, 192, colour=True)}
        preset = {n: params for n, _, params in SEVERITIES[severity].residual}
        assert wide["blur"]["sigma"] == pytest.approx([v * 0.96 for v in preset["blur"]["sigma"]])
        assert old["blur"]["sigma"] == pytest.approx([v * 2 for v in preset["blur"]["sigma"]])
        assert wide["motion_blur"]["length"] == pytest.approx([v * 0.96 for v in preset["motion_blur"]["length"]])
        camera = next(params for n, _, params in SEVERITIES[severity].capture if n == "shadow")
        assert wide["shadow"]["softness"] == pytest.approx([v * 0.96 for v in camera["softness"]])
        assert wide["gaussian_noise"] == preset["gaussian_noise"] and wide["jpeg"] == preset["jpeg"]
        # the alignment is off by as many of the photo's pixels: by 96/200 of the preset's share
        assert wide["rotation"]["degrees"] == pytest.approx(preset["rotation"]["degrees"] * 0.48)
        assert wide["translation"]["fraction"] == pytest.approx(preset["translation"]["fraction"] * 0.48)
        assert wide["perspective"]["jitter"] == pytest.approx(preset["perspective"]["jitter"] * 0.48)
        lo, hi = preset["scale"]["factor"]
        assert wide["scale"]["factor"] == pytest.approx([1 - (1 - lo) * 0.48, 1 + (hi - 1) * 0.48])
        assert old["rotation"] == preset["rotation"] and old["scale"] == preset["scale"]


def test_bad_colour_parameter_names_the_step(registry: Registry) -> None:
    with pytest.raises(AugmentConfigError, match="steps\\[0\\] 'chroma_subsampling': upsample: expected one of"):
        AugmentPipeline({"steps": [{"name": "chroma_subsampling", "params": {"upsample": "bicubic"}}]}, registry)
    with pytest.raises(AugmentConfigError, match="steps\\[0\\] 'paper_tint': grey: bounds must lie"):
        AugmentPipeline({"steps": [{"name": "paper_tint", "params": {"grey": [-0.1, 0.1]}}]}, registry)
