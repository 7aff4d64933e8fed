"""Devices: ``--device auto|cpu|cuda`` parses and resolves, a missing CUDA is one clear line,
the CPU's channels-last decoder computes what the default layout does, and where CUDA exists a
tiny training and its validation give the CPU's numbers within the tolerances stated below."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.codec import train_model, tune_decoder
from deepmorph.training.loop import read_log
from deepmorph.training.validation import validate_renders
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.device import resolve_device
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.networks import Decoder, DecoderConfig
from tests.app.test_training import TINY
from tests.conftest import make_svg, table_text
from tests.pretend_cuda import pretend_cuda

app = application()
CUDA = torch.cuda.is_available()
needs_cuda = pytest.mark.skipif(not CUDA, reason="no CUDA device")
no_cuda = pytest.mark.skipif(CUDA, reason="a CUDA device is present")
TRAIN = ["--payload-bits", "4", "--crc", "8", "--ecc-t", "0", "--steps", "2", "--batch", "4", "--image-width", "32",
         "--threads", "1", "--validation", "0"]  # fmt: skip


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.svg"
    path.write_bytes(TINY)
    return path


def test_auto_is_cuda_where_present_else_the_cpu() -> None:
    assert resolve_device("auto") == ("cuda" if CUDA else "cpu")
    assert resolve_device("cpu") == "cpu"
    with pytest.raises(DeepMorphError, match="expected one of auto, cpu, cuda"):
        resolve_device("gpu")


@no_cuda
def test_cuda_without_cuda_is_one_clear_line(tiny: Path, tmp_path: Path) -> None:
    with pytest.raises(DeepMorphError, match="no CUDA device is available"):
        resolve_device("cuda")
    result = CliRunner().invoke(app, ["train", str(tiny), "--out", str(tmp_path / "m.dmm"), *TRAIN, "--device", "cuda"])
    assert result.exit_code == 1
    assert "no CUDA device is available" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "m.dmm").exists()
    detector = CliRunner().invoke(
        app,
        ["train-detector", str(BUNDLED_MODEL), "--out", str(tmp_path / "d.dmm"), "--steps", "1", "--device", "cuda"],
    )
    assert detector.exit_code == 1 and "no CUDA device is available" in detector.output
    assert "Traceback" not in detector.output and not (tmp_path / "d.dmm").exists()


@pytest.mark.parametrize("command", ["train", "validate"])
def test_an_unknown_device_is_a_usage_error(command: str, tiny: Path, tmp_path: Path) -> None:
    args = [str(tiny), "--out", str(tmp_path / "m.dmm"), *TRAIN] if command == "train" else [str(tmp_path / "m.dmm")]
    result = CliRunner().invoke(app, [command, *args, "--device", "tpu"])
    assert result.exit_code == 2 and "tpu" in result.output


def test_train_and_validate_take_auto_and_record_the_device(tiny: Path, tmp_path: Path) -> None:
    out = tmp_path / "m.dmm"
    trained = CliRunner().invoke(app, ["train", str(tiny), "--out", str(out), *TRAIN, "--device", "auto"])
    assert trained.exit_code == 0, trained.output
    info = json.loads(CliRunner().invoke(app, ["info", str(out), "--json"]).stdout)
    where = "cuda" if CUDA else "cpu"
    assert info["train"]["device"] == where and info["record"]["device"] == where
    assert info["trained_on"] == {"device": where, "world_size": 1, "global_batch": 4}
    result = CliRunner().invoke(
        app, ["validate", str(out), "--samples", "4", "--photos", "0", "--device", "auto", "--json"]
    )
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["validation"][0]["samples"] == 4


def test_bundles_from_before_the_record_say_not_recorded(tiny: Path, tmp_path: Path) -> None:
    out = tmp_path / "m.dmm"
    train_model(tiny, out, payload_bits=4, crc_bits=8, ecc_t=0, train={"steps": 1, "batch": 2, "width": 32},
                validation_samples=(0, 0))  # fmt: skip
    model = DeepMorphModel.load(out)
    model.meta.record.world_size = model.meta.record.global_batch = None  # as older bundles load
    model.save(out)
    info = json.loads(CliRunner().invoke(app, ["info", str(out), "--json"]).stdout)
    assert info["trained_on"]["world_size"] == "not recorded" and info["record"]["global_batch"] is None
    text = CliRunner().invoke(app, ["info", str(out)]).output
    assert "world size not recorded" in table_text(text)


def test_the_channels_last_decoder_computes_what_the_default_layout_does() -> None:
    """Training on the CPU runs the decoder channels-last (about a third faster): the same logits
    and gradients to float rounding (1e-5)."""
    torch.manual_seed(0)
    plain = Decoder(12, (40, 40), DecoderConfig(spatial_transformer=True))
    fast = Decoder(12, (40, 40), DecoderConfig(spatial_transformer=True))
    fast.load_state_dict(plain.state_dict())
    fast.to(memory_format=torch.channels_last)
    images = torch.rand(6, 1, 40, 40)
    a = plain(images.clone().requires_grad_(True))
    fast_in = images.clone().contiguous(memory_format=torch.channels_last).requires_grad_(True)
    b = fast(fast_in)
    torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
    a.square().sum().backward()
    b.square().sum().backward()
    for (name, p), q in zip(plain.named_parameters(), fast.parameters()):
        torch.testing.assert_close(p.grad, q.grad.contiguous(), atol=1e-5, rtol=1e-4, msg=name)


TWO_COLOURS = make_svg(
    """<g stroke="#1f5fbf" stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="2.5">
  <polyline points="4 6 12 4 20 6"/>
  <line x1="4" y1="12" x2="20" y2="12" stroke="#d9480f"/>
  <polyline points="4 18 12 20 20 18"/>
  <circle cx="12" cy="12" r="3" fill="#f2c12e" dm:move="1.5"/>
