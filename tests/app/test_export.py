"""``deepmorph export``: the files and manifest it writes, and a program with ONNX Runtime alone
(no DeepMorph) that reads the same bits and finds the same drawings as the Python chain."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.framing import align_to_frame
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import random_payloads
from deepmorph_core.photo import to_gray
from deepmorph_core.render import render_svg
from deepmorph_detect.locate import Locator
from deepmorph_detect.scenes import SceneMaker, close_up_photo

app = application()

#: A host program: ONNX Runtime, NumPy and OpenCV, and what manifest.json says. It reads the
#: decoder's bits on framed images, checks their CRC, and finds detector peaks on photos.
HOST = r"""
import json, sys
import cv2, numpy as np, onnxruntime as ort

folder = sys.argv[1]
manifest = json.load(open(f"{folder}/manifest.json"))
dec, det, code = manifest["decoder"], manifest["detector"], manifest["code"]

def crc(bits, cfg):
    assert not cfg["reflect_input"] and not cfg["reflect_output"]
    width, reg = cfg["width"], cfg["init"]
    for bit in [0] * (-len(bits) % 8) + list(bits):
        top = ((reg >> (width - 1)) & 1) ^ int(bit)
        reg = (reg << 1) & ((1 << width) - 1)
        reg ^= cfg["polynomial"] if top else 0
    reg ^= cfg["final_xor"]
    return [(reg >> (width - 1 - i)) & 1 for i in range(width)]

decoder = ort.InferenceSession(f"{folder}/{dec['file']}", providers=["CPUExecutionProvider"])
mask = np.array([int(c) for c in code["whitening"]], np.uint8)
p, c = code["payload_bits"], code["crc_bits"]
reads = []
for frame in np.load(f"{folder}/frames.npy"):
    assert list(frame.shape) == dec["framing"]["size"]
    (logits,) = decoder.run([dec["output"]["name"]], {dec["input"]["name"]: frame[None, None]})
    hard = (logits[0] > 0).astype(np.uint8)
    word = hard ^ mask
    reads.append({"bits": hard.tolist(), "payload": word[:p].tolist(), "crc_ok": crc(word[:p], code["crc"]) == word[p:p + c].tolist()})

detector = ort.InferenceSession(f"{folder}/{det['file']}", providers=["CPUExecutionProvider"])
_, _, H, W = det["input"]["shape"]
found = []
for path in sorted(__import__("glob").glob(f"{folder}/photo-*.png")):
    gray = cv2.cvtColor(cv2.imread(path), cv2.COLOR_BGR2GRAY).astype(np.float32) / 255
    h, w = gray.shape
    s = min(W / w, H / h)
    rw, rh = max(1, round(w * s)), max(1, round(h * s))
    small = cv2.resize(gray, (rw, rh), interpolation=cv2.INTER_AREA)
    small = cv2.copyMakeBorder(small, 0, H - rh, 0, W - rw, cv2.BORDER_REPLICATE)
    heat, corners = detector.run(["heat", "corners"], {det["input"]["name"]: small[None, None]})
    prob = 1 / (1 + np.exp(-heat[0, 0]))
    peaks = (prob == cv2.dilate(prob, np.ones((3, 3), np.uint8))) & (prob > det["threshold"])
    found.append(sorted((float(v) for v in prob[peaks]), reverse=True)[: det["max_detections"]])

