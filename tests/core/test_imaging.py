"""Framing images for the decoder: photos and renders are framed the same way."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from deepmorph_core.bundled import BUNDLED_DRAWING
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.framing import (
    align_to_frame,
    canonicalize,
    canonicalize_one,
    mask_moments,
    mask_moments_one,
    render_moments,
)
from deepmorph_core.image_io import library_said, read_image, save_gray
from deepmorph_core.kernels import (
    SELECTION_SAMPLE,
    _area_weights,
    area_resize,
    component_label_type,
    order_statistics,
    percentiles,
)
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.photo import flatten_illumination, ink_mask, to_gray
from deepmorph_core.render import render_svg


@pytest.fixture(scope="module")
def ghost() -> tuple[MorphableDrawing, np.ndarray]:
    md = MorphableDrawing.load(BUNDLED_DRAWING)
    return md, render_svg(md.to_svg(md.neutral_values()[0]), 96)


def test_canonical_frame_is_a_fixed_point(ghost) -> None:
    md, base = ghost
    img = torch.from_numpy(base)[None, None]
    target = render_moments(img)[0]
    framed = canonicalize(img, render_moments(img), target, (96, 96))
    assert (framed - img).abs().mean() < 0.01


def test_one_image_framing_matches_the_batched_one(ghost) -> None:
    """Decoding frames one view by OpenCV's warpAffine, training a batch by torch's grid_sample:
    the same map and sampling, shrunk, enlarged, shifted past the edge (white beyond it)."""
    _, base = ghost
    target = render_moments(torch.from_numpy(base)[None, None])[0]
    for moments in ([48.3, 47.1, 20.0, 18.5], [150.2, 140.7, 61.0, 55.3], [10.4, 90.6, 14.0, 16.0]):
        m = np.array(moments)
        expected = canonicalize(torch.from_numpy(base)[None, None], torch.from_numpy(m)[None], target, (96, 96))
        got = canonicalize_one(base, m, target, (96, 96))
        assert got.shape == (96, 96) and got.dtype == np.float32
        assert np.abs(got - expected[0, 0].numpy()).mean() < 1e-3
        assert np.abs(got - expected[0, 0].numpy()).max() < 0.05


def test_one_mask_moments_match_the_batched_ones(ghost) -> None:
    """Decoding frames a photo by OpenCV's moments, training by the batched torch ones: the
    same numbers, for the drawing's ink, for speckle and for an empty mask."""
    _, base = ghost
    rng = np.random.default_rng(3)
    for mask in (base < 0.5, rng.random((70, 130)) < 0.1, np.zeros((40, 50), bool)):
        expected = mask_moments(torch.from_numpy(mask)[None])[0].numpy()
        np.testing.assert_allclose(mask_moments_one(mask), expected, rtol=1e-9, atol=1e-9)


def test_a_frame_set_by_given_moments_ignores_ink_a_shadow_adds(ghost) -> None:
    """A dark band beside the drawing counts as ink and drags the framing by the photo's ink off; framed by the moments of the drawing's own ink (what a rectified view's alignment
    gives), the frame is the clean render's frame. Given moments are used as they are: moved
    by 6 px, the frame's content moves by 6 px times the frame's scale."""
    md, base = ghost
    target = render_moments(torch.from_numpy(base)[None, None])[0]
    clean = np.pad(render_svg(md.to_svg(md.neutral_values()[0]), 192), 24, constant_values=1.0)
    own = mask_moments_one(clean < 0.5)
    shaded = clean.copy()
    shaded[24:216, 4:20] *= 0.35  # a shadow's edge as dark as ink, in the margin (not at the border)
    clean_frame, _ = align_to_frame(clean, (96, 96), target)
    by_photo, _ = align_to_frame(shaded, (96, 96), target)
    by_moments, _ = align_to_frame(shaded, (96, 96), target, moments=own)
    inner = np.s_[:, 30:]  # away from the band, the two framings differ only by where they put the drawing
    assert np.abs(by_moments - clean_frame)[inner].mean() < 0.01
    assert np.abs(by_photo - clean_frame)[inner].mean() > 5 * np.abs(by_moments - clean_frame)[inner].mean()
    moved, _ = align_to_frame(clean, (96, 96), target, moments=own + np.array([6.0, 0.0, 0.0, 0.0]))
    scale = float(target[2]) / own[2]
    shifts = [np.abs(np.roll(moved, s, axis=1) - clean_frame)[:, 10:-10].mean() for s in range(8)]
    assert abs(int(np.argmin(shifts)) - 6 * scale) <= 1


