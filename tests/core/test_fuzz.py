"""Fuzzing the three readers of files strangers make: SVG drawings, model bundles and images.

Whatever bytes they are given, they return a result or raise one ``DeepMorphError``: no other
exception, no hang. Hypothesis draws the inputs (deterministically, so CI cannot flake), and
the number of examples keeps the whole module to a few seconds.
"""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deepmorph_core.bundled import BUNDLED_DRAWING, BUNDLED_MODEL
from deepmorph_core.drawing import load_drawing
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.image_io import read_image_bgr
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.morph import MorphSpace

SEED_SVG = BUNDLED_DRAWING.read_bytes()
SEED_BUNDLE = BUNDLED_MODEL.read_bytes()
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

TAGS = ["line", "polyline", "polygon", "rect", "circle", "ellipse", "path", "g", "a", "defs", "style", "use", "text"]
ATTRS = ["x1", "y1", "x2", "y2", "cx", "cy", "r", "rx", "ry", "x", "y", "width", "height", "points", "d",
         "transform", "stroke", "fill", "stroke-width", "style", "dm:move", "dm:shift", "dm:scale", "dm:rotate",
         "href", "onload", "class", "viewBox"]  # fmt: skip
VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(str),
    st.sampled_from(
        [
            "M1 1 L5 5 A2 2 0 0 1 9 9 Z",
            "1,2 3,4",
            "rotate(30)",
            "black",
            "none",
            "url(#p)",
            "1e308",
            "javascript:x",
            "a2 2 0 0 0-1-1.73",
            "١٢",
            "",
            "  ",
            "matrix(0 0 0 0 0 0)",
        ]
    ),  # fmt: skip
    st.text(max_size=12),
)


@st.composite
def documents(draw: st.DrawFn) -> bytes:
    def element(depth: int) -> str:
        tag = draw(st.sampled_from(TAGS))
        attrs = draw(st.dictionaries(st.sampled_from(ATTRS), VALUES, max_size=5))
        text = " ".join(f'{k}="{_escape(v)}"' for k, v in attrs.items())
        kids = "".join(element(depth + 1) for _ in range(draw(st.integers(0, 2)) if depth < 3 else 0))
        return f"<{tag} {text}>{kids}</{tag}>"

    body = "".join(element(0) for _ in range(draw(st.integers(0, 4))))
    viewbox = draw(st.sampled_from(["0 0 24 24", "0 0 0 0", "-1 -1 1e6 1e-6", "0 0 24", "a b c d"]))
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:dm="urn:deepmorph:1" viewBox="{viewbox}" dm:move="0.5">'
        f"{body}</svg>"
    ).encode()


def _escape(value: str) -> str:
    return value.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;")


def _mutate(data: bytes, edits: list[tuple[int, int]], cut: int | None) -> bytes:
    buf = bytearray(data)
    for where, byte in edits:
        buf[where % len(buf)] = byte
    return bytes(buf[:cut] if cut else buf)


def _reads_or_refuses(call) -> object:
    try:
        return call()
    except DeepMorphError:
        return None


@FAST
@given(documents())
def test_the_svg_reader_returns_or_refuses_made_up_documents(data: bytes) -> None:
    drawing = _reads_or_refuses(lambda: load_drawing(data))
    if drawing is not None and drawing.primitives:
        space = MorphSpace(drawing)
        written = space.write_svg(space.values_from_unit(space.neutral_unit(1))[0])
        assert "<script" not in written and "onload" not in written and "href" not in written


@FAST
@given(st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), max_size=8), st.none() | st.integers(1, 3000))
def test_the_svg_reader_returns_or_refuses_damaged_files(edits: list[tuple[int, int]], cut: int | None) -> None:
    _reads_or_refuses(lambda: load_drawing(_mutate(SEED_SVG, edits, cut)))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(st.tuples(st.integers(0, 10**7), st.integers(0, 255)), min_size=1, max_size=6),
    st.none() | st.integers(1, 10**6),
)
def test_the_bundle_loader_returns_or_refuses_damaged_bundles(
    tmp_path_factory: pytest.TempPathFactory, edits: list[tuple[int, int]], cut: int | None
) -> None:
    path = tmp_path_factory.mktemp("b") / "damaged.dmm"
    # damage the first 64 KiB most of the time: the header and metadata are where parsing happens
    near = [(where % 65536 if where % 3 else where, byte) for where, byte in edits]
    path.write_bytes(_mutate(SEED_BUNDLE, near, cut))
    _reads_or_refuses(lambda: DeepMorphModel.load(path))


def _encoded(kind: str) -> bytes:
    image = (np.random.default_rng(0).random((40, 50, 3)) * 255).astype(np.uint8)
    if kind == "tiff":
        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(image).save(buf, format="TIFF")
        return buf.getvalue()
    ok, buf = cv2.imencode(f".{kind}", image)
    assert ok
    return buf.tobytes()


IMAGES = {kind: _encoded(kind) for kind in ("png", "jpg", "bmp", "webp", "tiff")}


@FAST
@given(
    st.sampled_from(sorted(IMAGES)),
    st.lists(st.tuples(st.integers(0, 10**5), st.integers(0, 255)), max_size=6),
    st.none() | st.integers(1, 2000),
)
def test_the_image_reader_returns_or_refuses_damaged_images(
    tmp_path_factory: pytest.TempPathFactory, kind: str, edits: list[tuple[int, int]], cut: int | None
) -> None:
    path = tmp_path_factory.mktemp("i") / f"damaged.{kind}"
    path.write_bytes(_mutate(IMAGES[kind], edits, cut))
    image = _reads_or_refuses(lambda: read_image_bgr(path))
    if image is not None:
        assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3


def test_the_seeds_read() -> None:
    """The undamaged inputs the fuzzers start from are read (so the fuzzers test refusals)."""
    assert load_drawing(SEED_SVG).primitives
    assert DeepMorphModel.load(BUNDLED_MODEL).meta.n_variables > 0
    for kind, data in IMAGES.items():
        path = Path(__file__).parent / f"__seed.{kind}"
        try:
            path.write_bytes(data)
            assert read_image_bgr(path).shape == (40, 50, 3)
        finally:
            path.unlink(missing_ok=True)
