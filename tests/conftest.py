"""Shared fixtures. Tests never depend on whatever plugins happen to be installed: an autouse
fixture makes the process-wide registry the built-in primitives only, and tests that need the
Bézier plugin ask for it explicitly."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

import deepmorph.plugin as builtin_commands
import deepmorph_augment.plugin as builtin_augmentations
import deepmorph_detect.plugin as builtin_detectors
import deepmorph_primitives.plugin as builtin_plugin
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.plugins import Registry, load_registry, set_default_registry
from deepmorph_detect.camera import Camera
from deepmorph_detect.locate import Locator
from deepmorph_detect.refine import Alignment, ImagePyramid, refine
from deepmorph_detect.scenes import Placement, SceneMaker

# Property tests are deterministic (same examples every run) so that CI cannot flake.
settings.register_profile("deepmorph", derandomize=True, deadline=None)
settings.load_profile("deepmorph")

DATA = Path(__file__).parent / "data"
FEATHER = DATA / "feather"


def make_svg(body: str, root: str = 'viewBox="0 0 24 24"', style: str = "") -> bytes:
    """A small SVG document (with the dm namespace declared) around ``body``."""
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:dm="urn:deepmorph:1" {root} {style}>\n{body}\n</svg>'
    ).encode()


def table_text(output: str) -> str:
    """The words of a command's table (``deepmorph info``) in order, without its rules and cell
    borders: a cell's text wrapped over lines reads as one phrase, whatever width the console
    took (rich fixes it from ``COLUMNS`` when the command line is first imported)."""
    return " ".join(word for word in output.split() if word.strip("│┃┌┐└┘├┤┬┴┼─━"))


def shaken_clip(image: np.ndarray, count: int, rng: np.random.Generator, folder: Path, video: Path) -> None:
    """``count`` frames of the same photo (BGR uint8), shaken by up to 3 pixels each way and with
    fresh sensor noise, as of a print held in front of a camera: written as the new folder
    ``folder`` (``f00.png`` ...) and as the video ``video`` (``.mp4``, else Motion JPEG)."""
    import cv2

    h, w = image.shape[:2]
    folder.mkdir()
    codec = cv2.VideoWriter_fourcc(*("mp4v" if video.suffix == ".mp4" else "MJPG"))
    writer = cv2.VideoWriter(str(video), codec, 10, (w, h))
    assert writer.isOpened(), video
    for i in range(count):
        shift = np.float32([[1, 0, rng.uniform(-3, 3)], [0, 1, rng.uniform(-3, 3)]])
        frame = cv2.warpAffine(image, shift, (w, h), borderMode=cv2.BORDER_REPLICATE)
        frame = np.clip(frame + rng.normal(0, 6, frame.shape), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"f{i:02d}.png"), frame)
        writer.write(frame)
    writer.release()


@pytest.fixture
def builtin_registry() -> Registry:
    """What the deepmorph distribution itself provides: built-in primitives, augmentations, detectors, commands."""
    return load_registry(
        [builtin_plugin, builtin_augmentations, builtin_detectors, builtin_commands], entry_points=False
    )


@pytest.fixture
def bezier_registry() -> Registry:
    bez = pytest.importorskip("deepmorph_bezier.plugin", reason="the example Bézier plugin is not installed")
    return load_registry(
        [builtin_plugin, builtin_augmentations, builtin_detectors, builtin_commands, bez], entry_points=False
    )


@pytest.fixture(autouse=True)
def isolated_plugins(builtin_registry: Registry) -> Iterator[None]:
    set_default_registry(builtin_registry)
    try:
        yield
    finally:
        set_default_registry(None)


@pytest.fixture(autouse=True, scope="session")
def small_validations() -> Iterator[None]:
    """Training validates on 1000 renders and 200 photos; tests train tiny models many times,
    so they validate on a few (tests/app/test_validation.py checks the real thing)."""
    import deepmorph.training.validation as validation

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(validation, "RENDER_SAMPLES", 24)
        patch.setattr(validation, "PHOTO_SAMPLES", 2)
        yield


@pytest.fixture
def with_bezier(bezier_registry: Registry) -> Registry:
    """Make the process-wide registry the built-ins plus the Bézier plugin."""
    set_default_registry(bezier_registry)
    return bezier_registry


@pytest.fixture(scope="module")
def model() -> DeepMorphModel:
    """The bundled ghost with its detector (loaded once per test module)."""
    return DeepMorphModel.load(BUNDLED_MODEL)


@pytest.fixture(scope="module")
def locator(model: DeepMorphModel) -> Locator:
    """A locator for the bundled ghost."""
    return Locator(model)


def easy_print_aligned(
    model: DeepMorphModel, locator: Locator
) -> tuple[Placement, np.ndarray, Camera, ImagePyramid, Alignment]:
    """One print in an easy scene (seed 11): its placement, the photo as ``locator`` frames it
    (gray, camera, pyramid), and its alignment refined from the true outline."""
    scene = SceneMaker(model, severity="easy", seed=11).make(drawings=1, distractors=0, aruco=False)
    (placed,) = [p for p in scene.placements if p.kind == "drawing"]
    gray, cam, pyramid = locator.frame(scene.image, None)
    right = refine(pyramid, placed.homography, locator.template)
    assert right is not None
    return placed, gray, cam, pyramid, right
