"""The built-in capture corruptions and their pipeline: registration, shapes, gradients,
replayability, references (kornia per sample, Pillow's JPEG) and config validation."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import torch
from kornia.filters import gaussian_blur2d
from PIL import Image

import deepmorph_augment.plugin as augment_plugin
from deepmorph_augment.jpeg import jpeg_compress
from deepmorph_augment.kernels import filter_per_sample, filter_separable_per_sample, gaussian_kernels, line_kernels
from deepmorph_core.corruption import AugmentConfig, AugmentConfigError, AugmentPipeline, warp_chosen, warp_white
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.plugins import Registry, load_registry
from deepmorph_core.protocols import Augmentation

# Strong settings, so that every corruption visibly changes a drawing.
STRONG: dict[str, dict] = {
    "perspective": {"jitter": 0.1},
    "scale": {"factor": [0.7, 0.8]},
    "rotation": {"degrees": [10.0, 20.0]},
    "translation": {"fraction": 0.1},
    "blur": {"sigma": [1.0, 2.0]},
    "defocus": {"radius": [1.0, 2.0]},
    "motion_blur": {"length": [2.0, 4.0]},
    "lighting": {"gradient": 0.3, "vignette": 0.2},
    "shadow": {"strength": [0.4, 0.6], "softness": [0.5, 1.0]},
    "intensity": {"contrast": [0.5, 0.7], "brightness": 0.1},
    "gaussian_noise": {"sigma": [0.05, 0.1]},
    "salt_pepper": {"amount": [0.05, 0.1]},
    "jpeg": {"quality": [10.0, 30.0]},
}
NAMES = sorted(STRONG)
COLOUR_NAMES = ["chroma_subsampling", "ink_fade", "paper_tint", "white_balance"]  # tests/augment/test_colour.py


@pytest.fixture(scope="module")
def registry() -> Registry:
    return load_registry([augment_plugin], entry_points=False)


def make(registry: Registry, name: str, p: float = 1.0, **overrides):
    return registry.augmentations[name].obj(p=p, **{**STRONG[name], **overrides})


def drawing(batch: int = 4, size: int = 32, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """White paper with a dark bar, a ring and a grey patch, different in every sample."""
    y, x = torch.meshgrid(torch.arange(size, dtype=dtype), torch.arange(size, dtype=dtype), indexing="ij")
    images = torch.ones(batch, 1, size, size, dtype=dtype)
    for i in range(batch):
        c = size / 2 + i - batch / 2
        ring = ((x - c) ** 2 + (y - size / 2) ** 2).sqrt()
        images[i, 0] -= 0.9 * torch.sigmoid(4 * (1.5 - (ring - size / 4).abs()))
        images[i, 0, 4 : size - 4, 3 + i : 6 + i] = 0.0
        images[i, 0, 2:8, size - 10 : size - 3] = 0.5
    return images


def seeded(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def test_every_builtin_is_registered_through_the_plugin(registry: Registry) -> None:
    assert sorted(registry.augmentations) == sorted(NAMES + COLOUR_NAMES)
    for name, reg in registry.augmentations.items():
        assert reg.plugin == augment_plugin.__name__
        assert reg.obj.name == name
        assert isinstance(reg.obj(), Augmentation)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_shape_dtype_and_effect(registry: Registry, name: str, dtype: torch.dtype) -> None:
    images = drawing(dtype=dtype)
    out = make(registry, name)(images, seeded())
    assert out.shape == images.shape and out.dtype == dtype and out.device == images.device
    assert torch.isfinite(out).all()
    assert (out - images).abs().amax(dim=(1, 2, 3)).min() > 1e-3, "every sample should change at p=1"


@pytest.mark.parametrize("name", NAMES)
def test_pipeline_output_in_unit_range(registry: Registry, name: str) -> None:
    pipe = AugmentPipeline({"steps": [{"name": name, "params": STRONG[name]}]}, registry)
    out = pipe(drawing(), seeded())
    assert out.shape == (4, 1, 32, 32)
    assert out.min() >= 0.0 and out.max() <= 1.0


@pytest.mark.parametrize("name", NAMES)
def test_replayable_with_a_seeded_generator(registry: Registry, name: str) -> None:
    aug, images = make(registry, name, p=0.5), drawing(batch=8)
    first, again = aug(images, seeded(3)), aug(images, seeded(3))
    assert torch.equal(first, again)
    assert not torch.equal(first, aug(images, seeded(4)))
    # Draws are made in float32 whatever the images' dtype: float64 replays the same corruption.
    torch.testing.assert_close(aug(images.double(), seeded(3)).float(), first, atol=2e-3, rtol=0)


@pytest.mark.parametrize("name", NAMES)
def test_p_zero_is_identity(registry: Registry, name: str) -> None:
    images = drawing()
    assert torch.equal(make(registry, name, p=0.0)(images, seeded()), images)


@pytest.mark.parametrize("name", NAMES)
def test_p_selects_samples(registry: Registry, name: str) -> None:
    images = drawing(batch=16)
    out = make(registry, name, p=0.5)(images, seeded(1))
    changed = (out - images).abs().amax(dim=(1, 2, 3)) > 1e-6
    assert 0 < int(changed.sum()) < 16


@pytest.mark.parametrize("name", NAMES)
def test_gradcheck_float64(registry: Registry, name: str) -> None:
    """Every corruption is smooth in the image for fixed random draws (all but JPEG are
    linear in it; JPEG is checked with its cubic rounding)."""
    overrides = {"rounding": "cubic"} if name == "jpeg" else {}
    aug = make(registry, name, p=0.75, **overrides)
    images = torch.rand(3, 1, 8, 8, dtype=torch.float64, generator=seeded(5)).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: aug(x, seeded(2)), (images,))


def test_jpeg_straight_through_gradient_is_identity(registry: Registry) -> None:
    images = drawing(size=24).requires_grad_(True)
    weights = torch.rand(images.shape, generator=seeded(1))
    (make(registry, "jpeg")(images, seeded()) * weights).sum().backward()
    torch.testing.assert_close(images.grad, weights, atol=1e-4, rtol=0)


def test_jpeg_cubic_gradient_is_finite_and_non_zero(registry: Registry) -> None:
    images = drawing(size=24).requires_grad_(True)
    make(registry, "jpeg", rounding="cubic")(images, seeded()).square().sum().backward()
    assert torch.isfinite(images.grad).all() and images.grad.abs().sum() > 0


def test_salt_pepper_gradient_is_finite_and_non_zero(registry: Registry) -> None:
    images = drawing().requires_grad_(True)
    out = make(registry, "salt_pepper")(images, seeded())
    out.sum().backward()
    replaced = images.grad == 0
    assert torch.isfinite(images.grad).all() and (~replaced).any()
    assert 0.02 < replaced.float().mean() < 0.15


def blockiness(images: torch.Tensor) -> float:
    """Mean jump across 8x8 block borders minus the mean jump inside blocks."""
    dx = (images[..., 1:] - images[..., :-1]).abs()
    border = torch.zeros(dx.shape[-1], dtype=torch.bool)
    border[7::8] = True
    return float(dx[..., border].mean() - dx[..., ~border].mean())


def test_jpeg_quality_controls_error_and_blockiness() -> None:
    images = drawing(batch=2, size=32)
    high = jpeg_compress(images, torch.full((2,), 95.0))
    low = jpeg_compress(images, torch.full((2,), 10.0))
    err_high, err_low = (high - images).abs().mean(), (low - images).abs().mean()
    assert err_high < 0.01
    assert err_low > 3 * err_high
    assert blockiness(low) > blockiness(high) + 0.005


@pytest.mark.parametrize("quality", [10, 50, 90])
def test_jpeg_matches_pillow(quality: int) -> None:
    """Against libjpeg through Pillow (grey, baseline): within libjpeg's integer DCT and 8-bit
    rounding."""
    pixels = (drawing(batch=1, size=40)[0, 0] * 255).round().to(torch.uint8).numpy()
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="JPEG", quality=quality)
    reference = torch.from_numpy(np.asarray(Image.open(buffer)).astype(np.float64) / 255.0)
    ours = jpeg_compress(
        torch.from_numpy(pixels / 255.0)[None, None], torch.tensor([float(quality)], dtype=torch.float64)
    )
    diff = (ours[0, 0].clamp(0, 1) - reference).abs() * 255
    assert diff.mean() < 0.5 and diff.max() <= 3.0


@pytest.mark.parametrize("quality", [30, 90])
def test_colour_jpeg_matches_pillow_at_4_2_0(quality: int) -> None:
    """RGB through Y with the luminance table and 4:2:0 Cb/Cr with the chrominance table, against
    libjpeg through Pillow: within libjpeg's integer DCT, colour conversion and 8-bit rounding."""
    rng = np.random.default_rng(3)
    gray = drawing(batch=1, size=40)[0, 0].numpy()
    tint = rng.uniform(0.3, 1.0, (3, 1, 1))
    rgb = (np.clip(gray[None] * tint + (1 - gray[None]) * rng.uniform(0, 0.6, (3, 1, 1)), 0, 1) * 255).round()
    pixels = rgb.astype(np.uint8).transpose(1, 2, 0)
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="JPEG", quality=quality, subsampling=2)
    reference = np.asarray(Image.open(buffer)).astype(np.float64) / 255.0
    ours = jpeg_compress(torch.from_numpy(rgb / 255.0)[None], torch.tensor([float(quality)], dtype=torch.float64))
    ours = ours[0].clamp(0, 1).numpy().transpose(1, 2, 0)
    luma = np.array([0.299, 0.587, 0.114])
    # measured: 0.42 / 0.61 levels of luminance, 1.25 / 1.30 per channel at quality 30 / 90
    assert np.abs(ours @ luma - reference @ luma).mean() * 255 < 0.8
    assert np.abs(ours - reference).mean() * 255 < 1.6
    assert np.abs(ours - rgb.transpose(1, 2, 0) / 255).mean() > 0  # it did compress


