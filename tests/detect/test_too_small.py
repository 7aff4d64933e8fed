"""A print narrower in the photo than the decoder's frame that does not read is reported as too
small (move closer, print larger), in the API, the JSON and ``decode``'s text."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.render import render_svg
from deepmorph_detect.scenes import close_up_photo

app = application()


def small_prints(model, count: int = 12) -> list[tuple[np.ndarray, np.ndarray]]:
    """Hard close-ups whose drawing spans about 40 camera pixels (the ghost reads about a third)."""
    rng = np.random.default_rng(0)
    photos = []
    for _ in range(count):
        payload = rng.integers(0, 2, model.codec.spec.payload_bits).astype(np.uint8)
        photos.append((close_up_photo(render_svg(model.encode(payload), 200), "hard", rng, size=64), payload))
    return photos


def test_unread_small_prints_are_too_small_and_read_ones_are_not(model, locator) -> None:
    flagged = read = 0
    for photo, payload in small_prints(model):
        for found in locator.locate(photo):
            assert found.needs_px == model.width == 96
            assert 30 < found.width_px < 50
            if found.result.ok:
                assert np.array_equal(found.result.payload, payload)
                assert not found.too_small and "too_small" not in found.to_json()
                read += 1
            else:
                assert found.too_small
                assert found.to_json()["too_small"] == {"width_px": round(found.width_px, 1), "needs_px": 96.0}
                flagged += 1
    assert flagged >= 3 and read >= 3
    # the same unread drawing at twice the size in the photo is not too small: another reason
    unread = next(f for photo, _ in small_prints(model) for f in locator.locate(photo) if not f.result.ok)
    wide = replace(unread, corners=unread.corners * 3)
    assert wide.width_px > 96 and not wide.too_small


def test_decode_says_a_print_is_too_small(model, locator, tmp_path: Path) -> None:
    photo = next(p for p, _ in small_prints(model) if any(f.too_small for f in locator.locate(p)))
    path = tmp_path / "small.png"
    cv2.imwrite(str(path), photo)
    shown = CliRunner().invoke(app, ["decode", str(BUNDLED_MODEL), str(path)])
    assert shown.exit_code == 4, shown.output
    assert "NOT READ: too small to read (" in shown.output and "px across, needs 96)" in shown.output
    data = json.loads(CliRunner().invoke(app, ["decode", str(BUNDLED_MODEL), str(path), "--json"]).output)
    (detection,) = data[0]["detections"]
    assert detection["too_small"]["needs_px"] == 96.0 and not detection["ok"]


def test_info_gives_the_smallest_print() -> None:
    data = json.loads(CliRunner().invoke(app, ["info", str(BUNDLED_MODEL), "--json"]).output)
    assert data["smallest_print_px"] == 96 == data["image_size"][1]
    shown = CliRunner().invoke(app, ["info", str(BUNDLED_MODEL)], env={"COLUMNS": "200"})
    assert "96 px across in a photo" in shown.output