@pytest.mark.parametrize("width, pad, tol", [(96, 0, 0.03), (300, 40, 0.03), (57, 5, 0.06)])
def test_photo_framing_matches_render_framing(ghost, width: int, pad: int, tol: float) -> None:
    """A larger (or smaller) render with a paper margin frames like the training render."""
    md, base = ghost
    target = render_moments(torch.from_numpy(base)[None, None])[0]
    big = np.pad(render_svg(md.to_svg(md.neutral_values()[0]), width), pad, constant_values=1.0)
    frame, box = align_to_frame(big, (96, 96), target)
    assert np.abs(frame - base).mean() < tol  # a smaller source is blurrier when enlarged
    assert box[0] >= pad and box[2] <= width + pad


@pytest.mark.parametrize("width", [192, 240, 288])
def test_larger_sources_keep_their_edges_where_the_render_has_them(ghost, width: int) -> None:
    """A source two to three decoder widths wide is area-averaged, not sampled, into the frame:
    on its edge pixels (where the morphs are read) it differs from a render at the frame's
    width by less than 0.12 on average (0.09-0.11; sampling left 0.15-0.18)."""
    md, base = ghost
    target = render_moments(torch.from_numpy(base)[None, None])[0]
    frame, _ = align_to_frame(render_svg(md.to_svg(md.neutral_values()[0]), width), (96, 96), target)
    edges = (base > 0.02) & (base < 0.98)
    assert np.abs(frame - base)[edges].mean() < 0.12


def test_blank_and_flat_images_have_no_drawing(ghost) -> None:
    md, base = ghost
    target = render_moments(torch.from_numpy(base)[None, None])[0]
    assert align_to_frame(np.ones((80, 80), np.float32), (96, 96), target) is None
    assert align_to_frame(np.full((80, 80), 0.2, np.float32), (96, 96), target) is None
    noise = np.random.default_rng(0).uniform(0.97, 1.0, (80, 80)).astype(np.float32)
    assert align_to_frame(noise, (96, 96), target) is None


def test_an_unreadable_image_says_what_the_library_said_without_its_log_prefix(tmp_path) -> None:
    """OpenCV logs a failed decode with its level, source file, line and function around the
    message; the one error line keeps the message alone."""
    gif = tmp_path / "cut.gif"
    gif.write_bytes(b"GIF89a")
    with pytest.raises(DeepMorphError) as caught:
        read_image(gif)
    said = str(caught.value)
    assert said.startswith(f"{gif}: not an image OpenCV can read (corrupt, or an unsupported format")
    assert "[ERROR" not in said and ".cpp" not in said and "in function" not in said
    opencv = (
        "[ERROR:0@1.514] global loadsave.cpp:1377 imdecode_ imdecode_(''): can't read header: OpenCV(5.1.0) "
        "/io/opencv/modules/imgcodecs/src/bitstrm.cpp:59: error: (-2:Unspecified error) Unexpected end of "
        "input stream in function 'readBlock'\n\n"
    )
    assert library_said(opencv) == "can't read header: Unexpected end of input stream"
    assert library_said("libpng warning: iCCP: known incorrect sRGB profile\n") == (
        "libpng warning: iCCP: known incorrect sRGB profile"
    )
    assert library_said("") == "" and library_said("\n \n") == ""


