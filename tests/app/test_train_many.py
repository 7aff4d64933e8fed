"""``deepmorph train-many``: a folder of drawings trained, a broken one reported without
stopping the others, done bundles skipped and checkpoints resumed on the next run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.codec import train_model
from deepmorph.training.loop import Interrupted
from deepmorph.training.many import train_many
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from tests.app.test_training import TINY
from tests.conftest import make_svg

app = application()
SECOND = make_svg(
    """<g stroke="black" stroke-width="2.5" fill="none" dm:move="2">
  <polyline points="3 4 12 8 21 4"/>
  <rect x="6" y="11" width="12" height="8"/>
  <line x1="4" y1="21" x2="20" y2="21"/>
</g>"""
)
FAST = ["--payload-bits", "4", "--steps", "3", "--batch", "4", "--image-width", "32", "--severity", "easy",
        "--threads", "1", "--validation", "4,0", "--device", "cpu"]  # fmt: skip


@pytest.fixture
def drawings(tmp_path: Path) -> Path:
    folder = tmp_path / "drawings"
    folder.mkdir()
    (folder / "a-tiny.svg").write_bytes(TINY)
    (folder / "b-second.svg").write_bytes(SECOND)
    (folder / "c-broken.svg").write_text("<svg xmlns='http://www.w3.org/2000/svg'><text>hi</text>")
    return folder


def test_trains_each_drawing_reports_a_broken_one_and_skips_done_ones(drawings: Path, tmp_path: Path) -> None:
    models = tmp_path / "models"
    first = CliRunner().invoke(app, ["train-many", str(drawings), "--out", str(models), *FAST, "--json"])
    assert first.exit_code == 1, first.output  # a drawing failed; the others were trained
    report = json.loads(first.stdout)
    status = {Path(d["drawing"]).name: d for d in report["drawings"]}
    assert [status[n]["status"] for n in ("a-tiny.svg", "b-second.svg", "c-broken.svg")] == [
        "trained",
        "trained",
        "failed",
    ]
    assert "c-broken.svg" in status["c-broken.svg"]["error"] and "\n" not in status["c-broken.svg"]["error"]
    assert status["a-tiny.svg"]["steps"] == 3 and status["a-tiny.svg"]["payload_bits"] == 4
    assert set(status["a-tiny.svg"]["validation"]) == {"renders"}
    assert report["counts"] == {"trained": 2, "resumed": 0, "done": 0, "failed": 1}
    assert DeepMorphModel.load(models / "b-second.dmm").meta.record.finished
    assert not (models / "c-broken.dmm").exists()
    assert "[3/3]" in first.stderr or "[3/3]" in first.output

    (drawings / "c-broken.svg").unlink()
    stamp = (models / "a-tiny.dmm").stat().st_mtime_ns
    second = CliRunner().invoke(app, ["train-many", str(drawings), "--out", str(models), *FAST])
    assert second.exit_code == 0, second.output
    assert "2 done" in second.stdout and (models / "a-tiny.dmm").stat().st_mtime_ns == stamp


def test_a_checkpoint_is_resumed(drawings: Path, tmp_path: Path) -> None:
    (drawings / "c-broken.svg").unlink()
    models = tmp_path / "models"
    models.mkdir()

    def stop_at_2(total: int, done: int):
        def on_log(m):
            if m["step"] == 2:
                raise KeyboardInterrupt

        return on_log

    train = {"steps": 4, "batch": 4, "width": 32, "severity": "easy", "threads": 1, "log_every": 1, "device": "cpu"}
    with pytest.raises(Interrupted):
        train_model(drawings / "a-tiny.svg", models / "a-tiny.dmm", payload_bits=4, train=train, on_start=stop_at_2)
    results = train_many(drawings, models, payload_bits=4, train={"steps": 4, "threads": 1}, device="cpu",
                         validation_samples=(0, 0))  # fmt: skip
    assert [(r.status, r.steps) for r in results] == [("resumed", 4), ("trained", 4)]
    assert DeepMorphModel.load(models / "a-tiny.dmm").meta.record.finished


def test_two_cpu_jobs_share_the_drawings(drawings: Path, tmp_path: Path) -> None:
    (drawings / "c-broken.svg").unlink()
    results = train_many(drawings, tmp_path / "models", payload_bits=4, device="cpu", jobs=2, validation_samples=(0, 0),
                         train={"steps": 2, "batch": 4, "width": 32, "severity": "easy", "threads": 1})  # fmt: skip
    assert [r.status for r in results] == ["trained", "trained"]


def test_a_folder_without_drawings_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(DeepMorphError, match="no .svg drawings"):
        train_many(tmp_path, tmp_path / "models", device="cpu")
    result = CliRunner().invoke(app, ["train-many", str(tmp_path / "nowhere"), "--out", str(tmp_path / "m")])
    assert result.exit_code == 1 and "not a folder of drawings" in result.output
