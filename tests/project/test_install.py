"""The lean install: the photo chain and the capture simulator need neither scikit-image nor
matplotlib, the background photos ship with their licence, and training without matplotlib
says in one line how to get its plot."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.loop import NO_PLOT
from deepmorph_detect.backgrounds import PHOTOS, sample_photos

ROOT = Path(__file__).resolve().parents[2]


def test_scenes_and_decoding_import_no_plotting_or_image_science_library() -> None:
    code = (
        "import sys\n"
        "import numpy as np\n"
        "import deepmorph\n"
        "from deepmorph_detect.scenes import SceneMaker\n"
        "model = deepmorph.load('deepmorph_core/data/ghost.dmm')\n"
        "scene = SceneMaker(model.bundle, severity='easy', seed=3).make(drawings=1)\n"
        "found = model.decode(scene.image, bgr=True)\n"
        "assert found and found[0].ok, found\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'skimage', 'scipy', 'matplotlib'}))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_background_photos_ship_with_their_licence() -> None:
    files = sorted(p.name for p in PHOTOS.glob("*.jpg"))
    licence = (PHOTOS / "LICENSE").read_text()
    named = sorted(re.findall(r"^(\w+\.jpg)\s", licence, re.MULTILINE))
    assert files == named and len(files) == 13
    photos = sample_photos()
    assert len(photos) == 13 and all(p.ndim == 3 and p.shape[2] == 3 and p.dtype.name == "float32" for p in photos)
    assert sum(p.stat().st_size for p in PHOTOS.glob("*.jpg")) < 1_000_000
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert '"data/backgrounds/*.jpg", "data/backgrounds/LICENSE"' in pyproject  # in the wheel


def test_training_without_matplotlib_says_how_to_get_the_plot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises ImportError
    out = tmp_path / "m.dmm"
    args = ["train", str(ROOT / "deepmorph_core/data/ghost.svg"), "--out", str(out), "--payload-bits", "8",
            "--steps", "2", "--batch", "2", "--image-width", "32", "--threads", "1", "--validation", "0"]  # fmt: skip
    res = CliRunner().invoke(application(), args)
    assert res.exit_code == 0, res.output
    text = " ".join(res.stderr.split())  # the console wraps long lines
    assert text.count("warning:") == 1 and f"warning: {NO_PLOT}" in text, text
    assert out.is_file() and not out.with_suffix(".log.png").exists() and ", plot " not in res.stdout
