"""Training learns, checkpoints are exact, bundles round-trip and refuse bad files, and a
small trained model survives encode -> real renderer -> decode."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.codec import train_model, variable_effects
from deepmorph.training.loop import Interrupted, read_log
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.capacity import predict
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.image_io import save_gray
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.morphable import INVISIBLE, MorphableDrawing
from deepmorph_core.networks import Encoder, spread_weights
from deepmorph_core.payload import random_payloads
from deepmorph_core.render import render_svg
from deepmorph_detect.locate import Locator
from tests.conftest import make_svg, table_text

app = application()  # the command line's own commands and every installed plugin's

#: A tiny drawing with generous bounds: fast to render, easy to learn.
TINY = make_svg(
    """<g stroke="black" stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="2.5">
  <polyline points="4 6 12 4 20 6"/>
  <line x1="4" y1="12" x2="20" y2="12"/>
  <polyline points="4 18 12 20 20 18"/>
  <circle cx="12" cy="12" r="3" dm:move="1.5"/>
  <polyline points="2 9 2 15" dm:move="1.5"/>
  <polyline points="22 9 22 15" dm:move="1.5"/>
</g>""",
    style='stroke-linejoin="round"',
)
FAST = {"width": 40, "batch": 16, "severity": "none", "hard_fraction": 0.0, "log_every": 10, "threads": 1}


@pytest.fixture(scope="module")
def tiny_svg(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("d") / "tiny.svg"
    path.write_bytes(TINY)
    return path


@pytest.fixture(scope="module")
def trained(tiny_svg: Path, tmp_path_factory) -> Path:
    """A 4-bit model trained for a few hundred steps (shared by the tests below). It uses
    CRC-16: with CRC-8 about 1 % of failed reads pass the check by chance (docs/codec.md),
    which no "never a wrong payload" assertion could survive."""
    out = tmp_path_factory.mktemp("m") / "tiny.dmm"
    train = {**FAST, "steps": 800, "severity": "none", "hard_fraction": 0.25, "width": 48, "seed": 1}
    train_model(tiny_svg, out, payload_bits=4, crc_bits=16, ecc_t=0, train=train)
    return out


def soft_bit_accuracy(model: DeepMorphModel, n: int = 128, seed: int = 0) -> float:
    gen = torch.Generator().manual_seed(seed)
    bits = torch.randint(0, 2, (n, model.codec.spec.code_bits), generator=gen).float()
    with torch.no_grad():
        images = 1 - model.rasterizer()(model.morph_values(bits))
        probs = model.probabilities(images)
    return ((probs > 0.5) == (bits > 0.5)).float().mean().item()


def test_short_training_learns(tiny_svg: Path, tmp_path: Path) -> None:
    out = tmp_path / "short.dmm"
    summary = train_model(tiny_svg, out, payload_bits=8, crc_bits=8, ecc_t=0, train={**FAST, "steps": 150})
    model = DeepMorphModel.load(out)
    acc = soft_bit_accuracy(model)
    assert acc > 0.8, acc  # chance is 0.5
    assert summary.stage2_start is not None and 0 < summary.stage2_start < 150
    log = [json.loads(line) for line in summary.log.read_text().splitlines()]
    assert log[-1]["step"] == 150 and {1, 2} == {row["stage"] for row in log}
    assert summary.plot is not None and summary.plot.stat().st_size > 1000


def test_interrupt_and_resume_equal_an_uninterrupted_run(tiny_svg: Path, tmp_path: Path) -> None:
    cfg = {**FAST, "steps": 60, "checkpoint_every": 10, "seed": 3}
    straight = tmp_path / "straight.dmm"
    train_model(tiny_svg, straight, payload_bits=4, crc_bits=8, ecc_t=0, train=cfg)

    broken = tmp_path / "broken.dmm"

    def stop_at_30(total: int, done: int):
        def on_log(m):
            if m["step"] == 30:
                raise KeyboardInterrupt

        return on_log

    hint = rf"interrupted at step 30/60; checkpoint written to {re.escape(str(broken))} \(continue with --resume\)$"
    with pytest.raises(Interrupted, match=hint):
        train_model(tiny_svg, broken, payload_bits=4, crc_bits=8, ecc_t=0, train=cfg, on_start=stop_at_30)
    assert [line["step"] for line in read_log(broken.with_suffix(".log.jsonl"))] == [10, 20, 30]
    checkpoint = DeepMorphModel.load(broken)
    assert checkpoint.meta.record.step == 30 and not checkpoint.meta.record.finished
    with pytest.raises(DeepMorphError, match="already exists"):
        train_model(tiny_svg, broken, payload_bits=4, train=cfg)
    train_model(tiny_svg, broken, resume=True)
    a, b = DeepMorphModel.load(straight), DeepMorphModel.load(broken)
    assert b.meta.record.finished and b.meta.record.step == 60
    for (ka, va), (_kb, vb) in zip(a.decoder.state_dict().items(), b.decoder.state_dict().items()):
        torch.testing.assert_close(va, vb, msg=ka)
    torch.testing.assert_close(a.encoder.linear.weight, b.encoder.linear.weight)


def test_bundle_round_trip(trained: Path, tmp_path: Path) -> None:
    m = DeepMorphModel.load(trained)
    copy = tmp_path / "copy.dmm"
    m.save(copy)
    again = DeepMorphModel.load(copy)
    assert again.graphs["decoder"].data == m.graphs["decoder"].data  # exported when training ended
    payload = random_payloads(1, 4, np.random.default_rng(0))[0]
    assert m.encode(payload) == again.encode(payload)
    info = again.info()
    assert info["payload_bits"] == 4 and info["code_bits"] == m.codec.spec.code_bits == 20
    assert info["record"]["finished"] and info["versions"]["torch"]
    assert again.meta.raster["flat_fills"] is True  # its fills culled near their outlines, as trained


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "corrupt or truncated"),
        (b"\x89PNG\r\n\x1a\n" + b"\0" * 64, "corrupt or truncated"),
        (b"hello world, definitely not a model file", "corrupt or truncated"),
    ],
)
def test_corrupt_bundles_are_one_clear_error(tmp_path: Path, content: bytes, message: str) -> None:
    bad = tmp_path / "bad.dmm"
    bad.write_bytes(content)
    with pytest.raises(DeepMorphError, match=message):
        DeepMorphModel.load(bad)


def test_truncated_and_foreign_bundles(trained: Path, tmp_path: Path) -> None:
    from safetensors.torch import save_file

    data = trained.read_bytes()
    cut = tmp_path / "cut.dmm"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(DeepMorphError, match="not a usable DeepMorph model file"):
        DeepMorphModel.load(cut)
    foreign = tmp_path / "foreign.safetensors"
    save_file({"w": torch.zeros(2)}, str(foreign))
    with pytest.raises(DeepMorphError, match="without DeepMorph metadata"):
        DeepMorphModel.load(foreign)
    other = tmp_path / "other.dmm"
    save_file({"w": torch.zeros(2)}, str(other), metadata={"deepmorph": json.dumps({"format": "deepmorph-model/99"})})
    with pytest.raises(DeepMorphError, match="format 'deepmorph-model/99'"):
        DeepMorphModel.load(other)
    with pytest.raises(DeepMorphError, match="cannot read model file"):
        DeepMorphModel.load(tmp_path / "missing.dmm")


def test_encode_real_render_decode_round_trip(trained: Path, tmp_path: Path) -> None:
    m = DeepMorphModel.load(trained)
    rng = np.random.default_rng(7)
    payloads = random_payloads(20, 4, rng)
    ok = 0
    for i, payload in enumerate(payloads):
        render = render_svg(m.encode(payload), 160)  # a real renderer, larger than training
        png = tmp_path / f"p{i}.png"
        save_gray(render, png)
        from deepmorph_core.image_io import read_image

        found = Locator(m).locate(read_image(png))
        assert len(found) <= 1, "one drawing, found twice"
        # a morph of 10 % of the width may align to the unmorphed drawing below the bar: not found
        for det in found:
            if not det.result.ok:
                continue
            assert np.array_equal(det.result.payload, payload), "a wrong payload was reported ok"
            ok += 1
    assert ok >= 15, f"only {ok}/20 payloads recovered"


def test_api_encode_takes_the_clis_payload_text_and_refuses_what_it_would_cast(trained: Path) -> None:
    m = DeepMorphModel.load(trained)
    bits = [1, 0, 1, 1]  # the trained model carries 4 payload bits
    assert m.encode("0xB") == m.encode("1011") == m.encode(np.array(bits)) == m.encode(np.array(bits, bool))
    for payload, message in [
        ("0xA1B2C3", "has 6 hex digits"),
        (np.full(4, 0.6), "only 0 and 1"),  # cast to uint8 this was 0000, silently
        (np.ones(5, np.uint8), r"shape \(4,\)"),
    ]:
        with pytest.raises(DeepMorphError, match=message):
            m.encode(payload)


def test_training_warns_when_the_code_outnumbers_the_visible_variables(tiny_svg: Path, tmp_path: Path) -> None:
    """26 variables cannot carry a 24-bit payload's 44 code bits (``deepmorph capacity``): the user
    is told before the run, not after minutes of training, and offered the size that fits."""
    base = ["train", str(tiny_svg), "--steps", "1", "--image-width", "32", "--batch", "2", "--threads", "1"]
    base += ["--validation", "0"]  # a 1-step model fails its validation, which says so too
    res = runner.invoke(app, [*base, "--payload-bits", "24", "--out", str(tmp_path / "big.dmm")])
    text = " ".join(res.stderr.split())
    assert res.exit_code == 0 and "warning:" in text, text
    assert "26 readable variables are predicted to carry 18" in text and "is 5 bits (--payload-bits auto)" in text
    res = runner.invoke(app, [*base, "--payload-bits", "4", "--out", str(tmp_path / "small.dmm")])
    assert res.exit_code == 0 and "warning" not in res.stderr


def test_cli_spatial_transformer_flag_reaches_the_bundle(tiny_svg: Path, tmp_path: Path) -> None:
    """New trainings put the spatial transformer in front of the decoder; the flag leaves it out,
    and ``info`` says which decoder a bundle has."""
    base = ["train", str(tiny_svg), "--steps", "2", "--image-width", "32", "--batch", "2", "--threads", "1"]
    for flag, expected in (([], True), (["--no-spatial-transformer"], False)):
        out = tmp_path / f"m{expected}.dmm"
        res = runner.invoke(app, [*base, *flag, "--payload-bits", "4", "--out", str(out)])
        assert res.exit_code == 0, res.output
        model = DeepMorphModel.load(out)
        assert model.meta.decoder.spatial_transformer is expected and (model.decoder.align is not None) is expected
        info = json.loads(runner.invoke(app, ["info", str(out), "--json"]).stdout)
        assert info["decoder"]["spatial_transformer"] is expected
        shown = table_text(runner.invoke(app, ["info", str(out)]).stdout)
        assert ("spatial transformer, then CNN" in shown) is expected, shown


def _interrupt_at(step: int):
    """An ``on_start`` whose log callback stops the run (as Ctrl-C does) once ``step`` is logged."""

    def on_start(total: int, done: int):
        def on_log(line):
            if line["step"] == step:
                raise KeyboardInterrupt

        return on_log

    return on_start


def test_early_stop_ends_where_the_full_corruption_batches_read_and_is_the_planned_runs_model(
    tiny_svg: Path, tmp_path: Path
) -> None:
    """The early stop's window counts only steps at the training severity (from step 20 here,
    when the curriculum's ramp ends), survives an interrupt, and a stopped run is the planned
    run's model at that step: the learning-rate schedule runs over the planned steps."""
    cfg = {**FAST, "severity": "easy", "curriculum": 0.5, "steps": 40, "log_every": 5, "checkpoint_every": 5,
           "seed": 5, "early_stop_window": 10, "early_stop_rate": 1e-6}  # fmt: skip
    code = {"payload_bits": 4, "crc_bits": 8, "ecc_t": 0, "validation_samples": (0, 0)}
    early = tmp_path / "early.dmm"
    summary = train_model(tiny_svg, early, **code, train=cfg)
    assert summary.steps == 30 and summary.stopped_early
    model = DeepMorphModel.load(early)
    rec = model.meta.record
    assert rec.finished and rec.stopped_early and rec.step == rec.total_steps == 30
    assert model.meta.train["steps"] == 40
    assert model.meta.train["registered"] is False and not model.registered  # no --pixels: framed by ink alone
    assert [line["step"] for line in map(json.loads, summary.log.read_text().splitlines())][-1] == 30
    shown = table_text(runner.invoke(app, ["info", str(early)]).stdout)
    assert "30/30 steps" in shown and "finished early" in shown, shown

    resumed = tmp_path / "resumed.dmm"  # five full-corruption reads in its window when interrupted
    with pytest.raises(Interrupted, match="interrupted at step 25/40"):
        train_model(tiny_svg, resumed, **code, train=cfg, on_start=_interrupt_at(25))
    assert train_model(tiny_svg, resumed, resume=True, validation_samples=(0, 0)).steps == 30

    planned = tmp_path / "planned.dmm"
    with pytest.raises(Interrupted, match="interrupted at step 30/40"):
        train_model(tiny_svg, planned, **code, train={**cfg, "early_stop": False}, on_start=_interrupt_at(30))
    for other in (DeepMorphModel.load(resumed), DeepMorphModel.load(planned)):
        theirs = other.decoder.state_dict()
        for key, value in model.decoder.state_dict().items():
            torch.testing.assert_close(value, theirs[key], msg=key)
        torch.testing.assert_close(model.encoder.linear.weight, other.encoder.linear.weight)

    never = tmp_path / "never.dmm"  # off, or a rate its batches do not reach: the planned steps
    assert train_model(tiny_svg, never, **code, train={**cfg, "early_stop_rate": 1.0}).steps == 40


