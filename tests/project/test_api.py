"""The public API (``import deepmorph``): the payloads and images it takes, the errors it gives
for anything else, colour order, PDFs that decode, and ``train`` as the command line has it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pypdfium2
import pytest
from PIL import Image

import deepmorph
from deepmorph_core.bundled import BUNDLED_DRAWING, BUNDLED_MODEL
from deepmorph_detect.scenes import close_up_photo
from tests.conftest import shaken_clip

PAYLOAD = 0xA1B2C3


@pytest.fixture(scope="module")
def ghost() -> deepmorph.Model:
    return deepmorph.load(BUNDLED_MODEL)


@pytest.fixture(scope="module")
def photo(ghost: deepmorph.Model) -> np.ndarray:
    """A close-up photo (BGR uint8) of the code under a warm light: its channels differ."""
    bgr = close_up_photo(ghost.encode(PAYLOAD).render(200), "easy", np.random.default_rng(4))
    return np.clip(bgr * np.array([0.55, 0.8, 1.0]), 0, 255).astype(np.uint8)


def read(found: list[deepmorph.Located]) -> list[tuple[str, bool, list[float]]]:
    return [(f.payload.hex, f.ok, np.round(f.corners, 3).ravel().tolist()) for f in found]


@pytest.mark.parametrize(
    "payload",
    [
        PAYLOAD,
        np.uint32(PAYLOAD),
        "0xA1B2C3",
        "0xa1b2c3",
        "101000011011001011000011",
        b"\xa1\xb2\xc3",
        bytearray(b"\xa1\xb2\xc3"),
        [int(b) for b in "101000011011001011000011"],
        np.array([int(b) for b in "101000011011001011000011"], np.uint8),
        deepmorph.Payload(np.array([int(b) for b in "101000011011001011000011"])),
    ],
    ids=lambda p: type(p).__name__,
)
def test_every_payload_form_gives_the_same_code(ghost: deepmorph.Model, payload: deepmorph.PayloadLike) -> None:
    code = ghost.encode(payload)
    assert isinstance(code, deepmorph.Code)
    assert (code.payload.int, code.payload.hex, code.payload.bytes) == (PAYLOAD, "0xA1B2C3", b"\xa1\xb2\xc3")
    assert code.svg == ghost.encode(PAYLOAD).svg


@pytest.mark.parametrize(
    "payload, message",
    [
        (2**24, "does not fit in 24 bits"),
        (-1, "does not fit in 24 bits"),
        (1.0, "cannot be a float"),
        (math.nan, "cannot be a float"),
        (None, "cannot be None"),
        (True, "not a bool"),
        ({"a": 1}, "cannot be a dict"),
        ("0xA1B2", "has 4 hex digits"),
        ("0xA1B2C3D", "has 7 hex digits"),
        ("1010", "has 4 binary digits"),
        ("hello", "neither 0x-prefixed hex, a 0d-prefixed number nor binary digits"),
        (b"\xa1\xb2", "payload of 2 bytes"),
        (b"\x00\xa1\xb2\xc3", "payload of 4 bytes"),
        (b"", "payload of 0 bytes"),
        ([0, 1] * 5, "shape (24,), got (10,)"),
        ([2] + [0] * 23, "only 0 and 1"),
        (np.zeros((4, 6)), "shape (24,), got (4, 6)"),
    ],
    ids=repr,
)
def test_a_wrong_payload_is_one_clear_error(ghost: deepmorph.Model, payload: object, message: str) -> None:
    with pytest.raises(deepmorph.DeepMorphError) as err:
        ghost.encode(payload)  # type: ignore[arg-type]
    assert message in str(err.value) and "expected a 24-bit payload" in str(err.value), str(err.value)


def test_every_image_type_reads_the_same(ghost: deepmorph.Model, photo: np.ndarray, tmp_path: Path) -> None:
    path = tmp_path / "photo.png"
    cv2.imwrite(str(path), photo)
    rgb = np.ascontiguousarray(photo[..., ::-1])
    gray = cv2.cvtColor(photo, cv2.COLOR_BGR2GRAY)
    expected = read(ghost.decode(rgb))
    assert [(hex_, ok) for hex_, ok, _ in expected] == [("0xA1B2C3", True)]
    same = {
        "str path": str(path),
        "Path": path,
        "PIL RGB": Image.fromarray(rgb),
        "PIL RGBA": Image.fromarray(rgb).convert("RGBA"),
        "RGBA array": np.dstack([rgb, np.full(gray.shape, 255, np.uint8)]),
        "gray uint8": gray,
        "gray float": gray.astype(np.float32) / 255,
    }
    for name, image in same.items():
        assert read(ghost.decode(image)) == expected, name
    assert read(ghost.decode(photo, bgr=True)) == expected  # OpenCV's order, said so


def test_swapped_colour_order_of_a_black_print_reads_the_same(ghost: deepmorph.Model) -> None:
    """The chain reads gray; a BGR photo passed as RGB weighs red and blue the other way round,
    which leaves a black print on paper as legible (warm and cool light, three photos each)."""
    art = ghost.encode(PAYLOAD).render(200)
    for seed in range(3):
        bgr = close_up_photo(art, "medium", np.random.default_rng(seed))
        for light in ([0.55, 0.8, 1.0], [1.0, 0.75, 0.45]):
            lit = np.clip(bgr * np.array(light), 0, 255).astype(np.uint8)
            assert [(f.payload.hex, f.ok) for f in ghost.decode(lit)] == [("0xA1B2C3", True)]


@pytest.mark.parametrize(
    "image, message",
    [
        (None, "not None"),
        (42, "not a int"),
        (b"\x89PNG", "not a bytes"),
        ("missing.png", "no such image file"),
        (np.zeros((40, 40, 5), np.uint8), "expected 1, 3 (BGR) or 4 (BGRA) channels"),
        (np.zeros((2, 40, 40, 3), np.uint8), "expected a 2-D image"),
        (np.full((40, 40), 200.0), "float"),
    ],
    ids=["None", "int", "bytes", "missing", "5 channels", "4-D", "float 0-255"],
)
def test_a_wrong_image_is_one_clear_error(ghost: deepmorph.Model, image: object, message: str) -> None:
    with pytest.raises(deepmorph.DeepMorphError, match=message.replace("(", r"\(").replace(")", r"\)")):
        ghost.decode(image)  # type: ignore[arg-type]


def test_a_folder_is_not_an_image(ghost: deepmorph.Model, tmp_path: Path) -> None:
    with pytest.raises(deepmorph.DeepMorphError, match="is a folder, not an image file"):
        ghost.decode(tmp_path)


def _alike(a: object, b: object, tol: float = 1e-5) -> bool:
    """The same JSON values, numbers within ``tol``: after other reads in the same process, the
    same frames' pose can come out a unit apart in its sixth printed decimal (float rounding)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_alike(a[k], b[k], tol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_alike(x, y, tol) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and abs(a - b) <= tol
    return a == b