def test_read_image_errors(tmp_path) -> None:
    with pytest.raises(DeepMorphError, match="no such image file"):
        read_image(tmp_path / "none.png")
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\nbroken")
    with pytest.raises(DeepMorphError, match="not an image"):
        read_image(bad)
    empty = tmp_path / "empty.jpg"
    empty.write_bytes(b"")
    with pytest.raises(DeepMorphError, match="empty file"):
        read_image(empty)
    tiny = tmp_path / "tiny.png"
    save_gray(np.linspace(0, 1, 64).reshape(8, 8), tiny)
    with pytest.raises(DeepMorphError, match=r"tiny.png: 8x8 pixels is too small to hold a drawing"):
        read_image(tiny)
    ok = tmp_path / "ok.png"
    save_gray(np.linspace(0, 1, 320).reshape(16, 20), ok)
    img = read_image(ok)
    assert img.shape == (16, 20) and img.dtype == np.float32 and 0 <= img.min() and img.max() <= 1


def test_to_gray_takes_every_usual_pixel_type_and_refuses_the_rest() -> None:
    bgr = np.random.default_rng(0).integers(0, 256, (40, 50, 3), dtype=np.uint8)
    gray = to_gray(bgr)
    assert gray.dtype == np.float32 and gray.shape == (40, 50)
    same = [np.dstack([bgr, np.full((40, 50), 255, np.uint8)]), bgr.astype(np.uint16) * 257, bgr / 255.0]
    for image in same:  # BGRA, 16-bit (was clipped to white) and float BGR give the same gray
        assert np.abs(to_gray(image) - gray).max() < 1 / 255
    assert np.array_equal(to_gray(bgr[..., :1]), bgr[..., 0] / np.float32(255))
    assert np.array_equal(to_gray(bgr[..., 0] > 127), (bgr[..., 0] > 127).astype(np.float32))
    assert to_gray(np.full((20, 20), 1.2)).max() == 1.0  # noise just past white is clipped
    refused = {
        "lie in \\[0, 255\\] \\(divide by 255": bgr.astype(np.float64),  # a 0-255 float photo was all white
        "lie in \\[12, 200\\]": np.linspace(12, 200, 400).reshape(20, 20),
        "expected 1, 3 \\(BGR\\) or 4": bgr[..., :2],
        "int64 pixels are not supported": bgr.astype(np.int64),
        "non-finite": np.full((20, 20), np.nan, np.float32),
        "2-D image": np.zeros(100, np.uint8),
    }
    for message, image in refused.items():
        with pytest.raises(DeepMorphError, match=message):
            to_gray(image)


@pytest.mark.parametrize("width", [96, 480])  # 480: a closing wider than PAPER_CLOSING_PX, run shrunk
def test_flatten_illumination_removes_a_shadow_and_keeps_the_ink(ghost, width: int) -> None:
    drawing, render = ghost
    if width != render.shape[1]:
        render = render_svg(drawing.to_svg(drawing.neutral_values()[0]), width)
    render = render.astype(np.float32)
    shadowed = render.copy()
    shadowed[:, int(0.6 * shadowed.shape[1]) :] *= 0.45  # a hard shadow edge across the print
    stroke_px = 2.6 / 64 * render.shape[1]
    flat = flatten_illumination(shadowed, stroke_px)
    assert np.abs(shadowed - render).mean() > 0.1
    assert np.abs(flat - render).mean() < 0.02
    assert np.abs(flatten_illumination(render, stroke_px) - render).mean() < 0.01  # clean paper: unchanged
    ink = render < 0.5
    assert flat[ink].mean() < 0.35 and flat[~ink].mean() > 0.95


