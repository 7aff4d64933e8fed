"""The command line, driven for real (typer's CliRunner), with exit codes and output shapes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_DRAWING
from deepmorph_core.drawing import load_drawing
from tests.conftest import FEATHER

app = application()  # the command line's own commands and every installed plugin's

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, [str(a) for a in args])


def test_list_primitives_table_and_json(with_bezier) -> None:
    table = run("list-primitives")
    assert table.exit_code == 0
    flat = table.stdout
    assert "half-circle" in flat and "cubic-bezier" in flat
    rows = json.loads(run("list-primitives", "--json").stdout)
    kinds = {r["kind"]: r for r in rows}
    assert {"line", "polyline", "polygon", "rect", "circle", "ellipse", "path", "half-circle"} <= set(kinds)
    assert kinds["cubic-bezier"]["plugin"] == "deepmorph_bezier.plugin"
    assert kinds["cubic-bezier"]["reads"] == "path CcSs"
    assert all(set(r) == {"kind", "category", "reads", "plugin", "distribution", "morphable"} for r in rows)


def test_inspect_without_bounds_says_how_to_add_some() -> None:
    result = run("inspect", FEATHER / "alert-circle.svg")
    assert result.exit_code == 0
    assert "0 variables" in result.stdout and "dm:move" in result.stdout and "--move 0.5" in result.stdout


def test_inspect_json_with_default_bounds() -> None:
    result = run("inspect", FEATHER / "alert-circle.svg", "--json", "--move", "0.5", "--scale", "0.9,1.1")
    info = json.loads(result.stdout)
    assert info["n_variables"] == 2 + 4 + 4 + 3
    assert [p["kind"] for p in info["primitives"]] == ["circle", "line", "line"]
    assert info["primitives"][0]["bounds"] == {"move": 0.5, "scale": [0.9, 1.1]}


def test_morph_random_is_seeded_and_inside_bounds(tmp_path: Path) -> None:
    a, b, c = tmp_path / "a.svg", tmp_path / "b.svg", tmp_path / "c.svg"
    assert run("morph", BUNDLED_DRAWING, "--random", "--seed", "3", "--out", a).exit_code == 0
    assert run("morph", BUNDLED_DRAWING, "--random", "--seed", "3", "--out", b).exit_code == 0
    assert run("morph", BUNDLED_DRAWING, "--random", "--seed", "4", "--out", c).exit_code == 0
    assert a.read_text() == b.read_text() != c.read_text()
    base, morphed = load_drawing(BUNDLED_DRAWING), load_drawing(a)
    for p, q in zip(base.primitives, morphed.primitives):
        moved = np.linalg.norm(q.primitive.control_points().numpy() - p.primitive.control_points().numpy(), axis=1)
        limit = 0.0 if p.fixed else p.bounds.move
        assert moved.max() <= limit + 1e-3


def test_morph_refuses_to_overwrite_input_and_needs_variables(tmp_path: Path) -> None:
    src = tmp_path / "x.svg"
    src.write_bytes((FEATHER / "activity.svg").read_bytes())
    same = run("morph", src, "--random", "--move", "0.5", "--out", src)
    assert same.exit_code == 1 and "refusing to overwrite" in same.stderr
    none = run("morph", src, "--random", "--out", tmp_path / "y.svg")
    assert none.exit_code == 1 and "0 variables" in none.stderr
    assert not (tmp_path / "y.svg").exists()


@pytest.mark.parametrize("soft", [False, True])
def test_render_hard_soft_and_overlay(tmp_path: Path, soft: bool) -> None:
    flags = ["--soft"] if soft else []
    out = tmp_path / "a.png"
    assert run("render", BUNDLED_DRAWING, "--out", out, "--width-px", "128", *flags).exit_code == 0
    img = np.asarray(Image.open(out))
    assert img.shape == (128, 128) and img.min() < 50 and img.max() == 255
    morphed = tmp_path / "m.svg"
    run("morph", BUNDLED_DRAWING, "--random", "--seed", "1", "--out", morphed)
    cmp = tmp_path / "cmp.png"
    assert run("render", morphed, "--base", BUNDLED_DRAWING, "--out", cmp, "--width-px", "128", *flags).exit_code == 0
    rgb = np.asarray(Image.open(cmp).convert("RGB")).astype(int)
    reddish = (rgb[..., 0] > 150) & (rgb[..., 1] < 100)
    assert reddish.sum() > 20  # the base shows in red where the morph moved away


@pytest.mark.parametrize(
    "content, message",
    [
        ("<svg", "malformed XML"),
        (
            '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 9 9"><text>x</text></svg>',
            "unsupported: element <text>",
        ),
    ],
)
def test_bad_input_gives_one_error_line(tmp_path: Path, content: str, message: str) -> None:
    bad = tmp_path / "bad.svg"
    bad.write_text(content)
    for args in (
        ("inspect", bad),
        ("render", bad, "--out", tmp_path / "o.png"),
        ("morph", bad, "--random", "--out", tmp_path / "o.svg"),
    ):
        result = run(*args)
        assert result.exit_code == 1
        assert result.stderr.startswith(f"error: {bad}:1: ") and message in result.stderr
        assert result.stderr.count("\n") == 1
        assert result.exception is None or isinstance(result.exception, SystemExit)


def test_unsupported_curves_without_plugin(tmp_path: Path) -> None:
    result = run("inspect", FEATHER / "mail.svg")
    assert result.exit_code == 1 and "unsupported: path command c" in result.stderr


def test_usage_errors_exit_2() -> None:
    assert run("render", BUNDLED_DRAWING).exit_code == 2  # --out missing
    assert run("inspect", "--scale", "a,b", BUNDLED_DRAWING).exit_code == 1


def test_no_output_replaces_an_input(tmp_path: Path) -> None:
    """The model, the drawing or a photo named as an output is one clear error before any work,
    and the file is left as it was (an encode over the model once replaced it with an SVG)."""
    import shutil

    import cv2

    from deepmorph_core.bundled import BUNDLED_MODEL

    model = tmp_path / "ghost.dmm"
    shutil.copy(BUNDLED_MODEL, model)
    drawing = tmp_path / "ghost.svg"
    shutil.copy(BUNDLED_DRAWING, drawing)
    photo = tmp_path / "photo.png"
    cv2.imwrite(str(photo), np.full((120, 160), 255, np.uint8))
    (tmp_path / "b").mkdir()
    twin = tmp_path / "b" / "photo.png"
    shutil.copy(photo, twin)
    before = {p: p.read_bytes() for p in (model, drawing, photo)}
    enc = ["encode", model, "--payload", "0xA1B2C3"]
    cases = [
        ([*enc, "--out", model], "--out", "refusing to overwrite the model file"),
        ([*enc, "--out", tmp_path / "code.svg", "--png", model], "--png", "refusing to overwrite the model file"),
        ([*enc, "--out", tmp_path / "c.svg", "--png", tmp_path / "c.svg"], "--png", "file given with --out"),
        ([*enc, "--out", tmp_path / "c.pdf", "--pdf", tmp_path / "c.pdf"], "--pdf", "file given with --out"),
        ([*enc, "--out", tmp_path / "c.svg", "--png", tmp_path / "c.xyz"], "c.xyz", "this file is a PNG; name it .png"),
        ([*enc, "--out", tmp_path / "c.svg", "--pdf", tmp_path / "c.svg.txt"], "--pdf", "this file is a PDF"),
        ([*enc, "--out", tmp_path / "c.xyz"], "c.xyz", "a code is written as .svg, .pdf or .png"),
        (["render", drawing, "--out", drawing], "--out", "refusing to overwrite the input drawing"),
        (["decode", model, photo, "--overlay", tmp_path / "ann.xyz"], "--overlay", "cannot write this image format"),
        (["morph", drawing, "--random", "--out", drawing], "--out", "refusing to overwrite the input drawing"),
        (["decode", model, photo, "--overlay", photo], "--overlay", "refusing to overwrite the input"),
        (["decode", model, photo, "--overlay", model], "--overlay", "refusing to overwrite the model file"),
        (["decode", model, photo, twin, "--overlay", tmp_path / "ann"], "--overlay", "would both be annotated"),
    ]
    for args, option, message in cases:
        res = run(*args)
        text = " ".join(res.output.split())
        assert res.exit_code == 1 and option in text and message in text, text
        assert "Traceback" not in text
        assert {p: p.read_bytes() for p in before} == before
    assert not (tmp_path / "ann").exists() and not (tmp_path / "c.svg").exists()  # nothing was done
    # a writable --png next to the SVG is written whole
    res = run(*enc, "--out", tmp_path / "code.svg", "--png", tmp_path / "code.png")
    assert res.exit_code == 0 and Image.open(tmp_path / "code.png").size[0] == 591


def test_encode_takes_a_decimal_number_after_0d(tmp_path: Path) -> None:
    """``--payload`` reads hex after ``0x``, a decimal number after ``0d`` and bits otherwise;
    a number too large for the model's payload is one error line."""
    from deepmorph_core.bundled import BUNDLED_MODEL

    codes = {}
    for payload in ("0xA1B2C3", "0d10597059", "101000011011001011000011"):
        res = run("encode", BUNDLED_MODEL, "--payload", payload, "--out", tmp_path / f"{payload}.svg", "--json")
        assert res.exit_code == 0, res.output
        assert json.loads(res.stdout)["payload"]["hex"] == "0xA1B2C3"
        codes[payload] = (tmp_path / f"{payload}.svg").read_text()
    assert len(set(codes.values())) == 1
    res = run("encode", BUNDLED_MODEL, "--payload", "0d16777216", "--out", tmp_path / "big.svg")
    assert res.exit_code == 1 and not (tmp_path / "big.svg").exists()
    assert res.stderr == "error: payload '0d16777216' is too large for 24 bits: the largest is 16777215 (0xFFFFFF)\n"
    assert "0d..." in " ".join(run("encode", "--help").output.split())