</g>"""
)


@pytest.mark.parametrize(
    ("drawing", "settings"),
    [(TINY, {"small_prints": 0.25}), (TWO_COLOURS, {}), (TINY, {"print_px": 64, "verifier": False})],
    ids=["black-and-white", "colour", "pixels"],
)
def test_the_cuda_path_keeps_its_tensors_on_the_device(drawing: bytes, settings: dict, tmp_path: Path) -> None:
    """Where no GPU is at hand (CI): training with ``device="cuda"`` (real renders, registration,
    small prints, a colour drawing's renders, the decoder's ONNX graph) and its validation on
    the device, with a pretend CUDA device (``tests/pretend_cuda.py``), never hand a CPU
    tensor to an operation on the device's tensors, as the first run on a real GPU found
    ``values_from_unit`` doing."""
    svg = tmp_path / "drawing.svg"
    svg.write_bytes(drawing)
    out = tmp_path / "m.dmm"
    cfg = {"steps": 6, "batch": 8, "width": 32, "severity": "easy", "hard_fraction": 0.25, "threads": 1}
    with pretend_cuda() as device:
        train_model(svg, out, payload_bits=4, crc_bits=8, ecc_t=0, train={**cfg, **settings, "device": "cuda"},
                    validation_samples=(8, 4))  # fmt: skip
    assert not device.mixes, device.mixes
    assert not torch.cuda.is_available() or CUDA  # the pretence ends with the block
    model = DeepMorphModel.load(out)
    assert model.meta.record.device == "cuda" and "decoder" in model.graphs
    assert next(model.decoder.parameters()).device.type == "cpu"
    assert model.registered == ("print_px" in settings)  # --pixels: renders registered onto the drawing


def test_tuning_the_decoder_keeps_its_tensors_on_the_device(tiny: Path, tmp_path: Path) -> None:
    """``tune-decoder`` with ``device="cuda"`` on the pretend device: no mix, its entry in the
    bundle's tunings says cuda (the training record stays the training's), and the tuned decoder
    comes back on the CPU with its ONNX graph."""
    base, tuned = tmp_path / "m.dmm", tmp_path / "tuned.dmm"
    cpu = {"steps": 2, "batch": 8, "width": 32, "threads": 1, "device": "cpu"}  # the CPU even where CUDA is present
    train_model(tiny, base, payload_bits=4, crc_bits=8, ecc_t=0, train=cpu, validation_samples=(0, 0))
    with pretend_cuda() as device:
        tune_decoder(base, tuned, steps=4, device="cuda", validation_samples=(8, 4))
    assert not device.mixes, device.mixes
    model = DeepMorphModel.load(tuned)
    assert model.meta.tuning[-1]["device"] == "cuda" and model.meta.record.device == "cpu"
    assert "decoder" in model.graphs and next(model.decoder.parameters()).device.type == "cpu"


@needs_cuda
@pytest.mark.parametrize("settings", [{}, {"print_px": 64, "verifier": False}], ids=["96 px", "pixels"])
def test_cuda_trains_and_validates_as_the_cpu_does(tiny: Path, tmp_path: Path, settings: dict) -> None:
    """Tolerances: the logged loss of every step within 2e-3 of the CPU's (the same draws: the
    generators stay on the CPU; only float rounding differs); every weight within 2 x lr x steps
    (Adam moves a weight by at most about lr a step, and where a gradient is near zero rounding
    can flip its sign; batch-norm statistics are not Adam's and are left out); the validation's bit accuracy on the same 200 renders within 0.02."""
    steps = 8
    cfg = {"steps": steps, "batch": 8, "width": 32, "severity": "easy", "hard_fraction": 0.25, "threads": 1,
           "log_every": 1, "seed": 2}  # fmt: skip
    runs = {}
    for device in ("cpu", "cuda"):
        out = tmp_path / f"{device}.dmm"
        train_model(tiny, out, payload_bits=4, crc_bits=8, ecc_t=0, train={**cfg, **settings, "device": device},
                    validation_samples=(0, 0))  # fmt: skip
        runs[device] = out
    cpu, cuda = DeepMorphModel.load(runs["cpu"]), DeepMorphModel.load(runs["cuda"])
    assert cuda.meta.record.device == "cuda" and cpu.meta.record.device == "cpu"
    log_cpu, log_cuda = (read_log(p.with_suffix(".log.jsonl")) for p in (runs["cpu"], runs["cuda"]))
    assert [line["step"] for line in log_cuda] == list(range(1, steps + 1))
    for a, b in zip(log_cpu, log_cuda):
        assert abs(a["loss"] - b["loss"]) < 2e-3, (a, b)
    bound = 2 * max(cpu.meta.train["lr"], cpu.meta.train["encoder_lr"]) * steps
    for net in ("encoder", "decoder"):
        sa, sb = getattr(cpu, net).state_dict(), getattr(cuda, net).state_dict()
        for key in sa:
            if sa[key].is_floating_point() and "running" not in key:
                assert (sa[key] - sb[key]).abs().max() <= bound, f"{net}.{key}"
    on_cpu = validate_renders(cpu, samples=200, seed=3, device="cpu")
    on_cuda = validate_renders(cpu, samples=200, seed=3, device="cuda")
    assert abs(on_cpu.bit_accuracy - on_cuda.bit_accuracy) < 0.02
    assert next(cpu.decoder.parameters()).device.type == "cpu"  # back on the CPU afterwards