def test_jpeg_refuses_two_channels() -> None:
    with pytest.raises(ValueError, match="1 or 3"):
        jpeg_compress(torch.ones(1, 2, 8, 8), torch.tensor([50.0]))


def test_shadow_darkens_inside_its_polygon_only() -> None:
    from deepmorph_augment.shadow import Shadow, polygon_masks

    square = torch.tensor([[[0.25, 0.25], [0.75, 0.25], [0.75, 0.75], [0.25, 0.75], [0.25, 0.75]]])
    mask = polygon_masks(square, 40, 40)
    assert mask[0, 0, 20, 20] == 1 and mask[0, 0, 2, 2] == 0 and mask[0, 0, 20, 35] == 0
    assert mask.sum() == 20 * 20
    shadow = Shadow(strength=[0.5, 0.5], softness=[0.0, 0.0])
    out = shadow(torch.ones(64, 1, 32, 32), seeded(2))
    assert set(torch.unique(out.round(decimals=4)).tolist()) <= {0.5, 1.0}
    share = (out < 0.75).float().mean((1, 2, 3))
    assert (share > 0).float().mean() > 0.8  # most shadows fall on the page
    assert (share < 1).all()


def test_jpeg_pads_sizes_that_are_not_multiples_of_8() -> None:
    images = drawing(batch=2, size=21)
    out = jpeg_compress(images, torch.tensor([90.0, 60.0]))
    assert out.shape == images.shape
    assert (out - images).abs().mean() < 0.03


