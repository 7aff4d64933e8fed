"""The capture simulator: close-ups fill the frame and are read; the same seed
gives the same photo; every severity of the one table makes a photo."""

from __future__ import annotations

import numpy as np
import pytest

from deepmorph_core.bundled import BUNDLED_DRAWING
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.render import render_svg
from deepmorph_core.severity import PHOTO_SEVERITIES
from deepmorph_detect.scenes import close_up_photo, close_up_placed


@pytest.fixture(scope="module")
def ghost_render() -> np.ndarray:
    md = MorphableDrawing.load(BUNDLED_DRAWING)
    return render_svg(md.to_svg(md.neutral_values()[0]), 400)


def test_close_ups_of_codes_fill_the_frame_and_are_read(model, locator) -> None:
    rng = np.random.default_rng(1)
    for severity in PHOTO_SEVERITIES:
        payload = rng.integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8)
        photo = close_up_photo(render_svg(model.encode(payload), 400), severity, rng)
        assert photo.dtype == np.uint8 and photo.shape == (240, 240, 3)
        (found,) = locator.locate(photo)
        assert found.result.ok and np.array_equal(found.result.payload, payload), severity
        x0, y0, x1, y1 = found.bbox
        assert x1 - x0 > 0.5 * 240  # the drawing fills most of the frame


def test_close_ups_are_seeded_and_every_photo_severity_makes_one(ghost_render) -> None:
    render = ghost_render
    a = close_up_photo(render, "hard", np.random.default_rng(5), size=128)
    b = close_up_photo(render, "hard", np.random.default_rng(5), size=128)
    assert np.array_equal(a, b)
    assert PHOTO_SEVERITIES == ("easy", "medium", "hard")
    darkest = [close_up_photo(render, s, np.random.default_rng(0), size=128).mean() for s in PHOTO_SEVERITIES]
    assert all(10 < d < 245 for d in darkest)
    with pytest.raises(DeepMorphError, match="'none' has no photo settings"):
        close_up_photo(render, "none", np.random.default_rng(0))


def test_a_close_up_says_where_its_print_lies() -> None:
    """``close_up_placed``'s homography maps the art's pixels to where the photo shows them: a
    black square in the art's middle is dark there and the paper around it is light."""
    art = np.ones((400, 400), np.float32)
    art[150:250, 150:250] = 0.0
    photo, art_to_image = close_up_placed(art, "easy", np.random.default_rng(2), size=240)
    assert np.array_equal(photo, close_up_photo(art, "easy", np.random.default_rng(2), size=240))
    gray = photo.mean(axis=2)

    def seen(x: float, y: float) -> float:
        p = art_to_image @ np.array([x, y, 1.0])
        return float(gray[int(round(p[1] / p[2])), int(round(p[0] / p[2]))])

    assert seen(200, 200) < 0.5 * seen(100, 100)
    assert seen(200, 200) < 0.5 * seen(300, 300)


def test_a_print_finer_than_the_photo_is_averaged_by_the_camera_not_sampled() -> None:
    """Stripes of a 3-pixel period on the sheet fall 1.1 photo pixels apart at a scale of 0.37,
    finer than the photo resolves: a camera integrates them to an even grey (0.035 of spread
    measured), where sampling the sheet at points leaves stripes of full contrast (0.26)."""
    from deepmorph_detect.scenes import _print_and_place

    art = np.ones((400, 400), np.float32)
    art[:, ::3] = 0.0
    scale = 0.37
    art_to_image = np.array([[scale, 0, 120 - 200 * scale], [0, scale, 120 - 200 * scale], [0, 0, 1.0]])
    img = np.zeros((240, 240, 3), np.float32)
    _print_and_place(img, art, art_to_image, 0.1, 400, np.random.default_rng(0))
    patch = img[100:140, 100:140, 1]
    assert patch.std() < 0.08
    assert 0.55 < patch.mean() < 0.7  # the stripes' mean (2/3) in the paper and ink tones


