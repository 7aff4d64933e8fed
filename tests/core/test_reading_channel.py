"""The channel a colour drawing is read in: chosen from its colours, stored in the bundle, and
used alike by training, the renders, the photo simulator and the photo chain."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

import deepmorph
from deepmorph.cli import application
from deepmorph.training.codec import train_model
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.corruption import build_pipeline
from deepmorph_core.luminance import LUMA_WEIGHTS
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.photo import to_gray
from deepmorph_core.reading_channel import SINGLE_CHANNELS, choose_channel
from deepmorph_core.render import render_svg, render_svg_rgb
from deepmorph_detect.locate import Locator
from deepmorph_detect.photo_validation import PRINT_PX, printed
from deepmorph_detect.scenes import SceneMaker, close_up_photo
from tests.conftest import make_svg

DATA = Path(__file__).resolve().parents[1] / "data"  # the colour icons are MIT (LICENSE beside them)
BLUE = SINGLE_CHANNELS["blue"]
YELLOW = make_svg(
    """<g fill="#ffc83d" dm:move="1.2">
  <rect x="3" y="3" width="8" height="8" rx="1"/>
  <circle cx="17" cy="7" r="4"/>
  <path d="M3 14h18l-9 7z"/>
</g>"""
)


@pytest.mark.parametrize(
    "path, name",
    [
        (DATA / "fluent-emoji-flat" / "face-without-mouth.svg", "blue"),  # orange-yellow face, 0.27 in luminance
        (DATA / "fluent-emoji-flat" / "airplane-arrival.svg", "luminance"),
        (DATA / "feather" / "anchor.svg", "luminance"),  # black on white
    ],
)
def test_a_drawing_is_read_in_the_channel_where_its_colours_differ_most(path: Path, name: str) -> None:
    assert choose_channel(path.read_text())[0] == name


def test_photos_renders_and_the_soft_rasterizer_turn_gray_in_the_same_channel(with_bezier) -> None:
    svg = (DATA / "fluent-emoji-flat" / "face-without-mouth.svg").read_text()
    rgb = render_svg_rgb(svg, 64)
    np.testing.assert_allclose(render_svg(svg, 64, BLUE), rgb[..., 2], atol=1e-6)
    np.testing.assert_array_equal(render_svg(svg, 64), render_svg(svg, 64, LUMA_WEIGHTS))
    # a BGR photo (OpenCV's order) in uint8 and in float
    bgr = np.round(rgb[..., ::-1] * 255).astype(np.uint8)
    np.testing.assert_allclose(to_gray(bgr, BLUE), bgr[..., 0] / 255, atol=1e-6)
    np.testing.assert_allclose(to_gray(bgr.astype(np.float32) / 255, BLUE), bgr[..., 0] / 255, atol=1e-6)
    # the face is ink in blue, and barely so in luminance
    assert render_svg(svg, 64, BLUE)[32, 8] < 0.25 < 0.6 < render_svg(svg, 64)[32, 8]
    md = MorphableDrawing.load(svg.encode(), move=0.5).read_in()
    assert md.channel == BLUE
    with torch.no_grad():
        soft = 1.0 - md.rasterizer(96)(md.neutral_values())[0, 0].numpy()
    assert np.abs(soft - render_svg(md.to_svg(md.neutral_values()[0]), 96, BLUE)).mean() <= 0.03


@pytest.fixture(scope="module")
def yellow_bundle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A yellow drawing's model, trained briefly."""
    folder = tmp_path_factory.mktemp("yellow")
    svg = folder / "yellow.svg"
    svg.write_bytes(YELLOW)
    out = folder / "yellow.dmm"
    train = {"width": 48, "batch": 16, "severity": "none", "hard_fraction": 0.25, "steps": 500, "seed": 1, "threads": 1}
    said: list[str] = []  # the capacity warning: a 12-bit code on 12 readable variables
    # CRC-8, not 16: 20 code bits on 12 readable variables read 8 of 16 payloads after 500 steps, 12 read all 16
    train_model(
        svg, out, payload_bits=4, crc_bits=8, ecc_t=0, train=train, validation_samples=(0, 0), on_warning=said.append
    )
    return out


