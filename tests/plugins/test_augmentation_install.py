"""A real third-party corruption, pip-installed into a folder, reaches the one capture simulator:
the corruption a model's training added to its preset also reaches its close-ups and scenes,
through the same plugin registry, with no test-only registration."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.plugins.installing import install_plugin, run_python

PLUGIN_PYPROJECT = """
[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "deepmorph-fog-test"
version = "0.1.0"
dependencies = []

[project.entry-points.deepmorph]
fog_test = "deepmorph_fog_test"
"""

PLUGIN_CODE = '''
"""A toy corruption: a grey veil over the whole image (fog, a dirty lens)."""
from deepmorph_core import hookimpl


class Fog:
    name = "fog"
    stage = "custom"

    def __init__(self, *, veil=0.5, p=1.0):
        self.veil, self.p = float(veil), float(p)

    def __call__(self, images, generator=None):
        return images * (1 - self.veil) + 0.6 * self.veil


@hookimpl
def deepmorph_register_augmentations(register):
    register.augmentation(Fog)
'''

PROBE = """
import json, numpy as np
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.corruption import AugmentConfig, build_pipeline
from deepmorph_core.render import render_svg
from deepmorph_detect.scenes import SceneMaker, close_up_photo, model_added_steps

model = DeepMorphModel.load(BUNDLED_MODEL)
plain_close = close_up_photo(render_svg(model.encode(np.zeros(24, np.uint8)), 240), "medium", np.random.default_rng(0))
plain_scene = SceneMaker(model, severity="medium", seed=3).make(drawings=1).image
config = AugmentConfig.parse(model.meta.augment).model_dump()
config["steps"].append({"name": "fog", "p": 1.0, "params": {"veil": 0.9}})
model.meta.augment = config  # as a model trained with the fog stores it
build_pipeline(model.meta.train["severity"], model.width, config)  # training builds it too
added = model_added_steps(model)
fog_close = close_up_photo(
    render_svg(model.encode(np.zeros(24, np.uint8)), 240), "medium", np.random.default_rng(0), extra=added
)
fog_scene = SceneMaker(model, severity="medium", seed=3).make(drawings=1).image
print(json.dumps({
    "added": [s.name for s in added],
    "spread": [float(plain_close.std()), float(fog_close.std()), float(plain_scene.std()), float(fog_scene.std())],
}))
"""


@pytest.fixture(scope="module")
def installed_fog(tmp_path_factory) -> Path:
    return install_plugin(tmp_path_factory, PLUGIN_PYPROJECT, "deepmorph_fog_test", PLUGIN_CODE)


def test_an_installed_corruption_reaches_close_ups_and_scenes(installed_fog: Path) -> None:
    run = run_python(installed_fog, "-c", PROBE)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    assert out["added"] == ["fog"]
    plain_close, fog_close, plain_scene, fog_scene = out["spread"]
    # a 0.9 veil leaves a tenth of the contrast (noise and JPEG come after it)
    assert fog_close < 0.3 * plain_close
    assert fog_scene < 0.3 * plain_scene