def test_the_camera_is_the_registered_plugins_in_camera_pixels() -> None:
    """One simulator: a photo's capture is built from the augmentation registry, the severity
    table's steps with their pixel parameters in the camera's pixels, scaled only for a frame
    shrunk (the detector's input)."""
    from deepmorph_core.corruption import capture_pipeline
    from deepmorph_core.severity import capture_steps

    pipeline = capture_pipeline("hard")
    names = [step.name for step in pipeline.steps]
    assert names == ["blur", "motion_blur", "lighting", "shadow", "intensity", "gaussian_noise", "jpeg"]
    taken = {name: params for name, _, params in capture_steps("hard")}
    shrunk = {name: params for name, _, params in capture_steps("hard", 0.5)}
    assert shrunk["blur"]["sigma"] == [s / 2 for s in taken["blur"]["sigma"]]
    assert shrunk["shadow"]["softness"] == [s / 2 for s in taken["shadow"]["softness"]]
    assert shrunk["jpeg"] == taken["jpeg"] and shrunk["gaussian_noise"] == taken["gaussian_noise"]
    with pytest.raises(DeepMorphError, match="'none' has no photo settings"):
        capture_steps("none")


def test_a_print_seen_small_loses_detail_as_in_a_camera(ghost_render) -> None:
    """Blur is in the camera's pixels: the same print filling a 64-pixel photo is blurred by as
    many pixels as in a 400-pixel one, so it keeps less of its edges (mean gradient of the
    photo, each resized to 64 px, over 20 photos)."""
    import cv2

    def sharpness(size: int) -> float:
        rng = np.random.default_rng(3)
        total = 0.0
        for _ in range(20):
            photo = close_up_photo(ghost_render, "hard", rng, size=size, desk=0.7)
            gray = cv2.resize(cv2.cvtColor(photo, cv2.COLOR_BGR2GRAY), (64, 64), interpolation=cv2.INTER_AREA)
            total += float(np.abs(np.diff(gray.astype(np.float32), axis=1)).mean())
        return total / 20

    assert sharpness(64) < 0.8 * sharpness(400)


@pytest.mark.parametrize("channel", ["luminance", "blue"])
def test_a_colour_print_has_one_paper_over_its_whole_sheet(channel: str) -> None:
    """Tinted paper, white balance and a colour cast change the print's paper; the sheet around
    the art is the same paper, so the art's square shows no edge in the photo (a white margin
    around this tint steps by 0.1 there)."""
    from deepmorph_core.corruption import AugmentPipeline
    from deepmorph_core.reading_channel import CHANNELS
    from deepmorph_detect.scenes import _print_and_place, colour_print

    steps = [
        {"name": "paper_tint", "params": {"grey": [0.25, 0.25], "warmth": [0.1, 0.1]}},
        {"name": "white_balance", "params": {"temperature": [0.15, 0.15], "tint": 0.0, "cast": [0.03, 0.03]}},
    ]
    colours = AugmentPipeline({"steps": steps}, channel=CHANNELS[channel])
    rgb = np.ones((41, 40, 3), np.float32)  # an odd height: the paper's rows are whole chroma blocks still
    rgb[15:25, 15:25] = (0.9, 0.2, 0.1)  # a red square of ink
    art, paper = colour_print(rgb, colours, np.random.default_rng(0))
    assert np.allclose(art[0, 0], paper, atol=1e-5) and np.allclose(art[-1, -1], paper, atol=1e-5)
    assert np.abs(np.asarray(paper) - 1.0).max() > 0.05  # the paper is not white
    img = np.zeros((120, 120, 3), np.float32)
    art_to_image = np.array([[2.0, 0, 20], [0, 2.0, 20], [0, 0, 1]])
    _print_and_place(img, art, art_to_image, 0.25, 40, np.random.default_rng(1), paper)
    across_the_edge = img[60, 5:38]  # from the margin into the art, short of the ink
    assert np.abs(np.diff(across_the_edge, axis=0)).max() < 1e-3
    # art without a paper of its own (a render as it is) is printed on white, in colour too
    assert close_up_photo(rgb, "easy", np.random.default_rng(2), 64).shape == (64, 64, 3)