def test_blur_matches_kornia_per_sample(registry: Registry) -> None:
    images = drawing(batch=3)
    blur = make(registry, "blur")
    chosen, params = blur.draw(images, seeded())
    out = blur(images, seeded())
    assert chosen.all()
    for i, sigma in enumerate(params["sigma"].tolist()):
        ref = gaussian_blur2d(images[i : i + 1], 13, (sigma, sigma), border_type="replicate")
        torch.testing.assert_close(out[i : i + 1], ref, atol=1e-3, rtol=0)


def test_grouped_filter_matches_per_sample_convolution() -> None:
    images = drawing(batch=3, dtype=torch.float64)
    kernels = line_kernels(torch.tensor([0.0, 3.0, 5.0]), torch.tensor([10.0, 45.0, 120.0]), 7).double()
    out = filter_per_sample(images, kernels)
    for i in range(3):
        padded = torch.nn.functional.pad(images[i : i + 1], (3, 3, 3, 3), mode="replicate")
        ref = torch.nn.functional.conv2d(padded, kernels[i][None, None])
        torch.testing.assert_close(out[i : i + 1], ref)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_filters_without_gradient_match_the_differentiable_ones(dtype: torch.dtype) -> None:
    """Scenes and validation filter by OpenCV (no gradient wanted), training by kornia: the same
    kernels and borders give the same pictures, and the training path keeps its gradient."""
    images = torch.rand(3, 2, 37, 61, generator=torch.Generator().manual_seed(0), dtype=dtype)
    lines = line_kernels(torch.tensor([0.0, 6.0, 11.0]), torch.tensor([10.0, 45.0, 120.0]), 13).to(dtype)
    gaussians = gaussian_kernels(torch.tensor([0.0, 1.5, 4.0], dtype=dtype), 15)
    for apply, kernels in ((filter_per_sample, lines), (filter_separable_per_sample, gaussians)):
        fast = apply(images, kernels)
        tracked = images.clone().requires_grad_(True)
        differentiable = apply(tracked, kernels)
        assert differentiable.requires_grad and not fast.requires_grad
        torch.testing.assert_close(fast, differentiable.detach(), atol=1e-6, rtol=0)
        differentiable.sum().backward()
        assert tracked.grad is not None and tracked.grad.abs().sum() > 0