def test_paper_light_of_a_wide_closing_matches_the_full_size_one(ghost) -> None:
    """The shrunk closing (:data:`PAPER_CLOSING_PX`) finds the light the full-size one finds, on a
    print under a smooth gradient and sensor noise."""
    import cv2

    from deepmorph_core.photo import PAPER_CLOSING_PX, paper_light

    drawing, _ = ghost
    render = render_svg(drawing.to_svg(drawing.neutral_values()[0]), 400).astype(np.float32)
    light = np.linspace(0.55, 1.0, render.shape[1], dtype=np.float32)[None, :] * np.ones_like(render)
    photo = render * light + np.random.default_rng(0).normal(0, 0.02, render.shape).astype(np.float32)
    feature_px = 2.6 / 64 * 400
    k = int(1.5 * feature_px) | 1
    assert k > PAPER_CLOSING_PX
    ellipse = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    full = cv2.GaussianBlur(cv2.morphologyEx(photo, cv2.MORPH_CLOSE, ellipse), (0, 0), k / 4)
    shrunk = paper_light(photo, feature_px)
    paper = render > 0.9
    assert np.abs(shrunk - full)[paper].mean() < 0.01
    assert np.corrcoef(shrunk[paper], light[paper])[0, 1] > 0.99


def test_read_image_follows_exif_orientation_and_refuses_bombs_before_decoding(tmp_path) -> None:
    import struct
    import zlib

    import cv2
    from PIL import Image

    from deepmorph_core.image_io import read_image_bgr

    pixels = np.random.default_rng(0).integers(0, 256, (60, 90, 3), dtype=np.uint8)
    for orientation in range(1, 9):
        path = tmp_path / f"o{orientation}.jpg"
        exif = Image.Exif()
        exif[0x0112] = orientation
        Image.fromarray(pixels).save(path, exif=exif.tobytes(), quality=95)
        # OpenCV's own reader turns by the tag too (but drops alpha and 16 bits, which we keep)
        assert np.array_equal(read_image_bgr(path), cv2.imread(str(path))), orientation

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    for side, message in [(30000, "claims far too many pixels"), (9500, "9500x9500 pixels is too large")]:
        rows = zlib.compress(b"\x00" * (side + 1) * 8)  # a few rows of a huge gray image: 10 KB on disk
        header = struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0)
        bomb = tmp_path / f"bomb{side}.png"
        bomb.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", rows) + chunk(b"IEND", b""))
        with pytest.raises(DeepMorphError, match=message):
            read_image_bgr(bomb)


def test_a_heic_photo_is_read_turned_as_stored_once(tmp_path) -> None:
    """iPhones take HEIC photos, which OpenCV cannot decode: libheif decodes them, turned as
    the file says (the EXIF tag written as HEIF's own turn), and never turned a second time.
    Each of the eight orientations reads nearest its own turn of the pixels."""
    from PIL import Image

    from deepmorph_core.image_io import is_heif, read_image_bgr, upright

    y, x = np.mgrid[0:60, 0:90]
    pixels = np.stack([2 * x, 4 * y, np.full_like(x, 128)], axis=-1).astype(np.uint8)
    pixels[5:25, 10:40] = (255, 255, 0)  # a block near one corner: no turn looks like another
    for orientation in range(1, 9):
        path = tmp_path / f"o{orientation}.heic"
        exif = Image.Exif()
        exif[0x0112] = orientation
        Image.fromarray(pixels).save(path, exif=exif.tobytes(), quality=95)
        assert is_heif(np.fromfile(path, np.uint8))
        read = read_image_bgr(path)[..., ::-1].astype(np.float32)
        errors = {
            k: float(np.abs(read - upright(pixels, k)).mean())
            for k in range(1, 9)
            if upright(pixels, k).shape == read.shape
        }
        assert min(errors, key=errors.get) == orientation and errors[orientation] < 4.0, (orientation, errors)


