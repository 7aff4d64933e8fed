"""``deepmorph bench-photos``: a folder of photos scored against labels.csv, with a report."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.measure.photo_report import NO_PLOTS, write_report
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import format_payload
from deepmorph_detect.scenes import SceneMaker

app = application()
runner = CliRunner()

SUMMARY_KEYS = {
    "format", "model", "folder", "labels", "camera", "photos", "skipped", "codes", "photos_without_code", "read",
    "wrong", "not_verified", "missed", "false_reads", "wrong_payloads", "read_rate", "corner_error_px", "time_ms",
    "results", "threads",
}  # fmt: skip


def _corners(c: np.ndarray) -> str:
    return ",".join(f"{v:.2f}" for v in np.asarray(c).ravel())


@pytest.fixture(scope="module")
def photos(model: DeepMorphModel, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four photos: three prints (labelled with corners, without corners, and with a wrong
    payload) and one with no print of the model; ``labels.csv`` says so, a header included."""
    folder = tmp_path_factory.mktemp("photos")
    maker = SceneMaker(model, severity="easy", seed=21)
    rows = ["file,payload,x0,y0,x1,y1,x2,y2,x3,y3"]
    for name in ("a", "b", "c"):
        scene = maker.make(drawings=1, aruco=False)
        cv2.imwrite(str(folder / f"{name}.png"), scene.image)
        (p,) = [p for p in scene.placements if p.kind == "drawing"]
        payload = p.payload if name != "c" else 1 - p.payload
        hexa = format_payload(payload)["hex"]
        rows.append({"a": f"a.png,{hexa},{_corners(p.corners)}", "b": f"b.png,{hexa[2:]}",
                     "c": f"c.png,{hexa},{_corners(p.corners)}"}[name])  # fmt: skip
    cv2.imwrite(str(folder / "d.png"), maker.make(drawings=0, distractors=1, aruco=True).image)
    rows.append("d.png,")
    (folder / "labels.csv").write_text("\n".join(rows) + "\n")
    return folder


def test_counts_json_shape_and_report(photos: Path, tmp_path: Path) -> None:
    report_dir = tmp_path / "report"
    res = runner.invoke(app, ["bench-photos", str(BUNDLED_MODEL), str(photos), "--report", str(report_dir), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)  # one JSON object, nothing else on stdout
    assert set(data) == SUMMARY_KEYS | {"written"}
    assert (data["photos"], data["codes"], data["photos_without_code"]) == (4, 3, 1)
    assert (data["read"], data["wrong"], data["not_verified"], data["missed"]) == (2, 1, 0, 0)
    assert data["false_reads"] == 0 and data["wrong_payloads"] == 1 and data["read_rate"] == round(2 / 3, 4)
    assert data["corner_error_px"]["n"] == 1 and data["corner_error_px"]["max"] < 2  # a.png: read, corners labelled
    assert data["time_ms"]["n"] == 4 and data["time_ms"]["median"] > 0
    codes = {c["file"]: c for r in data["results"] for c in r["codes"]}
    assert codes["a.png"]["status"] == "read" and codes["a.png"]["corners_from"] == "label"
    assert codes["b.png"]["status"] == "read" and codes["b.png"]["corners_from"] == "detection"
    assert codes["c.png"]["status"] == "wrong" and codes["c.png"]["payload"] != codes["c.png"]["expected"]
    for c in codes.values():
        assert 30 < c["width_px"] < 640 and 0 <= c["tilt_deg"] < 90 and c["sharpness"] > 0
    d = next(r for r in data["results"] if r["file"] == "d.png")
    assert d["codes"] == [] and d["false_reads"] == []
    names = {"report.html", "report.json", "width.png", "tilt.png", "sharpness.png"}
    assert {p.name for p in report_dir.iterdir()} == names
    assert sorted(data["written"]) == sorted(str(report_dir / n) for n in names)
    html = (report_dir / "report.html").read_text()
    assert "c.png" in html and "wrong" in html and "<img src='width.png'" in html
    assert cv2.imread(str(report_dir / "tilt.png")) is not None
    assert json.loads((report_dir / "report.json").read_text())["read"] == 2

    # without matplotlib: the tables, and a one-line note instead of the plots
    saved = sys.modules.get("matplotlib")
    sys.modules["matplotlib"] = None  # type: ignore[assignment]
    try:
        written, note = write_report(data, tmp_path / "bare")
    finally:
        if saved is None:
            del sys.modules["matplotlib"]
        else:
            sys.modules["matplotlib"] = saved
    assert note == NO_PLOTS and {p.name for p in written} == {"report.html", "report.json"}
    assert NO_PLOTS in (tmp_path / "bare" / "report.html").read_text()


def test_text_summary(photos: Path) -> None:
    res = runner.invoke(app, ["bench-photos", str(BUNDLED_MODEL), str(photos), "--labels", str(photos / "labels.csv")])
    assert res.exit_code == 0, res.output
    text = " ".join(res.stdout.split())
    assert "read 2 (66.7%)" in text and "wrong payloads 1" in text and "corner error median" in text


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ("a.png,0xZZZZZZ\n", "labels.csv:1: payload '0xZZZZZZ'"),
        ("file,payload\na.png,0xA1B2C3,1,2,3\n", "labels.csv:2: 3 corner coordinates; expected none or 8"),
        ("a.png,0xA1B2C3\na.png,\n", "labels.csv:2: a.png is also on line 1"),
        ("../a.png,0xA1B2C3\n", "labels.csv:1: file '../a.png' must be a name inside"),
        ("missing.png,0xA1B2C3\n", "labels.csv:1: "),
        ("a.png,0xA1B2C3\n", "b.png: not in"),
    ],
)
def test_bad_labels_are_one_clear_error(photos: Path, tmp_path: Path, rows: str, message: str) -> None:
    folder = tmp_path / "p"
    folder.mkdir()
    for name in ("a.png", "b.png"):
        (folder / name).write_bytes((photos / name).read_bytes())
    (folder / "labels.csv").write_text(rows)
    res = runner.invoke(app, ["bench-photos", str(BUNDLED_MODEL), str(folder)])
    assert res.exit_code == 1 and message in " ".join(res.stderr.split()) and "Traceback" not in res.output, res.output
    res = runner.invoke(app, ["bench-photos", str(BUNDLED_MODEL), str(folder), "--report", str(folder)])
    assert res.exit_code == 1 and "the photos' folder" in res.stderr