def test_line_kernels() -> None:
    k = line_kernels(torch.tensor([0.0, 4.0, 4.0]), torch.tensor([0.0, 0.0, 90.0]), 7)
    torch.testing.assert_close(k.sum((-2, -1)), torch.ones(3))
    assert k[0, 3, 3] == 1.0
    torch.testing.assert_close(k[2], k[1].T)  # 90 degrees: vertical
    assert k[1, 3].sum() > 0.99  # 0 degrees: all on the middle row


def test_warp_fills_white_and_identity_is_exact() -> None:
    black = torch.zeros(2, 1, 16, 16)
    shift = torch.eye(3).repeat(2, 1, 1)
    shift[:, 0, 2] = 4.0
    out = warp_white(black, shift)
    assert torch.equal(out[..., :4], torch.ones(2, 1, 16, 4))
    assert out[..., 5:].abs().max() < 1e-5
    images = drawing(batch=2)
    torch.testing.assert_close(warp_white(images, torch.eye(3).repeat(2, 1, 1)), images, atol=1e-5, rtol=0)


def test_pipeline_fuses_geometry_into_one_warp(registry: Registry) -> None:
    config = {"steps": [{"name": n, "p": 0.7, "params": STRONG[n]} for n in ("perspective", "rotation", "scale")]}
    images = drawing(batch=8)
    out = AugmentPipeline(config, registry)(images, seeded(7))
    gen = seeded(7)
    steps = [make(registry, n, p=0.7) for n in ("perspective", "rotation", "scale")]
    chosen, matrix = torch.zeros(8, dtype=torch.bool), torch.eye(3).repeat(8, 1, 1)
    for step in steps:
        c, m = step.draw_matrices(images, gen)
        chosen, matrix = chosen | c, m @ matrix
    torch.testing.assert_close(out, warp_chosen(images, chosen, matrix).clamp(0, 1))


def test_pipeline_orders_steps_by_stage(registry: Registry) -> None:
    names = ["jpeg", "salt_pepper", "gaussian_noise", "intensity", "lighting", "motion_blur", "blur", "rotation"]
    pipe = AugmentPipeline({"steps": [{"name": n} for n in names]}, registry)
    # Config order is kept within a stage (motion_blur and blur are both optics).
    expected = ["rotation", "motion_blur", "blur", "lighting", "intensity", "gaussian_noise", "salt_pepper", "jpeg"]
    assert [s.name for s in pipe.steps] == expected