assert not [m for m in sys.modules if m.startswith("deepmorph")]
print(json.dumps({"reads": reads, "peaks": found}))
"""


def test_export_writes_the_graphs_and_a_manifest(tmp_path: Path) -> None:
    out = tmp_path / "export"
    result = CliRunner().invoke(app, ["export", str(BUNDLED_MODEL), "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["graphs"] == {"decoder": "stored", "detector": "stored"} and summary["bundle"] is None
    assert sorted(p.name for p in out.iterdir()) == ["decoder.onnx", "detector.onnx", "manifest.json"]
    for name, entry in summary["files"].items():
        blob = (out / name).read_bytes()
        assert entry["bytes"] == len(blob) and entry["sha256"] == hashlib.sha256(blob).hexdigest()
    manifest = json.loads((out / "manifest.json").read_text())
    model = DeepMorphModel.load(BUNDLED_MODEL)
    assert manifest["format"] == "deepmorph-export/1"
    assert manifest["decoder"]["input"]["shape"] == [1, 1, *model.image_size]
    assert manifest["decoder"]["output"]["shape"] == [1, model.codec.spec.code_bits]
    assert manifest["detector"]["input"]["shape"] == [1, 1, 192, 256]
    for name in ("decoder", "detector"):
        assert manifest[name]["sha256"] == hashlib.sha256((out / f"{name}.onnx").read_bytes()).hexdigest()
    code = manifest["code"]
    assert (code["payload_bits"], code["crc_bits"], code["code_bits"]) == (24, 8, model.codec.spec.code_bits)
    assert code["bch"]["t"] == model.codec.spec.bch_t and len(code["whitening"]) == code["code_bits"]
    assert manifest["template"]["viewbox"] == list(model.drawing.drawing.viewbox)
    text = CliRunner().invoke(app, ["export", str(BUNDLED_MODEL), "--out", str(out)])  # rewritten whole
    assert text.exit_code == 0 and "wrote decoder.onnx (1.5 MB), detector.onnx" in " ".join(text.output.split())

    usage = CliRunner().invoke(app, ["export", str(BUNDLED_MODEL)])
    assert usage.exit_code == 2 and "--out" in usage.output
    clash = CliRunner().invoke(app, ["export", str(out / "x.dmm"), "--out", str(out / "manifest.json")])
    assert clash.exit_code == 1 and "error:" in clash.output and "Traceback" not in clash.output


def test_export_stores_graphs_in_an_old_bundle(tmp_path: Path) -> None:
    old = DeepMorphModel.load(BUNDLED_MODEL)
    old.graphs = {}
    old.save(tmp_path / "old.dmm")
    result = CliRunner().invoke(app, ["export", str(tmp_path / "old.dmm"), "--bundle", str(tmp_path / "old.dmm")])
    assert result.exit_code == 0, result.output
    assert "with its ONNX graphs (decoder, detector)" in " ".join(result.output.split())
    again = DeepMorphModel.load(tmp_path / "old.dmm")
    ghost = DeepMorphModel.load(BUNDLED_MODEL)
    assert {name: g.data for name, g in again.graphs.items()} == {name: g.data for name, g in ghost.graphs.items()}
    for graph in again.graphs.values():  # the same bytes from any checkout: no source paths, lines or traces
        assert b"stack_trace" not in graph.data and b"deepmorph_core/" not in graph.data


def test_a_host_with_onnx_runtime_alone_reads_what_the_chain_reads(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["export", str(BUNDLED_MODEL), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    model = DeepMorphModel.load(BUNDLED_MODEL)
    locator = Locator(model)
    rng = np.random.default_rng(5)
    payloads = random_payloads(8, model.codec.spec.payload_bits, rng)
    frames, readings = [], []
    for payload in payloads:
        photo = to_gray(close_up_photo(render_svg(model.encode(payload), 300), "medium", rng))
        frames.append(align_to_frame(photo, model.image_size, model.canonical_moments())[0])
        readings.append(locator.reader.read(photo, soft=False))  # the chain's own reading of the view
    np.save(tmp_path / "frames.npy", np.stack(frames).astype(np.float32))
    maker = SceneMaker(model, (640, 480), "medium", seed=4)
    scenes = [maker.make(drawings=k % 3, distractors=1) for k in range(4)]
    for k, scene in enumerate(scenes):
        cv2.imwrite(str(tmp_path / f"photo-{k}.png"), scene.image)

    host = subprocess.run(
        [sys.executable, "-I", "-c", HOST, str(tmp_path)], capture_output=True, text=True, timeout=120, check=False
    )
    assert host.returncode == 0, host.stderr
    got = json.loads(host.stdout)
    for read, reading in zip(got["reads"], readings):
        assert read["bits"] == (reading.probabilities > 0.5).astype(int).tolist()
        if reading.result.corrected_bits == 0:  # no correction needed: the host's CRC says what the codec says
            assert read["crc_ok"] == reading.result.ok
            assert read["payload"] == reading.result.payload.tolist()
    assert sum(r["crc_ok"] and r["payload"] == p.tolist() for r, p in zip(got["reads"], payloads)) >= 6
    for peaks, scene in zip(got["peaks"], scenes):
        candidates = locator.detector.detect(scene.image)
        np.testing.assert_allclose(peaks, [c.score for c in candidates], atol=1e-3)
    assert any(got["peaks"])
