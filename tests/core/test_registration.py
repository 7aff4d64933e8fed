"""Registering framed renders onto the unmorphed drawing (:mod:`deepmorph_core.registration`), as
the photo chain's alignment sees a print."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from deepmorph_core import registration
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.registration import ITERATIONS, UnmorphedRegistration, warp


@pytest.fixture(scope="module")
def ghost() -> DeepMorphModel:
    return DeepMorphModel.load(BUNDLED_MODEL)


@pytest.fixture(scope="module")
def template(ghost: DeepMorphModel) -> torch.Tensor:
    """The unmorphed ghost framed as a training render is."""
    return ghost.framed(ghost.real_renders(ghost.drawing.neutral_values()))


def _turned(degrees: float, shear: float, tilt: float) -> torch.Tensor:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return torch.tensor([[c, -s + shear, 0.02], [s, c, -0.015], [tilt, -tilt / 2, 1.0]], dtype=torch.float64)


def test_a_known_homography_is_undone(template: torch.Tensor) -> None:
    """The unmorphed drawing seen through a known turn, shear and tilt registers back onto
    itself: the homography found is the known one's inverse, and the view is the drawing's."""
    known = torch.stack([_turned(2.0, 0.01, 0.01), _turned(-3.0, -0.02, -0.015)])
    seen = warp(template.repeat(2, 1, 1, 1), known)
    registration = UnmorphedRegistration(template)
    found = registration.homographies(seen)
    product = known @ found
    product = product / product[:, 2:3, 2:3]
    assert torch.allclose(product, torch.eye(3, dtype=torch.float64).expand(2, 3, 3), atol=2e-3)
    before = (seen - template).abs().mean()
    after = (registration(seen) - template).abs().mean()
    assert after < 0.4 * before  # the rest is resampling twice
    # each image is registered on its own: one at a time gives the same homographies
    one = torch.cat([registration.homographies(seen[i : i + 1]) for i in range(2)])
    assert torch.allclose(one, found, atol=1e-9)


def test_an_image_stops_once_its_steps_settle(
    ghost: DeepMorphModel, template: torch.Tensor, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Morphed renders (what training registers) take fewer than all the steps, and their views
    are those all the steps give, within a third of one 8-bit gray level."""
    bits = torch.from_numpy(np.random.default_rng(3).integers(0, 2, (8, ghost.codec.spec.code_bits)).astype(np.float32))
    renders = ghost.framed(ghost.real_renders(ghost.morph_values(bits)))
    warped: list[int] = []

    def counted(images: torch.Tensor, homographies: torch.Tensor) -> torch.Tensor:
        warped.append(images.shape[0])
        return warp(images, homographies)

    monkeypatch.setattr(registration, "warp", counted)
    settled = UnmorphedRegistration(template)(renders)
    settled_warps = sum(warped[:-1])  # the last warp is the view itself
    warped.clear()
    monkeypatch.setattr(registration, "SETTLED", 0.0)
    every_step = UnmorphedRegistration(template)(renders)
    assert sum(warped[:-1]) == ITERATIONS * len(renders) > settled_warps
    assert float((settled - every_step).abs().max()) < 1.5 / 255


def test_the_warp_samples_where_kornias_does(template: torch.Tensor) -> None:
    """The hand-written grid is kornia's ``homography_warp`` without its slow batched product: the
    same views of the ghost, colour and gray, through turns, tilts and a non-square frame."""
    from kornia.geometry.transform import homography_warp

    homographies = torch.stack(
        [_turned(2.0, 0.01, 0.01), _turned(-3.0, -0.02, -0.015), torch.eye(3, dtype=torch.float64)]
    )
    for images in (template.repeat(3, 1, 1, 1), torch.rand(3, 3, 40, 70, generator=torch.Generator().manual_seed(0))):
        h, w = images.shape[-2:]
        kornias = homography_warp(images, homographies.float(), (h, w), align_corners=True, padding_mode="border")
        torch.testing.assert_close(warp(images, homographies), kornias, atol=5e-5, rtol=0)
    torch.testing.assert_close(warp(template, torch.eye(3)[None]), template, atol=2e-5, rtol=0)


def test_registration_is_the_identity_on_the_drawing_itself(template: torch.Tensor) -> None:
    found = UnmorphedRegistration(template).homographies(template)
    assert torch.allclose(found[0], torch.eye(3, dtype=torch.float64), atol=1e-6)


def test_gradients_reach_the_renders_not_the_registration(template: torch.Tensor) -> None:
    """Training's encoder learns through the registered view; the homography is the chain's
    and carries no gradient."""
    seen = warp(template, _turned(1.0, 0.0, 0.0)[None]).requires_grad_(True)
    UnmorphedRegistration(template)(seen).sum().backward()
    assert seen.grad is not None and float(seen.grad.abs().sum()) > 0
    assert not UnmorphedRegistration(template).homographies(seen).requires_grad


def test_models_from_before_are_not_registered(ghost: DeepMorphModel) -> None:
    """A bundle without the setting (the bundled ghost, every model before it) frames its renders
    as it was trained to: by their ink alone."""
    assert not ghost.registered
    values = ghost.morph_values(torch.from_numpy(np.ones((1, ghost.codec.spec.code_bits), np.float32)))
    renders = ghost.real_renders(values)
    framed = ghost.framed(renders)
    ghost.meta.train["registered"] = True
    try:
        registered = ghost.framed(renders)
    finally:
        del ghost.meta.train["registered"]
    assert framed.shape == registered.shape
    assert float((framed - registered).abs().mean()) > 1e-3


@pytest.mark.parametrize("shape", [(48, 48), (37, 64), (2, 5)])
def test_motion_images_are_the_homography_parameters_derivatives(shape: tuple[int, int]) -> None:
    """Each motion image is how the picture changes with one homography parameter: the image
    gradient times that parameter's flow, in frame coordinates scaled to [-1, 1]."""
    image = np.random.default_rng(3).random(shape)
    h, w = shape
    gy, gx = np.gradient(image)
    gx, gy = gx * (w - 1) / 2.0, gy * (h - 1) / 2.0
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = 2.0 * x / (w - 1) - 1.0, 2.0 * y / (h - 1) - 1.0
    flows = [(x, 0), (y, 0), (1, 0), (0, x), (0, y), (0, 1), (-x * x, -x * y), (-x * y, -y * y)]
    expected = np.stack([gx * fx + gy * fy for fx, fy in flows])
    np.testing.assert_allclose(registration.motion_images(image), expected, rtol=1e-12, atol=1e-12)
    single = image.astype(np.float32)
    np.testing.assert_array_equal(registration.motion_images(single), registration.motion_images(single.astype(float)))