def test_a_print_photographed_as_heic_reads_its_payload_and_a_cut_heic_says_so(tmp_path) -> None:
    from PIL import Image

    import deepmorph
    from deepmorph_core.bundled import BUNDLED_MODEL

    model = deepmorph.load(BUNDLED_MODEL)
    png = tmp_path / "print.png"
    png.write_bytes(model.encode(0x3039).png(50, 150))
    heic = tmp_path / "IMG_0001.HEIC"
    Image.open(png).save(heic, format="HEIF", quality=80)
    found = [d for d in model.decode(heic) if d.ok]
    assert [d.payload.int for d in found] == [0x3039]
    cut = tmp_path / "cut.heic"
    cut.write_bytes(heic.read_bytes()[: heic.stat().st_size // 2])
    with pytest.raises(DeepMorphError) as caught:
        read_image(cut)
    said = str(caught.value)
    assert said.startswith(f"{cut}: a HEIF image libheif cannot decode: ") and "\n" not in said


@settings(max_examples=200, deadline=None)
@given(
    shape=st.tuples(st.integers(1, 40), st.integers(1, 40)),
    dtype=st.sampled_from([np.float32, np.float64, np.uint8]),
    qs=st.lists(st.floats(0, 100), min_size=1, max_size=4),
    seed=st.integers(0, 2**32 - 1),
    levels=st.sampled_from([0, 2, 256]),
)
def test_percentiles_are_numpys_to_the_last_bit(shape, dtype, qs, seed, levels) -> None:
    """The framing of every reading takes its contrast from these: any difference from
    np.percentile would shift what the decoder sees."""
    rng = np.random.default_rng(seed)
    values = rng.random(shape)
    if levels:  # ties, as in 8-bit photos and flat paper
        values = np.round(values * (levels - 1)) / max(levels - 1, 1)
    values = (values * 255).astype(dtype) if dtype == np.uint8 else values.astype(dtype)
    ours, theirs = percentiles(values, tuple(qs)), np.percentile(values, qs)
    assert ours.dtype == theirs.dtype
    assert np.array_equal(ours, theirs)


def test_ink_mask_drops_a_light_border_shadow_and_keeps_dark_border_ink(ghost) -> None:
    _, base = ghost
    view = np.pad(base, 20, constant_values=1.0)
    plain_mask, plain_box = ink_mask(view)
    shadowed = view.copy()
    shadowed[:, :8] = 0.45  # a grey band along the edge: lighter than the ink inside
    mask, box = ink_mask(shadowed)
    # the band moves Otsu's threshold a little (a pixel of anti-aliasing), but is not ink
    assert box[0] > 8 and np.abs(np.subtract(box, plain_box)).max() <= 1
    assert (mask & plain_mask).sum() >= 0.95 * max(mask.sum(), plain_mask.sum())
    inked = view.copy()
    inked[40:60, :6] = 0.0  # as dark as the ink: a stroke running off the edge is kept
    _, box = ink_mask(inked)
    assert box[0] == 0 and box[2] == plain_box[2]


@pytest.mark.parametrize("side", [192, 509, 510, 511, 700])
def test_component_labels_never_run_out(side: int) -> None:
    # the most components a mask of this size can hold: one pixel in every 2x2 block
    worst = np.zeros((side, side), dtype=np.uint8)
    worst[::2, ::2] = 255
    n, labels, _, _ = cv2.connectedComponentsWithStats(worst, connectivity=8, ltype=component_label_type(side, side))
    assert n == ((side + 1) // 2) ** 2 + 1
    assert labels.max() == n - 1
    assert component_label_type(side, side) == (cv2.CV_16U if n <= 65535 else cv2.CV_32S)


@settings(max_examples=60, deadline=None)
@given(
    shape=st.tuples(st.integers(120, 260), st.integers(120, 260)),
    dtype=st.sampled_from([np.float32, np.float64]),
    qs=st.lists(st.floats(0, 100), min_size=1, max_size=4),
    seed=st.integers(0, 2**32 - 1),
    levels=st.sampled_from([0, 2, 5, 256]),
    order=st.sampled_from(["random", "ascending", "descending"]),
)
def test_percentiles_of_views_are_numpys_to_the_last_bit(shape, dtype, qs, seed, levels, order) -> None:
    """Views the size of a reading's (192 px) take the sampled selection (order_statistics),
    whose guesses must never change an answer: ties, two-level images, sorted data."""
    rng = np.random.default_rng(seed)
    values = rng.random(shape)
    if levels:
        values = np.round(values * (levels - 1)) / max(levels - 1, 1)
    if order != "random":
        values = np.sort(values, axis=None).reshape(shape)
        values = values if order == "ascending" else values[::-1, ::-1].copy()
    values = values.astype(dtype)
    qs = (*qs, 1.0, 99.0)
    assert np.array_equal(percentiles(values, qs), np.percentile(values, qs))


def test_order_statistics_partition_only_a_window_and_agree_with_a_full_partition(monkeypatch) -> None:
    rng = np.random.default_rng(7)
    flat = rng.random(192 * 192).astype(np.float32)
    assert flat.size >= SELECTION_SAMPLE * 32  # large enough for the sampled path
    ranks = np.array([0, 367, 368, 20000, 36495, 36496, flat.size - 1])
    expected = np.partition(flat, ranks)[ranks]
    sizes = []
    full_partition = np.partition

    def spy(a, kth, *args, **kwargs):
        sizes.append(np.asarray(a).size)
        return full_partition(a, kth, *args, **kwargs)

    monkeypatch.setattr(np, "partition", spy)
    assert np.array_equal(order_statistics(flat, ranks), expected)
    assert sizes and max(sizes) < flat.size // 4  # windows, never the whole array
    # NaN sorts last, as in a partition; the sampled path then steps aside for the full one
    flat[[5, 900, 30000]] = np.nan
    sizes.clear()
    got = order_statistics(flat, np.array([368, flat.size - 1]))
    assert np.isnan(got[1]) and got[0] == full_partition(flat, 368)[368]
    assert flat.size in sizes


@pytest.mark.parametrize(
    "src, dst",
    [
        ((640, 480), (256, 192)),  # a VGA photo for the detector: 2/5
        ((1920, 1080), (256, 144)),  # 2/15
        ((800, 600), (256, 192)),  # 8/25
        ((960, 720), (256, 192)),  # 4/15
        ((640, 480), (640, 192)),  # one axis only
        ((1280, 720), (256, 144)),  # a whole-number ratio: OpenCV's own quick path
        ((641, 481), (256, 192)),  # a long period: OpenCV
        ((300, 200), (400, 100)),  # wider: OpenCV
    ],
)
def test_area_resize_is_opencvs_area_resampling(src: tuple[int, int], dst: tuple[int, int]) -> None:
    image = np.random.default_rng(sum(src)).random(src[::-1], dtype=np.float32)
    ours = area_resize(image, dst)
    theirs = cv2.resize(image, dst, interpolation=cv2.INTER_AREA)
    assert ours.shape == theirs.shape == dst[::-1] and ours.dtype == np.float32
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-6)
    # uint8 and colour images go to OpenCV unchanged
    u8 = (image * 255).astype(np.uint8)
    assert np.array_equal(area_resize(u8, dst), cv2.resize(u8, dst, interpolation=cv2.INTER_AREA))


def test_area_weights_cover_each_source_pixel_once() -> None:
    weights = _area_weights(640, 256)  # 5 source pixels -> 2 outputs
    assert weights.shape == (2, 5)
    np.testing.assert_allclose(weights.sum(1), 1.0, rtol=1e-6)  # each output averages
    np.testing.assert_allclose(weights.sum(0) * 5 / 2, 1.0, rtol=1e-6)  # every source pixel counted once
    assert _area_weights(1280, 256) is not None and _area_weights(1280, 256).shape == (1, 5)
    assert _area_weights(641, 256) is None and _area_weights(256, 640) is None