@pytest.mark.parametrize("severity", ["none", "easy", "medium", "hard"])
def test_presets_build_and_run(registry: Registry, severity: str) -> None:
    pipe = AugmentPipeline(AugmentConfig.preset(severity), registry)
    images = drawing(batch=6).requires_grad_(True)
    out = pipe(images, seeded())
    assert out.shape == images.shape and 0.0 <= out.min() and out.max() <= 1.0
    out.sum().backward()
    assert torch.isfinite(images.grad).all() and images.grad.abs().sum() > 0
    if severity == "none":
        assert torch.equal(out, images)
    else:
        assert torch.equal(out, pipe(images, seeded()))


def test_presets_grow_with_severity(registry: Registry) -> None:
    images = drawing(batch=16)
    errors = [
        float((AugmentPipeline(AugmentConfig.preset(s), registry)(images, seeded()) - images).abs().mean())
        for s in ("none", "easy", "medium", "hard")
    ]
    assert errors == sorted(errors) and errors[0] == 0.0


def test_preset_scales_pixel_parameters() -> None:
    steps = {s.name: s for s in AugmentConfig.preset("medium", size=192).steps}
    assert steps["blur"].params["sigma"] == [0.0, 2.0]
    assert steps["rotation"].params["degrees"] == 5.0


def test_config_round_trips_through_json(registry: Registry) -> None:
    for severity in ("none", "easy", "medium", "hard"):
        config = AugmentConfig.preset(severity)
        stored = json.loads(json.dumps(config.model_dump()))
        assert AugmentConfig.model_validate(stored) == config
        images = drawing()
        a = AugmentPipeline(config, registry)(images, seeded())
        b = AugmentPipeline(stored, registry)(images, seeded())
        assert torch.equal(a, b)


@pytest.mark.parametrize(
    ("steps", "expected"),
    [
        ([{"name": "blur"}, {"name": "blurr"}], "steps[1] 'blurr': unknown augmentation"),
        ([{"name": "blur", "params": {"sigmaa": 1.0}}], "steps[0] 'blur': unknown parameter sigmaa (known: sigma, p)"),
        (
            [{"name": "rotation"}, {"name": "blur", "params": {"sigma": [2.0, 1.0]}}],
            "steps[1] 'blur': sigma: lower bound",
        ),
        ([{"name": "jpeg", "params": {"quality": [0.0, 50.0]}}], "steps[0] 'jpeg': quality: bounds must lie"),
        ([{"name": "jpeg", "params": {"rounding": "floor"}}], "steps[0] 'jpeg': rounding: expected one of"),
        ([{"name": "blur", "params": {"p": 0.5}}], "steps[0] 'blur': give p as the step's own field"),
        (
            [{"name": "noise"}, {"name": "blur", "p": 1.5}],
            "steps[1] 'blur': p: Input should be less than or equal to 1",
        ),
        ([{"name": "blur", "sigma": 1.0}], "steps[0] 'blur': sigma: Extra inputs are not permitted"),
    ],
)
def test_bad_config_names_the_step(registry: Registry, steps: list, expected: str) -> None:
    with pytest.raises(DeepMorphError) as info:
        AugmentPipeline({"steps": steps}, registry)
    assert isinstance(info.value, AugmentConfigError)
    assert expected in str(info.value)


def test_unknown_severity() -> None:
    with pytest.raises(DeepMorphError, match="unknown severity 'extreme' \\(known: none, easy, medium, hard\\)"):
        AugmentConfig.preset("extreme")


def test_rejects_non_image_input(registry: Registry) -> None:
    with pytest.raises(ValueError, match=r"blur: expected images of shape \(B, C, H, W\), got \(32, 32\)"):
        make(registry, "blur")(torch.ones(32, 32))