def test_an_unknown_or_bad_training_setting_is_named_with_the_known_ones(tiny_svg: Path, tmp_path: Path) -> None:
    with pytest.raises(DeepMorphError, match=r"training settings: unknown setting validation \(known: steps, batch,"):
        train_model(tiny_svg, tmp_path / "m.dmm", payload_bits=4, train={"validation": 5})
    with pytest.raises(
        DeepMorphError, match="training settings: early_stop_rate: Input should be less than or equal to 1"
    ):
        train_model(tiny_svg, tmp_path / "m.dmm", payload_bits=4, train={"early_stop_rate": 2.0})
    assert not (tmp_path / "m.dmm").exists()


#: A code without error correction and a run without the validation (the readout tests' runs).
UNCHECKED = {"crc_bits": 8, "ecc_t": 0, "validation_samples": (0, 0)}


def test_a_stalled_cnn_gets_the_least_squares_readout(tiny_svg: Path, tmp_path: Path) -> None:
    """Where stage 1 ends below READOUT_STALL of bits (forced here: a short plateau window and a
    plateau that always triggers), the decoder's linear readout is fitted to the code's renders
    and reads it at once, where the CNN alone is far behind; ``info`` says so."""
    cfg = {**FAST, "steps": 21, "plateau_window": 10, "plateau_gain": 1.0, "stage1_max_fraction": 1.0}
    accuracy = {}
    for readout in (True, False):
        out = tmp_path / f"r{readout}.dmm"
        summary = train_model(tiny_svg, out, payload_bits=8, train={**cfg, "readout": readout}, **UNCHECKED)
        assert summary.stage2_start == 20
        model = DeepMorphModel.load(out)
        assert model.meta.decoder.readout is readout and (model.decoder.readout is not None) is readout
        accuracy[readout] = soft_bit_accuracy(model)
    assert accuracy[True] > 0.95 and accuracy[True] - accuracy[False] > 0.1, accuracy
    res = runner.invoke(app, ["info", str(tmp_path / "rTrue.dmm")])
    assert "linear readout" in table_text(res.stdout)