def test_a_folder_or_a_video_is_one_sequence_read_as_decode_reads_it(ghost: deepmorph.Model, tmp_path: Path) -> None:
    """``Model.decode_sequence``: a folder of frames and a video of the same print, shaken a
    little, give one drawing read over the frames, as ``deepmorph decode`` gives it."""
    from typer.testing import CliRunner

    from deepmorph.cli import application
    from deepmorph_detect.scenes import SceneMaker

    scene = SceneMaker(ghost.bundle, severity="medium", seed=14).make(drawings=1)
    folder = tmp_path / "frames"
    shaken_clip(scene.image, 4, np.random.default_rng(3), folder, tmp_path / "clip.avi")
    bits = "".join(map(str, scene.placements[0].payload))
    for source in (folder, tmp_path / "clip.avi"):
        taken: list[None] = []
        reading = ghost.decode_sequence(source, on_frame=lambda taken=taken: taken.append(None))
        assert reading.frames == len(taken) == 4 and reading.skipped == []
        (found,) = reading.detections
        assert found["ok"] and found["payload"]["bits"] == bits and found["frames"] >= 3, found
    assert ghost.decode_sequence(tmp_path / "clip.avi", every=2).frames == 2
    res = CliRunner().invoke(application(), ["decode", str(BUNDLED_MODEL), str(folder), "--json"])
    assert res.exit_code == 0
    assert _alike(json.loads(res.stdout)[0]["detections"], ghost.decode_sequence(folder).detections)
    # a frame cut short is skipped, and said; the others still count
    whole = (folder / "f01.png").read_bytes()
    (folder / "f01.png").write_bytes(whole[: len(whole) // 3])
    said: list[str] = []
    reading = ghost.decode_sequence(folder, on_skip=said.append)
    assert reading.frames == 3 and [s["frame"] for s in reading.skipped] == ["f01.png"] and "f01.png" in said[0]
    assert reading.detections[0]["payload"]["bits"] == bits
    (tmp_path / "empty").mkdir()
    for source, message in ((folder / "f00.png", "Model.decode reads a single image"),
                            (tmp_path / "empty", "holds no image files"), (tmp_path / "gone", "no such folder"),
                            (tmp_path / "gone.mp4", "no such video file"), (folder, "positive")):  # fmt: skip
        with pytest.raises(deepmorph.DeepMorphError, match=message):
            ghost.decode_sequence(source, every=0 if message == "positive" else 1)


def test_the_pdf_is_the_print_size_and_its_raster_decodes(ghost: deepmorph.Model, tmp_path: Path) -> None:
    code = ghost.encode(PAYLOAD)
    pdf_path = code.save(tmp_path / "code.pdf", width_mm=40)
    pdf = pypdfium2.PdfDocument(pdf_path.read_bytes())
    page = pdf[0]
    assert page.get_size() == pytest.approx((40 / 25.4 * 72, 40 / 25.4 * 72), abs=1e-3)
    raster = page.render(scale=300 / 72, grayscale=True, fill_color=(255, 255, 255, 255)).to_pil().convert("L")
    pdf.close()
    assert abs(raster.width - 40 / 25.4 * 300) < 1  # 300 dpi
    sheet = np.pad(np.asarray(raster), 60, constant_values=255)  # the print on paper
    assert [(f.payload.hex, f.ok) for f in ghost.decode(sheet)] == [("0xA1B2C3", True)]
    small = cv2.resize(sheet, (200, 200), interpolation=cv2.INTER_AREA).astype(np.float32) / 255
    snap = close_up_photo(small, "medium", np.random.default_rng(1))  # a phone photo of that print
    assert [(f.payload.hex, f.ok) for f in ghost.decode(snap, bgr=True)] == [("0xA1B2C3", True)]


def test_train_passes_each_keyword_on(tmp_path: Path) -> None:
    logs: list[dict[str, float]] = []
    model = deepmorph.train(
        BUNDLED_DRAWING, tmp_path / "m.dmm", payload_bits=4, crc_bits=8, ecc_t=0, steps=3, batch=2, image_width=32,
        severity="none", real_render_share=0.5, small_prints=0.25, seed=5, encoder_init="random",
        spatial_transformer=False, readout=False, threads=1, checkpoint_every=2, move=0.7, shift=0.3, scale=(0.95, 1.05),
        rotate=(-2, 2), on_log=logs.append,
    )  # fmt: skip
    info = model.info()
    assert (info["payload_bits"], info["codec"]["crc_bits"], info["codec"]["bch_t"]) == (4, 8, 0)
    settings = {"steps": 3, "batch": 2, "width": 32, "severity": "none", "hard_fraction": 0.5, "small_prints": 0.25,
                "seed": 5, "encoder_init": "random", "spatial_transformer": False, "readout": False, "threads": 1,
                "checkpoint_every": 2}  # fmt: skip
    assert {k: info["train"][k] for k in settings} == settings
    assert info["bounds_defaults"] == {"move": 0.7, "shift": [0.3, 0.3], "scale": [0.95, 1.05], "rotate": [-2, 2]}
    assert logs and logs[-1]["step"] == 3
    with pytest.raises(deepmorph.DeepMorphError, match="nothing to resume"):
        deepmorph.train(BUNDLED_DRAWING, tmp_path / "m.dmm", resume=True)
