"""The photo chain on a device (``Locator(..., device=)``, ``deepmorph decode --device``,
``deepmorph.load(..., device=)``): the modules a CUDA device runs compute what the CPU's ONNX
graphs compute, a missing CUDA is one clear line, and where CUDA exists the chain reads the same
payloads at the same corners as on the CPU."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import deepmorph
from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.networks import fused_for_inference
from deepmorph_detect.centrenet import stored_net
from deepmorph_detect.fastrender import render_svg
from deepmorph_detect.locate import Locator
from deepmorph_detect.network import INPUT_SIZE, DetectorGraph
from deepmorph_detect.runtime import DeviceNetwork
from deepmorph_detect.scenes import close_up_photo
from deepmorph_detect.universal import UNIVERSAL_PATH, load_universal, shared_runner
from tests.pretend_cuda import pretend_cuda

app = application()
CUDA = torch.cuda.is_available()
needs_cuda = pytest.mark.skipif(not CUDA, reason="no CUDA device")
no_cuda = pytest.mark.skipif(CUDA, reason="a CUDA device is present")


@pytest.fixture(scope="module")
def model() -> DeepMorphModel:
    return DeepMorphModel.load(BUNDLED_MODEL)


def _photos(model: DeepMorphModel, n: int) -> list[tuple[np.ndarray, str]]:
    out = []
    for seed in range(n):
        payload = np.random.default_rng(seed).integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8)
        photo = close_up_photo(render_svg(model.encode(payload), 400), "medium", np.random.default_rng(seed))
        out.append((photo, "".join(map(str, payload))))
    return out


def test_the_modules_a_device_runs_compute_what_the_graphs_compute(model: DeepMorphModel) -> None:
    """What ``device="cuda"`` runs (the detector with its standardisation inside, the decoder with
    batch norms folded), here on the CPU, against the CPU's ONNX Runtime graphs."""
    cpu = Locator(model, device="cpu")
    generator = torch.Generator().manual_seed(3)
    W, H = INPUT_SIZE
    photos = [torch.rand(1, 1, H, W, generator=generator) for _ in range(2)]
    frames = [torch.rand(1, 1, *model.image_size, generator=generator) for _ in range(2)]
    universal, _, _, _ = load_universal(UNIVERSAL_PATH)
    for net, graph_run, inputs in (
        (DetectorGraph(fused_for_inference(stored_net(model))), cpu.detector.net, photos),
        (DetectorGraph(fused_for_inference(universal)), Locator(model, "universal").detector.net, photos),
        (fused_for_inference(model.decoder), cpu.reader.decoder, frames),
    ):
        device_run = DeviceNetwork(net, "cpu")
        for x in inputs:
            ours, theirs = device_run(x), graph_run(x)
            ours = ours if isinstance(ours, tuple) else (ours,)
            theirs = theirs if isinstance(theirs, tuple) else (theirs,)
            for a, b in zip(ours, theirs):
                assert a.device.type == "cpu"
                assert torch.as_tensor(a).sub(torch.as_tensor(b)).abs().max() < 1e-4


@no_cuda
def test_decode_on_cuda_without_cuda_is_one_clear_line(model: DeepMorphModel, tmp_path: Path) -> None:
    import cv2

    photo, _ = _photos(model, 1)[0]
    path = tmp_path / "photo.png"
    cv2.imwrite(str(path), photo)
    result = CliRunner().invoke(app, ["decode", str(BUNDLED_MODEL), str(path), "--device", "cuda"])
    assert result.exit_code == 1
    assert "no CUDA device is available" in result.output and "Traceback" not in result.output
    with pytest.raises(DeepMorphError, match="no CUDA device is available"):
        deepmorph.load(BUNDLED_MODEL, device="cuda")
    with pytest.raises(DeepMorphError, match="no CUDA device is available"):
        Locator(model, device="cuda")
    # auto is the CPU here, and reads
    auto = CliRunner().invoke(app, ["decode", str(BUNDLED_MODEL), str(path), "--device", "auto", "--json"])
    assert auto.exit_code == 0, auto.output


def test_an_unknown_device_is_refused(model: DeepMorphModel) -> None:
    result = CliRunner().invoke(app, ["decode", str(BUNDLED_MODEL), "x.png", "--device", "tpu"])
    assert result.exit_code == 2 and "tpu" in result.output
    with pytest.raises(DeepMorphError, match="expected one of auto, cpu, cuda"):
        deepmorph.load(BUNDLED_MODEL, device="tpu")


@pytest.mark.parametrize("detector", [None, "universal"])
def test_the_cuda_chain_keeps_its_tensors_on_the_device(model: DeepMorphModel, detector: str | None) -> None:
    """Where no GPU is at hand (CI): the chain on a pretend CUDA device (``tests/pretend_cuda.py``)
    never hands a CPU tensor to an operation on the device's tensors, and reads what the CPU
    reads (the numbers are the CPU's either way)."""
    photos = _photos(model, 3)
    cpu = Locator(model, detector, device="cpu")
    expected = [[(d.payload.binary, d.ok) for d in cpu.locate(photo)] for photo, _ in photos]
    with pretend_cuda() as device:
        cuda = Locator(model, detector, device="cuda")
        assert isinstance(cuda.reader.decoder, DeviceNetwork)
        got = [[(d.payload.binary, d.ok) for d in cuda.locate(photo)] for photo, _ in photos]
    assert not device.mixes, device.mixes
    assert got == expected and any(ok for found in got for _, ok in found)


def test_a_pretend_runner_does_not_outlive_the_pretence() -> None:
    """The universal detector's runner is cached per process and device: one made on the pretend
    device (CPU weights) must be gone when the pretence ends, or a real CUDA device later in the
    same process would be handed CPU weights (found on an H200, where the pretend tests run too)."""
    with pretend_cuda():
        pretend = shared_runner(device="cuda")
        assert isinstance(pretend, DeviceNetwork)
    assert shared_runner.cache_info().currsize == 0


@needs_cuda
@pytest.mark.parametrize("detector", [None, "universal"])
def test_cuda_reads_what_the_cpu_reads(model: DeepMorphModel, detector: str | None) -> None:
    """The same photos on both: the same payloads, vouched for alike, corners within 0.5 px."""
    cpu, cuda = Locator(model, detector, device="cpu"), Locator(model, detector, device="cuda")
    assert isinstance(cuda.reader.decoder, DeviceNetwork) and cuda.detector.net.device.type == "cuda"
    assert all(p.device.type == "cuda" for p in cuda.detector.net.net.parameters())
    read = 0
    for photo, bits in _photos(model, 12):
        a, b = cpu.locate(photo), cuda.locate(photo)
        assert [(d.payload.binary, d.ok) for d in a] == [(d.payload.binary, d.ok) for d in b]
        for da, db in zip(a, b):
            assert np.abs(da.corners - db.corners).max() < 0.5
        read += any(d.ok and d.payload.binary == bits for d in a)
    assert read >= 10