def test_a_cnn_that_learns_trains_as_without_the_readout(
    tiny_svg: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A dormant readout changes nothing: where stage 1 does not stall, the run equals one
    without the readout weight for weight, and the bundle holds none (nor does one written
    before the readout existed, the bundled ghost)."""
    monkeypatch.setattr("deepmorph.training.codec.READOUT_STALL", 0.0)
    cfg = {**FAST, "steps": 30, "plateau_window": 10, "seed": 4}
    models = {}
    for readout in (True, False):
        out = tmp_path / f"r{readout}.dmm"
        train_model(tiny_svg, out, payload_bits=4, train={**cfg, "readout": readout}, **UNCHECKED)
        models[readout] = DeepMorphModel.load(out)
        assert models[readout].decoder.readout is None and models[readout].meta.decoder.readout is False
    for (name, a), (_, b) in zip(models[True].decoder.state_dict().items(), models[False].decoder.state_dict().items()):
        torch.testing.assert_close(a, b, rtol=0, atol=0, msg=name)
    torch.testing.assert_close(models[True].encoder.linear.weight, models[False].encoder.linear.weight, rtol=0, atol=0)
    base = ["train", str(tiny_svg), "--steps", "1", "--image-width", "32", "--batch", "2", "--threads", "1"]
    res = runner.invoke(app, [*base, "--no-readout", "--payload-bits", "4", "--out", str(tmp_path / "cli.dmm")])
    assert res.exit_code == 0, res.output
    assert DeepMorphModel.load(tmp_path / "cli.dmm").meta.train["readout"] is False
    assert DeepMorphModel.load(BUNDLED_MODEL).decoder.readout is None


def test_resume_keeps_the_checkpoints_decoder(tiny_svg: Path, tmp_path: Path) -> None:
    """A checkpoint without the transformer (``--no-spatial-transformer``, or one written before
    it existed) resumes without it, whatever the new default is."""
    out = tmp_path / "plain.dmm"
    cfg = {**FAST, "steps": 20, "checkpoint_every": 5, "spatial_transformer": False, "readout": False}

    def stop_at_10(total: int, done: int):
        def on_log(m):
            if m["step"] == 10:
                raise KeyboardInterrupt

        return on_log

    with pytest.raises(Interrupted):
        train_model(tiny_svg, out, payload_bits=4, crc_bits=8, ecc_t=0, train=cfg, on_start=stop_at_10)
    checkpoint = DeepMorphModel.load(out)
    del checkpoint.meta.train["spatial_transformer"]  # as written before the transformer existed
    del checkpoint.meta.train["readout"]  # and before the readout
    checkpoint.save(out, extra=checkpoint.extra_tensors)
    train_model(tiny_svg, out, payload_bits=4, crc_bits=8, ecc_t=0, resume=True)
    done = DeepMorphModel.load(out)
    assert done.meta.record.finished and done.meta.record.step == 20
    assert done.meta.decoder.spatial_transformer is False and done.decoder.align is None
    assert done.meta.train.get("spatial_transformer", False) is False
    assert done.meta.decoder.readout is False and done.decoder.readout is None


def test_variables_a_renderer_does_not_show_do_not_count() -> None:
    """Feather package: 40 variables at 2 %, but 6 move points along the straight lines through
    them (0.00-0.03 of the median change); it read 40 % of 24-bit payloads (README). cpu: 40,
    all visible (the weakest, pins pushed into the outline, at 0.4)."""
    feather = Path(__file__).parent.parent / "data" / "feather"
    package_drawing = MorphableDrawing.load(feather / "package.svg", move=0.48)
    cpu_drawing = MorphableDrawing.load(feather / "cpu.svg", move=0.48)
    package, cpu = package_drawing.visibility(), cpu_drawing.visibility()
    assert len(package) == len(cpu) == 40 and (package <= INVISIBLE).sum() == 6 and (cpu <= INVISIBLE).sum() == 0
    assert np.median(cpu) == pytest.approx(1.0) and cpu.min() > 0.3
    package_report, cpu_report = predict(package_drawing), predict(cpu_drawing)
    assert package_report.visible == 34 and cpu_report.visible == 40
    assert package_report.code_bits < cpu_report.code_bits
    assert "6 of 40 variables change nothing a renderer shows" in " ".join(package_report.limits())


def test_blank_image_has_no_detection(trained: Path) -> None:
    m = DeepMorphModel.load(trained)
    locator = Locator(m)
    assert locator.locate(np.ones((100, 100), np.float32)) == []
    assert locator.locate(np.full((100, 100), 0.3, np.float32)) == []


runner = CliRunner()


def test_cli_info_encode_decode(trained: Path, tmp_path: Path) -> None:
    info = runner.invoke(app, ["info", str(trained), "--json"])
    assert info.exit_code == 0, info.output
    assert json.loads(info.stdout)["payload_bits"] == 4
    assert runner.invoke(app, ["info", str(trained)]).exit_code == 0

    svg, png = tmp_path / "code.svg", tmp_path / "code.png"
    enc = runner.invoke(
        app,
        [
            "encode",
            str(trained),
            "--payload",
            "0xA",
            "--out",
            str(svg),
            "--png",
            str(png),
            "--width-mm",
            "20",
            "--dpi",
            "200",
        ],
    )
    assert enc.exit_code == 0, enc.output
    assert svg.is_file() and png.is_file()
    from PIL import Image

    with Image.open(png) as img:
        assert img.width == round(20 / 25.4 * 200)
        assert round(img.info["dpi"][0]) == 200

    blank = tmp_path / "blank.png"
    save_gray(np.ones((50, 50)), blank)
    dec = runner.invoke(app, ["decode", str(trained), str(png), str(blank), "--json"])
    assert dec.exit_code == 4, dec.output  # the blank image gave no payload (docs/cli.md)
    results = json.loads(dec.stdout)
    assert [r["image"] for r in results] == [str(png), str(blank)]
    (det,) = results[0]["detections"]
    assert set(det) >= {"payload", "ok", "corrected_bits", "confidence", "bit_probabilities"}
    assert set(det["payload"]) == {"hex", "bits"} and len(det["payload"]["bits"]) == 4
    assert len(det["bit_probabilities"]) == DeepMorphModel.load(trained).codec.spec.code_bits
    assert results[1]["detections"] == []
    text = runner.invoke(app, ["decode", str(trained), str(png)])
    assert text.exit_code == 0 and str(png) in text.stdout


@pytest.mark.parametrize(
    "payload, message",
    [("0xA5", "hex"), ("0x", ""), ("010", "4"), ("hello", ""), ("01010", "4")],
)
def test_cli_wrong_payload_is_an_error(trained: Path, tmp_path: Path, payload: str, message: str) -> None:
    result = runner.invoke(app, ["encode", str(trained), "--payload", payload, "--out", str(tmp_path / "x.svg")])
    assert result.exit_code == 1
    assert result.stderr.startswith("error: ") and message in result.stderr
    assert not (tmp_path / "x.svg").exists()


def test_cli_decode_bad_files(trained: Path, tmp_path: Path) -> None:
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image")
    for args, message in (
        (["decode", str(trained), str(junk)], "not an image"),
        (["decode", str(trained), str(tmp_path / "nope.png")], "no such image file"),
        (["decode", str(junk), str(junk)], "not a usable DeepMorph model file"),
        (["info", str(tmp_path / "nope.dmm")], "cannot read model file"),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 1 and message in result.stderr and result.stderr.count("\n") == 1


def test_demo_runs_end_to_end_on_the_bundled_model(tmp_path: Path) -> None:
    from deepmorph_core.bundled import BUNDLED_MODEL

    assert BUNDLED_MODEL.is_file(), "the bundled demo model is missing"
    result = runner.invoke(app, ["demo", "--out", str(tmp_path / "demo")])
    assert result.exit_code == 0, result.output
    for name in ("code.svg", "code.png", "overlay.png", "photo-easy.png", "photo-medium.png", "photo-hard.png"):
        assert (tmp_path / "demo" / name).is_file(), name
    assert result.stdout.count("decoded") + result.stdout.count("no drawing found") == 3
    assert "WRONG" not in result.stdout  # a wrong payload must never pass the integrity check
    res = runner.invoke(app, ["demo", "--out", str(tmp_path / "demo" / "code.svg")])
    assert res.exit_code == 1 and "is not a folder" in res.output and "Traceback" not in res.output


def test_train_refuses_missing_or_broken_drawings(tmp_path: Path) -> None:
    bad = tmp_path / "bad.svg"
    bad.write_bytes(b'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 9 9">\n<text>x</text></svg>')
    for svg, message in (
        (tmp_path / "missing.svg", "cannot read file"),
        (bad, f"{bad}:2: unsupported: element <text>"),
    ):
        result = runner.invoke(app, ["train", str(svg), "--out", str(tmp_path / "m.dmm"), "--steps", "2"])
        assert result.exit_code == 1 and message in result.stderr, result.output
        assert result.stderr.count("\n") == 1
    assert not (tmp_path / "m.dmm").exists()


@pytest.mark.parametrize("n_vars, code_bits", [(58, 38), (40, 40), (26, 44), (5, 17)])
def test_spread_weights_give_every_bit_its_own_full_range_variables(n_vars: int, code_bits: int) -> None:
    gen = torch.Generator().manual_seed(0)
    changes = torch.randn(n_vars, 300, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    changes *= torch.rand(n_vars, 1, generator=torch.Generator().manual_seed(2), dtype=torch.float64) + 0.2
    changes[3] = -changes[1]  # a twin: the same move, mirrored (a closed path's repeated start)
    effects = changes @ changes.T
    weights = spread_weights(effects, code_bits, gen)
    assert weights.shape == (n_vars, code_bits)
    used = weights != 0
    assert used.any(0).all(), "a code bit drives no variable"
    assert used.any(1).all(), "a variable carries no bit"
    # twins carry the same bits, signed so that their effects add up instead of cancelling
    torch.testing.assert_close(weights[3], -weights[1])
    groups = n_vars - 1
    if groups >= code_bits:
        assert (used.sum(1) == 1).all()  # each variable follows exactly one bit, at full strength
        assert torch.allclose(weights.abs()[used], torch.tensor(4.0))
        # dealt most visible first to the least loaded bit: the most and least visible bits
        # differ by at most one group's visibility
        visibility = effects.diagonal().clone()
        visibility[1] = (changes[1] - changes[3]).pow(2).sum()
        visibility[3] = 0
        load = (used.double() * visibility[:, None]).sum(0)
        assert load.max() - load.min() <= visibility.max() + 1e-6
    else:
        assert used.sum(1).max() <= -(-code_bits // groups)
        torch.testing.assert_close(weights.abs().sum(1), torch.full((n_vars,), 4.0))
    # distinct code words give distinct morphs: a decoder can tell them apart
    bits = torch.randint(0, 2, (256, code_bits), generator=gen).float()
    encoder = Encoder(code_bits, n_vars)
    with torch.no_grad():
        encoder.linear.weight.copy_(weights)
        unit = encoder(bits)
    if groups >= code_bits:
        assert ((unit < 0.03) | (unit > 0.97)).float().mean() > 0.9  # bits move variables end to end
    codes = {tuple(row) for row in bits.int().tolist()}
    morphs = {tuple(row) for row in (unit * 1000).round().int().tolist()}
    assert len(morphs) == len(codes)


def test_the_ghosts_twin_variables_share_a_bit() -> None:
    """The ghost's head is a half circle between two vertical strokes. Lowering its left end or
    its right end turns the half circle about the same centre, which leaves the same circle:
    the two moves look alike (the soft rasterizer and resvg agree). Two bits on them would be
    told apart by nothing; the Gram matrix of picture changes finds them, so they share one."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    effects = variable_effects(model)
    energy = effects.diagonal()
    corr = effects / torch.sqrt(energy[:, None] * energy[None, :])
    left, right = 3, 5  # move-y of the head's two ends (points 1 and 2 of the body path)
    roles = [(v.role, v.point) for v in model.drawing.variables]
    assert roles[left] == ("move-y", 1) and roles[right] == ("move-y", 2)
    assert corr[left, right] > 0.99
    others = corr.abs().fill_diagonal_(0)
    others[left, right] = others[right, left] = 0
    assert others.max() < 0.95  # no other pair is that alike
    weights = spread_weights(effects, model.codec.spec.code_bits, torch.Generator().manual_seed(0))
    torch.testing.assert_close(weights[left], weights[right])


def test_training_starts_from_spread_weights_unless_asked_not_to(tiny_svg: Path, tmp_path: Path) -> None:
    for init in ("spread", "random"):
        out = tmp_path / f"{init}.dmm"
        cfg = {**FAST, "steps": 1, "encoder_init": init, "seed": 2}
        train_model(tiny_svg, out, payload_bits=8, crc_bits=8, ecc_t=0, train=cfg)
        density = (DeepMorphModel.load(out).encoder.linear.weight != 0).float().mean().item()
        if init == "spread":
            assert density < 0.2, density  # one (or a few) bits per variable
        else:
            assert density > 0.9, density  # the paper's dense random start


def test_small_print_captures_are_blurred_enlargements_and_still_train(tiny_svg: Path, tmp_path: Path) -> None:
    """``small_prints``: part of each batch is corrupted at 55-95 % of the width and enlarged
    again, as a small print in a photo is. Training with half the batch so still learns."""
    from deepmorph.training.codec import SMALL_PRINT_SCALE, CodecRun, TrainConfig

    out = tmp_path / "small.dmm"
    train_model(tiny_svg, out, payload_bits=8, crc_bits=8, ecc_t=0, train={**FAST, "steps": 150, "small_prints": 0.5})
    model = DeepMorphModel.load(out)
    assert model.meta.train["small_prints"] == 0.5
    assert soft_bit_accuracy(model) > 0.8  # chance is 0.5

    trainer = CodecRun(model, TrainConfig(**{**FAST, "steps": 10, "small_prints": 0.5}), tmp_path / "again.dmm")
    clean = 1.0 - trainer.raster(model.drawing.neutral_values(4)).detach()
    small = trainer.small_prints(clean)
    assert small.shape == clean.shape and 0 <= float(small.min()) and float(small.max()) <= 1
    sharpness = lambda x: (x[..., :, 1:] - x[..., :, :-1]).abs().mean().item()  # noqa: E731
    assert sharpness(small) < 0.9 * sharpness(clean)  # detail lost at the small size
    assert (small - clean).abs().mean() < 0.1  # but the same drawing
    assert 0 < SMALL_PRINT_SCALE[0] < SMALL_PRINT_SCALE[1] <= 1
    bits = torch.randint(0, 2, (16, model.codec.spec.code_bits), generator=torch.Generator().manual_seed(0)).float()
    assert trainer.images(bits, train_encoder=False).shape == (16, 1, *model.image_size)


def test_tune_decoder_keeps_the_encoder_and_records_the_run(trained: Path, tmp_path: Path) -> None:
    """``deepmorph tune-decoder``: only the decoder changes (printed codes and the detector stay
    valid), the training record is kept, the run is appended to ``tuning``, and it still reads."""
    before = DeepMorphModel.load(trained)
    out = tmp_path / "tuned.dmm"
    result = CliRunner().invoke(
        app,
        ["tune-decoder", str(trained), "--out", str(out), "--steps", "30", "--small-prints", "0.5", "--threads", "1"],
    )
    assert result.exit_code == 0, result.output
    after = DeepMorphModel.load(out)
    for name, value in before.encoder.state_dict().items():
        assert torch.equal(value, after.encoder.state_dict()[name]), name
    changed = [n for n, v in before.decoder.state_dict().items() if not torch.equal(v, after.decoder.state_dict()[n])]
    assert changed
    # the decoder's graph was exported again for the tuned weights
    assert after.graphs["decoder"].meta.weights_sha256 != before.graphs["decoder"].meta.weights_sha256
    assert after.meta.record == before.meta.record
    (run,) = after.meta.tuning
    assert run["steps"] == 30 and run["finished"] and run["small_prints"] == 0.5
    assert soft_bit_accuracy(after) > 0.9
    info = CliRunner().invoke(app, ["info", str(out)])
    assert info.exit_code == 0 and "decoder tuned" in info.output

    # refused: an existing --out, and a bundle whose training has not finished
    again = CliRunner().invoke(app, ["tune-decoder", str(trained), "--out", str(out), "--steps", "1"])
    assert again.exit_code != 0 and "already exists" in again.output
    unfinished = tmp_path / "unfinished.dmm"
    before.meta.record.finished = False
    before.save(unfinished)
    refused = CliRunner().invoke(app, ["tune-decoder", str(unfinished), "--out", str(tmp_path / "x.dmm")])
    assert refused.exit_code != 0 and "not finished" in refused.output


def test_an_interrupted_tuning_writes_what_it_has(
    trained: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from deepmorph.training.codec import CodecRun, tune_decoder

    real_step = CodecRun.step

    def step_then_stop(self: CodecRun):
        if self.record.step == 7:
            raise KeyboardInterrupt
        return real_step(self)

    monkeypatch.setattr(CodecRun, "step", step_then_stop)
    out = tmp_path / "part.dmm"
    with pytest.raises(Interrupted, match=rf"step 7/50; the decoder tuned so far is in {re.escape(str(out))}$"):
        tune_decoder(trained, out, steps=50, threads=1)
    assert out.with_suffix(".tune.log.jsonl").exists() and not out.with_suffix(".log.jsonl").exists()
    part = DeepMorphModel.load(out)
    (run,) = part.meta.tuning
    assert run["steps"] == 7 and not run["finished"]
    assert "decoder" not in part.graphs  # the graph of the decoder before tuning is not kept


def test_one_code_word_gives_the_batched_morph_values() -> None:
    """The photo chain's numpy path for one code word (hard or soft bits) matches the batched
    torch path, and refuses a word of the wrong length."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    rng = np.random.default_rng(3)
    n_b = model.codec.spec.code_bits
    for bits in (rng.integers(0, 2, n_b).astype(np.float32), rng.random(n_b).astype(np.float32)):
        batched = model.morph_values(torch.from_numpy(bits)[None])[0].double().numpy()
        np.testing.assert_allclose(model.morph_values_one(bits), batched, atol=2e-6)
    with pytest.raises(ValueError, match="code bits"):
        model.morph_values_one(np.zeros(n_b + 1))
    with pytest.raises(ValueError, match="variables"):
        model.drawing.space.values_from_unit_one(np.zeros(3))


def test_train_and_tune_print_one_json_object(tiny_svg: Path, trained: Path, tmp_path: Path) -> None:
    """``--json``: the result as one JSON object, and nothing else on stdout (docs/cli.md)."""
    out = tmp_path / "j.dmm"
    args = ["train", str(tiny_svg), "--steps", "2", "--image-width", "32", "--batch", "2", "--threads", "1",
            "--payload-bits", "4", "--out", str(out), "--json"]  # fmt: skip
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    keys = {"written", "bundle", "log", "plot", "steps", "stage2_start", "stopped_early", "payload_bits", "shrunk",
            "elapsed_s", "metrics", "validation", "trust", "verifier"}  # fmt: skip
    assert set(data) == keys and [r["name"] for r in data["validation"]] == ["renders", "close-ups"]
    assert data["payload_bits"] == 4 and data["shrunk"] == [] and data["verifier"] is None  # none without --pixels
    assert data["trust"] is None  # black ink: not measured by default
    assert data["bundle"] == str(out) and data["steps"] == 2 and str(out) in data["written"]
    assert {"step", "loss", "bit_acc"} <= set(data["metrics"]) and data["metrics"]["step"] == 2
    tuned = tmp_path / "t.dmm"
    res = CliRunner().invoke(
        app, ["tune-decoder", str(trained), "--out", str(tuned), "--steps", "2", "--threads", "1", "--json"]
    )
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["written"] == [str(tuned)] and data["bundle"] == str(tuned)
    assert [r["name"] for r in data["validation"]] == ["renders", "close-ups"]
    assert data["run"]["steps"] == 2 and data["run"]["finished"] is True and "bit_acc" in data["run"]


def test_pixels_puts_the_capture_in_the_cameras_pixels(tiny_svg: Path, tmp_path: Path) -> None:
    """``--pixels``: the decoder keeps its frame, and the capture's blur and the misalignment it
    is trained for are the camera's, in pixels of a print that wide (the preset's blur and turn
    scaled by 96/200 for a 200-px print). Its renders are registered onto the unmorphed drawing
    as the photo chain aligns photos, so only a fifth of that misalignment is left; ``info``
    gives the width as the smallest print."""
    out = tmp_path / "p200.dmm"
    base = ["train", str(tiny_svg), "--steps", "2", "--batch", "2", "--threads", "1", "--no-verifier"]
    base += ["--payload-bits", "4"]  # no verifier: tests/app/test_verifier_training.py trains one after the codec
    res = runner.invoke(app, [*base, "--pixels", "200", "--out", str(out), "--validation", "0"])
    assert res.exit_code == 0, res.output
    model = DeepMorphModel.load(out)
    assert model.width == 96 and model.print_px == model.smallest_print_px == 200
    assert model.meta.train["verifier"] is False and model.meta.verifier is None
    steps = {s["name"]: s["params"] for s in model.meta.augment["steps"]}
    assert steps["blur"]["sigma"] == pytest.approx([0.0, 0.48])  # medium's 0-1 px at 96 px
    assert steps["rotation"]["degrees"] == pytest.approx(0.48)  # medium's 5 degrees, by 96/200, a fifth left
    assert model.registered and model.meta.train["registered"] is True
    info = json.loads(runner.invoke(app, ["info", str(out), "--json"]).stdout)
    assert info["smallest_print_px"] == 200 and info["train"]["print_px"] == 200
    shown = table_text(runner.invoke(app, ["info", str(out)]).stdout)
    assert "200 px across in a photo (trained for prints that wide, --pixels)" in shown
    # a frame of its own: a 64-px frame of prints 128 px wide blurs by half the preset
    own = tmp_path / "own.dmm"
    res = runner.invoke(app, [*base, "--pixels", "128", "--image-width", "64", "--out", str(own), "--validation", "0"])
    assert res.exit_code == 0, res.output
    model = DeepMorphModel.load(own)
    assert model.width == 64 and model.smallest_print_px == 128
    blur = next(s for s in model.meta.augment["steps"] if s["name"] == "blur")
    assert blur["params"]["sigma"] == pytest.approx([0.0, 0.5])
    plain = DeepMorphModel.load(BUNDLED_MODEL)
    assert plain.print_px is None and plain.smallest_print_px == plain.width == 96 and not plain.registered
    # --payload-bits auto plans the code a model read at the print's own resolution carries
    planned = tmp_path / "auto.dmm"
    auto = [*base[:-2], "--payload-bits", "auto", "--pixels", "200", "--renders-tune", "0", "--out", str(planned)]
    auto += ["--validation", "0"]
    res = runner.invoke(app, auto)
    assert res.exit_code == 0, res.output
    wide = predict(MorphableDrawing.load(tiny_svg), print_px=200)
    assert DeepMorphModel.load(planned).codec.spec == wide.codec
    assert wide.payload_bits > predict(MorphableDrawing.load(tiny_svg)).payload_bits


def test_a_registered_model_learns_its_code_unregistered_on_the_clean_rung(tiny_svg: Path, tmp_path: Path) -> None:
    """``--pixels`` registers training renders onto the unmorphed drawing, but not on the
    curriculum's clean first rung: there the decoder first learns the code's moves, which the
    registration partly takes up (faint colour edges then learnt nothing at all). From the next
    rung on, every render is registered, as the photo chain's view is; without ``--pixels``
    none is."""
    from deepmorph.training.codec import CodecRun, open_model

    def asked(print_px: int | None) -> list[tuple[str, bool]]:
        train = {"threads": 1, "steps": 100, "batch": 4} | ({"print_px": print_px} if print_px else {})
        out = tmp_path / f"{print_px}.dmm"
        model, config, _ = open_model(
            tiny_svg, out, 4, None, None, None, train, False, True, False, lambda text: None, None
        )
        run = CodecRun(model, config, out)
        seen: list[bool] = []
        framed = model.framed
        model.framed = lambda renders, registered=None: seen.append(bool(registered)) or framed(renders, registered)
        rungs = []
        for step in (0, 99):  # the ladder's first rung, then its last
            run.record.step = step
            run.images(torch.zeros(4, model.codec.spec.code_bits), False)
            rungs.append(run._rung())
        return list(zip(rungs, seen))

    assert asked(200) == [("none", False), ("medium", True)]
    assert asked(None) == [("none", False), ("medium", False)]
