"""Training's registration (:mod:`deepmorph_core.registration`) makes the view the photo chain's
first look makes: a morphed print aligned to the unmorphed drawing by the chain's ECC and
rectified, framed by its ink, against the same print registered as training registers renders."""

from __future__ import annotations

import numpy as np
import torch

from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.framing import align_to_frame
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.render import render_svg
from deepmorph_detect.locate import Locator
from deepmorph_detect.read import RECTIFY_WIDTH_FACTOR
from deepmorph_detect.refine import LEVELS, ImagePyramid, refine_at, warp_to_template

PRINT_WIDTH = 240


def test_the_registered_render_is_the_chains_view() -> None:
    model = DeepMorphModel.load(BUNDLED_MODEL)
    template = Locator(model, detector="none").reader.template
    x, y, w, _ = model.drawing.drawing.viewbox
    rng = np.random.default_rng(3)
    chain_to_registered, chain_to_framed = [], []
    for _ in range(6):
        code = rng.integers(0, 2, (1, model.codec.spec.code_bits)).astype(np.float32)
        svg = model.drawing.to_svg(model.morph_values(torch.from_numpy(code))[0])
        render = np.asarray(render_svg(svg, PRINT_WIDTH), np.float32)
        scale = render.shape[1] / w
        H = np.array([[scale, 0.0, -x * scale], [0.0, scale, -y * scale], [0.0, 0.0, 1.0]])
        pyramid = ImagePyramid(render)
        for width in LEVELS:  # the chain's alignment, coarse to fine, to the unmorphed drawing
            aligned = refine_at(pyramid, H, template, width)
            assert aligned is not None
            H = aligned.homography
        view = warp_to_template(pyramid, H, template, model.width * RECTIFY_WIDTH_FACTOR)
        chain = torch.from_numpy(align_to_frame(view, model.image_size, model.canonical_moments())[0])
        batch = torch.from_numpy(render)[None, None]
        framed = model.framed(batch)[0, 0]
        model.meta.train["registered"] = True
        registered = model.framed(batch)[0, 0]
        del model.meta.train["registered"]
        chain_to_registered.append(float((chain - registered).abs().mean()))
        chain_to_framed.append(float((chain - framed).abs().mean()))
    assert np.mean(chain_to_registered) < 0.5 * np.mean(chain_to_framed), (chain_to_registered, chain_to_framed)
