"""The detector hook is real: a second detector registered by a plugin is the one the photo
chain uses, when asked for by name or named by the bundle, from Python and from the CLI."""

from __future__ import annotations

import types
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from typer.testing import CliRunner

import deepmorph.plugin as builtin_commands
import deepmorph_augment.plugin as builtin_augmentations
import deepmorph_detect.plugin as builtin_detectors
import deepmorph_primitives.plugin as builtin_primitives
from deepmorph.cli import application
from deepmorph_core import hookimpl
from deepmorph_core.errors import PluginError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.plugins import load_registry, set_default_registry
from deepmorph_core.protocols import Candidate
from deepmorph_detect.locate import Locator
from deepmorph_detect.propose import quad_bbox
from deepmorph_detect.scenes import SceneMaker


class KnownCorners:
    """A detector that proposes the corners the test put in :attr:`corners` (and counts calls)."""

    name: ClassVar[str] = "known-corners"
    corners: ClassVar[np.ndarray | None] = None
    calls: ClassVar[int] = 0

    @classmethod
    def from_model(cls, model: DeepMorphModel) -> KnownCorners:
        return cls()

    def detect(self, image: np.ndarray) -> list[Candidate]:
        type(self).calls += 1
        if self.corners is None:
            return []
        h, w = image.shape[:2]
        return [Candidate(self.corners, 0.99, quad_bbox(self.corners, w, h), source="known-corners")]


@hookimpl
def deepmorph_register_detectors(register):
    register.detector(KnownCorners)


PLUGIN = types.ModuleType("known_corners_plugin")
PLUGIN.deepmorph_register_detectors = deepmorph_register_detectors


@pytest.fixture
def registry():
    registry = load_registry(
        [builtin_primitives, builtin_augmentations, builtin_detectors, builtin_commands, PLUGIN], entry_points=False
    )
    set_default_registry(registry)
    KnownCorners.calls = 0
    return registry


@pytest.fixture
def scene(model: DeepMorphModel):
    scene = SceneMaker(model, severity="easy", seed=8).make(drawings=1)
    # the truth, a little off, as a detector's outline is
    KnownCorners.corners = scene.placements[0].corners + np.random.default_rng(0).normal(0, 2.0, (4, 2))
    return scene


def test_the_chain_uses_the_detector_asked_for_by_name(model: DeepMorphModel, registry, scene) -> None:
    locator = Locator(model, detector="known-corners", registry=registry)
    assert isinstance(locator.detector, KnownCorners)
    (found,) = locator.locate(scene.image, camera=scene.camera)
    assert KnownCorners.calls == 1
    assert found.source == "known-corners" and found.ok
    assert np.array_equal(found.result.payload, scene.placements[0].payload)
    with pytest.raises(
        PluginError, match="no detector 'nope' is installed \\(installed: centrenet, known-corners, universal\\)"
    ):
        Locator(model, detector="nope", registry=registry)


def test_the_chain_uses_the_detector_the_bundle_names(model: DeepMorphModel, registry, scene, tmp_path: Path) -> None:
    copy = tmp_path / "named.dmm"
    model.meta.detector = model.meta.detector.model_copy(update={"name": "known-corners"})
    try:
        model.save(copy)
    finally:
        model.meta.detector = model.meta.detector.model_copy(update={"name": "centrenet"})
    named = DeepMorphModel.load(copy)
    assert isinstance(Locator(named, registry=registry).detector, KnownCorners)
    assert type(Locator(model, registry=registry).detector).__name__ == "CentreNetDetector"


def test_decode_takes_a_detector_plugin_by_name(model: DeepMorphModel, registry, scene, tmp_path: Path) -> None:
    import cv2

    from deepmorph_core.bundled import BUNDLED_MODEL

    photo = tmp_path / "scene.png"
    cv2.imwrite(str(photo), scene.image)
    result = CliRunner().invoke(
        application(), ["decode", str(BUNDLED_MODEL), str(photo), "--detector", "known-corners"]
    )
    assert result.exit_code == 0, result.output
    assert KnownCorners.calls == 1 and " ok, " in result.output
    missing = CliRunner().invoke(application(), ["decode", str(BUNDLED_MODEL), str(photo), "--detector", "nope"])
    assert missing.exit_code == 1 and "no detector 'nope' is installed" in missing.output
