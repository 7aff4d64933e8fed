"""The decoder's spatial transformer: identity at the start, exact warps, learnable, stored in
bundles (and absent from bundles written before it)."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import torch

from deepmorph_core.bundle import BundleMeta
from deepmorph_core.codec import CodecSpec
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.networks import Decoder, DecoderConfig
from deepmorph_core.spatial import SpatialTransformer, normalised_grid, warp_homography
from tests.conftest import make_svg


def strokes(n: int, size: int = 48, seed: int = 0) -> torch.Tensor:
    """``(n, 1, size, size)`` white images with a few random black strokes (drawn by OpenCV)."""
    rng = np.random.default_rng(seed)
    out = np.ones((n, 1, size, size), np.float32)
    for img in out[:, 0]:
        for _ in range(4):
            p, q = rng.uniform(0.2 * size, 0.8 * size, (2, 2)).astype(int)
            cv2.line(img, tuple(map(int, p)), tuple(map(int, q)), 0.0, 2, cv2.LINE_AA)
    return torch.from_numpy(out)


def test_untrained_transformer_is_the_identity() -> None:
    images = strokes(3)
    st = SpatialTransformer((48, 48))
    assert torch.allclose(st(images), images, atol=1e-5)


def test_a_translation_homography_shifts_by_whole_pixels_and_brings_in_paper() -> None:
    images = strokes(2, size=40)
    shift = 3  # output pixel x reads input pixel x + 3
    H = torch.eye(3).repeat(2, 1, 1)
    H[:, 0, 2] = 2 * shift / 40  # normalised coordinates span 2 over the width
    out = warp_homography(images, H, normalised_grid(40, 40))
    assert torch.allclose(out[..., :-shift], images[..., shift:], atol=1e-5)
    assert torch.allclose(out[..., -shift:], torch.ones_like(out[..., -shift:]))  # from outside: paper


def test_warp_agrees_with_opencv_perspective() -> None:
    """A perspective warp in normalised coordinates equals cv2.warpPerspective with the same map
    in pixels (pixel centres at +0.5)."""
    img = strokes(1, size=64, seed=4)
    H = torch.tensor([[1.03, 0.02, 0.01], [-0.01, 0.98, -0.02], [0.03, -0.02, 1.0]])
    out = warp_homography(img, H[None], normalised_grid(64, 64))[0, 0].numpy()
    # pixel (u, v) -> normalised (2u + 1) / 64 - 1, and back
    to_norm = np.array([[2 / 64, 0, 1 / 64 - 1], [0, 2 / 64, 1 / 64 - 1], [0, 0, 1]])
    H_px = np.linalg.inv(to_norm) @ H.numpy().astype(np.float64) @ to_norm  # output px -> input px
    ref = cv2.warpPerspective(
        img[0, 0].numpy(),
        H_px,
        (64, 64),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=1.0,
    )
    assert np.abs(out - ref)[4:-4, 4:-4].max() < 0.02


def test_the_transformer_learns_to_undo_a_shift() -> None:
    """Trained on its own to map shifted images back onto the originals, it learns the shift
    (the decoder trains it the same way, from the decoding loss)."""
    torch.manual_seed(0)
    images = strokes(64, size=48, seed=1)
    H = torch.eye(3).repeat(64, 1, 1)
    H[:, 0, 2] = -2 * 2.5 / 48  # content moved 2.5 px to the right
    shifted = warp_homography(images, H, normalised_grid(48, 48))
    st = SpatialTransformer((48, 48))
    opt = torch.optim.Adam(st.parameters(), lr=3e-3)
    losses = []
    for _ in range(150):
        loss = (st(shifted) - images).pow(2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.3 * losses[0], (losses[0], losses[-1])
    st.eval()
    with torch.no_grad():
        tx = st.homography(shifted)[:, 0, 2].mean().item() * 48 / 2
    assert math.isclose(tx, 2.5, abs_tol=0.5), tx


def test_decoder_with_transformer_round_trips_through_a_bundle(tmp_path: Path) -> None:
    svg = make_svg('<polyline points="4 6 12 4 20 6" stroke="black" stroke-width="2" fill="none" dm:move="2"/>')
    model = DeepMorphModel.create(
        svg.decode(),
        "poly",
        {},
        CodecSpec(payload_bits=2, crc_bits=0, bch_t=0),
        32,
        {},
        {},
        {},
        decoder_config=DecoderConfig(spatial_transformer=True),
    )
    with torch.no_grad():
        for p in model.decoder.parameters():
            p.add_(0.01 * torch.randn_like(p))
    path = tmp_path / "m.dmm"
    model.save(path)
    loaded = DeepMorphModel.load(path)
    assert loaded.meta.decoder.spatial_transformer and loaded.decoder.align is not None
    images = strokes(2, size=32)
    model.decoder.eval()
    loaded.decoder.eval()
    with torch.no_grad():
        assert torch.equal(model.decoder(images), loaded.decoder(images))


def test_bundles_from_before_the_transformer_read_without_one() -> None:
    assert DecoderConfig.model_validate({"stem": 16, "channels": [32, 48], "hidden": 64}).spatial_transformer is False
    assert Decoder(4, (32, 32)).align is None
    assert "spatial_transformer" in BundleMeta.model_fields["decoder"].annotation.model_fields