def test_a_yellow_drawing_trains_reads_and_is_stored_in_blue(yellow_bundle: Path) -> None:
    """A yellow drawing's model reads blue; a print of it in its colours reads through the photo
    chain, and the bundle, `info` and old bundles say which channel."""
    model = DeepMorphModel.load(yellow_bundle)
    assert model.meta.reading_channel == BLUE and model.drawing.channel == BLUE
    assert model.info()["reading_channel"] == "blue"
    assert Locator(model).frame(np.full((64, 64, 3), (200, 10, 10), np.uint8), None)[0][0, 0] == pytest.approx(
        200 / 255
    )
    api = deepmorph.load(yellow_bundle)
    code = api.encode(0x9)
    png = Image.open(io.BytesIO(code.png(width_mm=30, dpi=150)))
    assert png.mode == "RGB"
    assert [(f.payload.int, f.ok) for f in api.decode(np.asarray(png))] == [(0x9, True)]
    shown = CliRunner().invoke(application(), ["info", str(yellow_bundle)])
    assert shown.exit_code == 0 and "blue" in shown.output
    assert DeepMorphModel.load(BUNDLED_MODEL).meta.reading_channel == LUMA_WEIGHTS  # written before channels


def test_a_model_read_in_another_channel_is_photographed_in_colour(yellow_bundle: Path) -> None:
    """Its close-ups and scenes are colour photos (the detector reads their luminance, the rest
    the model's channel, as in a real photo); a luminance model's colour prints stay gray."""
    model = DeepMorphModel.load(yellow_bundle)
    rng = np.random.default_rng(2)
    colours = build_pipeline("medium", PRINT_PX, colour=True, channel=model.drawing.channel)
    art, paper = printed(model, model.encode(np.array([1, 0, 0, 1], np.uint8)), colours, rng, 200)
    assert art.shape == (200, 200, 3) and paper.shape == (3,)
    photo = close_up_photo(art, "medium", rng, 160, paper=paper).astype(np.float32)
    assert np.abs(photo[..., 0] - photo[..., 2]).max() > 60  # blue and red differ where the print is yellow
    scene = SceneMaker(model, (320, 240), "easy", seed=3).make(drawings=1, distractors=0)
    assert np.abs(scene.image[..., 0].astype(np.float32) - scene.image[..., 2]).max() > 60
    luma_colours = build_pipeline("medium", PRINT_PX, colour=True)
    assert printed(model, model.encode(np.array([1, 0, 0, 1], np.uint8)), luma_colours, rng, 200)[0].ndim == 2


def test_a_bundle_with_impossible_channel_weights_is_one_clear_error(tmp_path: Path) -> None:
    from deepmorph_core.bundle import load_bundle, save_tagged
    from deepmorph_core.errors import DeepMorphError

    meta, tensors = load_bundle(BUNDLED_MODEL)
    bad = meta.model_copy(update={"reading_channel": (1.5, -0.5, 0.0)})
    save_tagged(tmp_path / "bad.dmm", bad, tensors)
    with pytest.raises(DeepMorphError, match="reading_channel"):
        DeepMorphModel.load(tmp_path / "bad.dmm")


def test_read_in_luminance_keeps_a_colour_drawing_for_gray_prints(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`--read-in luminance` (for prints made in gray) overrides the choice, in training and in
    `capacity`."""
    monkeypatch.setattr("deepmorph_detect.findable.SHOTS", 2)  # how often it is found is not asked here
    svg = tmp_path / "yellow.svg"
    svg.write_bytes(YELLOW)
    out = tmp_path / "gray.dmm"
    train = {"width": 48, "batch": 4, "steps": 3, "threads": 1, "read_in": "luminance"}
    train_model(svg, out, payload_bits=4, crc_bits=16, ecc_t=0, train=train, validation_samples=(0, 0),
                on_warning=lambda _: None)  # fmt: skip
    model = DeepMorphModel.load(out)
    assert model.meta.reading_channel == LUMA_WEIGHTS and model.meta.train["read_in"] == "luminance"
    runner = CliRunner()
    said = runner.invoke(application(), ["capacity", str(svg), "--json"])
    forced = runner.invoke(application(), ["capacity", str(svg), "--json", "--read-in", "luminance"])
    assert '"reading_channel": "blue"' in said.output and '"reading_channel": "luminance"' in forced.output
