"""Planning a print in pixels: a print's width in a phone photo, and how far the drawing's
variables move there (``deepmorph capacity --pixels`` / ``--print-mm --distance-cm``)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.capacity import predict
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.print_size import (
    PHONE_FOV_DEG,
    PHONE_FRAME_PX,
    farthest_cm,
    legibility,
    movement,
    pixels_across,
    plan,
    plan_sizes,
)
from tests.conftest import FEATHER, make_svg

app = application()

#: One straight line whose end points may each move 0.5 user units along each axis, in a
#: 24-unit-wide drawing: each variable's control point travels 1 unit, 1/24 of the width.
LINE = make_svg('<line x1="4" y1="4" x2="20" y2="20" stroke="black" stroke-width="2" dm:move="0.5"/>')


def test_a_print_spans_the_pixels_a_pinhole_camera_gives() -> None:
    """The documented camera: a 1080p frame's 1920 px span 65 degrees; a 50 mm print at 30 cm
    spans about 250 px, at 20 cm about 375 (the figures users plan with)."""
    assert (PHONE_FRAME_PX, PHONE_FOV_DEG) == (1920, 65.0)
    assert pixels_across(50, 30) == pytest.approx(251.1, abs=0.1)
    assert pixels_across(50, 20) == pytest.approx(376.7, abs=0.1)
    # linear in the print's width, inverse in the distance, linear in the frame's pixels
    assert pixels_across(100, 30) == pytest.approx(2 * pixels_across(50, 30))
    assert pixels_across(50, 60) == pytest.approx(pixels_across(50, 30) / 2)
    assert pixels_across(50, 30, frame_px=3840) == pytest.approx(2 * pixels_across(50, 30))
    seen = 2 * 300 * math.tan(math.radians(80) / 2)
    assert pixels_across(50, 30, fov_deg=80) == pytest.approx(1920 * 50 / seen)
    for bad in ({"print_mm": 0, "distance_cm": 30}, {"print_mm": 50, "distance_cm": -1}):
        with pytest.raises(DeepMorphError, match="must be positive"):
            pixels_across(**bad)
    with pytest.raises(DeepMorphError, match="field of view"):
        pixels_across(50, 30, fov_deg=190)


def test_each_variable_travels_its_bound_in_pixels() -> None:
    md = MorphableDrawing.load(LINE)
    assert md.n_variables == 4
    np.testing.assert_allclose(movement(md), 1 / 24, rtol=1e-6)
    (row,) = plan(md, np.ones(4, bool), [96.0])
    assert (row.median_move, row.smallest_move, row.sub_pixel) == (4.0, 4.0, 0)
    (row,) = plan(md, np.ones(4, bool), [12.0])
    assert row.sub_pixel == 4  # half a pixel each at 12 px across


def test_moves_grow_with_the_pixels_and_with_the_bounds() -> None:
    svg = (FEATHER / "airplay.svg").read_bytes()
    travel = {move: movement(MorphableDrawing.load(svg, move=move)) for move in (0.25, 0.5, 1.0)}
    np.testing.assert_allclose(travel[0.5], 2 * travel[0.25], rtol=1e-6)
    np.testing.assert_allclose(travel[1.0], 4 * travel[0.25], rtol=1e-6)
    md = MorphableDrawing.load(svg, move=0.5)
    rows = plan(md, np.ones(md.n_variables, bool), plan_sizes(251.0))
    assert [r.pixels for r in rows] == [96.0, 150.0, 200.0, 251.0, 300.0]
    medians = [r.median_move for r in rows]
    assert medians == sorted(medians) and medians[-1] > 3 * medians[0] - 0.1
    assert [r.sub_pixel for r in rows] == sorted((r.sub_pixel for r in rows), reverse=True)


def test_the_farthest_distance_is_where_the_print_spans_what_it_needs() -> None:
    """A 50 mm print spans 96 px at about 78 cm; nearer it spans more and reads, farther it is
    too small, and the verdict says which and how near to hold the camera."""
    far = farthest_cm(50, 96)
    assert far == pytest.approx(78.5, abs=0.1)
    assert pixels_across(50, far) == pytest.approx(96.0)
    assert farthest_cm(50, 96, frame_px=3840) == pytest.approx(2 * far)
    near = legibility(pixels_across(50, 30), 96, print_mm=50)
    assert near.reads and near.farthest_cm == pytest.approx(far)
    assert near.sentence() == "wide enough to read: 251 px across, 96 needed; it reads up to 78 cm away"
    distant = legibility(pixels_across(50, 120), 96, print_mm=50)
    assert not distant.reads
    assert (
        distant.sentence()
        == "too small to read: 63 px across, needs 96; hold the camera within 78 cm, or print it wider"
    )
    assert legibility(96, 96).reads and not legibility(95.9, 96).reads  # exactly the frame reads
    assert legibility(60, 96).to_json() == {"pixels": 60.0, "needs_px": 96.0, "farthest_cm": None, "reads": False}
    assert "1.6 m" in legibility(pixels_across(100, 30), 96, print_mm=100).sentence()
    with pytest.raises(DeepMorphError, match="must be positive"):
        farthest_cm(50, 0)


def test_capacity_plans_a_print_from_its_size_and_distance(tmp_path) -> None:
    svg = FEATHER / "airplay.svg"
    shown = CliRunner().invoke(app, ["capacity", str(svg), "--move", "0.5", "--print-mm", "50", "--distance-cm", "30"])
    assert shown.exit_code == 0, shown.output
    assert "a 50 mm print at 30 cm spans 251 px of a 1920-px, 65° frame" in shown.output
    assert "251 px ←" in shown.output
    assert "wide enough to read: 251 px across, 96 needed; it reads up to 78 cm away" in shown.output
    assert "--pixels 251 --payload-bits auto" in " ".join(shown.output.replace("│", " ").split())
    distant = CliRunner().invoke(
        app, ["capacity", str(svg), "--move", "0.5", "--print-mm", "20", "--distance-cm", "100"]
    )  # the same bounds: the drawing's channel, measured above, is not measured again
    assert "too small to read: 30 px across, needs 96; hold the camera within 31 cm, or print it wider" in " ".join(
        distant.output.split()
    )
    data = json.loads(
        CliRunner().invoke(app, ["capacity", str(svg), "--move", "0.5", "--pixels", "200", "--json"]).output
    )
    plan_json = data["print_size"]
    assert plan_json["pixels"] == 200 and plan_json["camera"] is None
    assert plan_json["legibility"] == {"pixels": 200.0, "needs_px": 96.0, "farthest_cm": None, "reads": True}
    assert [row["pixels"] for row in plan_json["sizes"]] == [96.0, 150.0, 200.0, 300.0]
    # the payload at each width: the default training's below 200 px, a --pixels model's above
    default, wide = plan_json["sizes"][1], plan_json["sizes"][3]
    assert default["train_pixels"] is None and wide["train_pixels"] == 200
    assert wide["payload_bits"] > default["payload_bits"] > 0
    assert wide["payload_text"] == f"{wide['payload_bits']} (--pixels 200)"
    assert data["print_px"] == 200 and data["payload_bits"] == wide["payload_bits"]  # planned for --pixels 200
    assert "visible_mask" not in data
    for args, message in (
        (["--print-mm", "50"], "give both --print-mm and --distance-cm"),
        (["--pixels", "200", "--print-mm", "50", "--distance-cm", "30"], "not both"),
        (["--print-mm", "50", "--distance-cm", "0"], "must be positive"),
    ):
        bad = CliRunner().invoke(app, ["capacity", str(svg), "--move", "0.5", *args])
        assert bad.exit_code in (1, 2), bad.output
        flat = " ".join(bad.output.replace("│", " ").split())  # the usage box wraps lines
        assert message in flat and "Traceback" not in bad.output


def test_a_plan_without_the_drawings_channel_says_its_wide_rows_are_still_measuring() -> None:
    """The studio answers at once and measures the channel in the background: until then the
    rows from 200 px up say so instead of a payload, and the narrower ones have theirs."""
    md = MorphableDrawing.load((FEATHER / "airplay.svg").read_bytes(), move=0.5)
    report = predict(md)
    rows = plan(md, report.visible_mask, plan_sizes(None), report)
    assert [(r.pixels, r.measuring) for r in rows] == [(96.0, False), (150.0, False), (200.0, True), (300.0, True)]
    assert rows[0].payload_bits == rows[1].payload_bits == report.payload_bits
    assert rows[2].payload_bits is None and rows[2].payload_text == "measuring ... (--pixels 200)"
